#include "config/gpio_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
GpioConfig parse_gpio(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
