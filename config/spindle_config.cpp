#include "config/spindle_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
SpindleConfig parse_spindle(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
