#include "config/interpolator_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
InterpolatorConfig parse_interpolator(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
