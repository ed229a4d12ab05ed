#include "config/force_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
ForceConfig parse_force(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
