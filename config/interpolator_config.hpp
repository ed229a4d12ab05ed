#pragma once
// `interpolator:` section. Owned by the interpolator (issue 3) work; see config/README.md for the schema.
#include "config/yaml_reader.hpp"

namespace contour::config {

struct InterpolatorConfig {};

InterpolatorConfig parse_interpolator(Section& s);

}  // namespace contour::config
