#pragma once
// `dynamometer:` section. Owned by the force I/O (issue 8) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct DynamometerConfig {};

DynamometerConfig parse_dynamometer(Section& s);

}  // namespace contour::config
