#include "config/dynamometer_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
DynamometerConfig parse_dynamometer(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
