#pragma once
// `program:` section. Owned by the G-code (issue 3) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct ProgramConfig {};

ProgramConfig parse_program(Section& s);

}  // namespace contour::config
