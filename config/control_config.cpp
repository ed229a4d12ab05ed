#include "config/control_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
ControlConfig parse_control(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
