#pragma once
// `force:` section. Owned by the force-control (issue 5) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct ForceConfig {};

ForceConfig parse_force(Section& s);

}  // namespace contour::config
