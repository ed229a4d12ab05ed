#pragma once
// `bus:` section. Owned by the CANopen (issue 7) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct BusConfig {};

BusConfig parse_bus(Section& s);

}  // namespace contour::config
