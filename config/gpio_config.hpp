#pragma once
// `gpio:` section. Owned by the force I/O (issue 8) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct GpioConfig {};

GpioConfig parse_gpio(Section& s);

}  // namespace contour::config
