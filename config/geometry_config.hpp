#pragma once
// Geometric-error model file (seed 003): polynomial coefficients of each axis' 6 error components
// plus squareness, as a user enters them from a laser / ballbar calibration. A separate YAML file
// (not a section of the main config), validated with config::Section like the main loader.
//
// Schema (units: translations um, rotations urad, axis position q in mm; coefficient k multiplies
// q^k, so c_k is in um/mm^k or urad/mm^k; at most 8 coefficients, c0 first):
//   tool_offset_mm: [0, 0, 0]        # tool tip in the Z-carriage frame (Abbe offsets)
//   squareness_urad: {xy: 0, yz: 0, zx: 0}   # xy > 0: actual X gets + s_xy * y
//   axes:
//     X: {dx_um: [..], dy_um: [..], dz_um: [..], ex_urad: [..], ey_urad: [..], ez_urad: [..]}
//     Y: {...}
//     Z: {...}
// For axis X, dx is its positioning error, dy/dz its straightness; ex/ey/ez its roll/pitch/yaw
// (rotations about the machine X/Y/Z). Every key is optional (absent = 0).
// Errors: ConfigError listing every problem as file:line:column: key.path: message.
#include <string>

#include "config/yaml_reader.hpp"
#include "control/geometric_error.hpp"

namespace contour::config {

control::GeometricErrorParams parse_geometry(Section& root);
control::GeometricErrorModel load_geometry_file(const std::string& path);
control::GeometricErrorModel load_geometry_string(const std::string& text,
                                                  const std::string& name = "<string>");

}  // namespace contour::config
