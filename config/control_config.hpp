#pragma once
// `control:` section. Owned by the contour-control (issue 4) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct ControlConfig {};

ControlConfig parse_control(Section& s);

}  // namespace contour::config
