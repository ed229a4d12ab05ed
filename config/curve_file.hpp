#pragma once
// Loader of parametric curve files (seed 000's test contours, config/programs/*.yaml):
//   curve:
//     name: eq11
//     units: blu          # blu | um | mm: units of the expressions' values
//     blu_um: 0.5         # size of one BLU (units: blu only)
//     u: [0, 1]           # parameter range (default [0, 1])
//     x: "1.5e5*u^2 - 1.5e5*u"      # muparser expressions in u (pi is defined)
//     y: "-2e4*u"
//     z: "-5e3*u"
//     dx: ...  dy: ...  dz: ...     # optional explicit first derivatives (else central differences)
// Errors (YAML, unknown keys, bad expressions, non-finite values) throw ConfigError naming
// file:line:column and the key; muparser's own message and position are included.
// The curve is not thread-safe (muparser evaluates through one shared variable); setup-time only.
#include <memory>
#include <string>

#include "config/yaml_reader.hpp"
#include "control/reference_path.hpp"

namespace contour::config {

struct CurveFile {
  std::string name;
  double scale_to_mm = 1.0;  // expression units -> mm
  std::unique_ptr<control::ParametricCurve> curve;  // in mm
};

CurveFile load_curve_file(const std::string& path);
CurveFile load_curve_string(const std::string& text, const std::string& name = "<string>");

}  // namespace contour::config
