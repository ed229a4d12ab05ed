#include "config/bus_config.hpp"

namespace contour::config {

// Schema not defined yet: every key present is reported as unknown by Section::finish().
BusConfig parse_bus(Section& s) {
  (void)s;
  return {};
}

}  // namespace contour::config
