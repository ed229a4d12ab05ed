#pragma once
// `program:` section (issue 3): what the G-code parser needs from the machine set-up. Keys:
//   work_offsets: {G54: [x, y, z], ..., G59: [...]}   mm, machine coords of each work zero
//   tools: [{number: 1, length_mm: 42.5}, ...]        G43 H tool table
//   g28_mm: [x, y, z], g30_mm: [x, y, z]              reference positions (machine coords)
//   start_mm: [x, y, z]                               where the program starts (machine coords)
//   rapid_mm_min: 5000                                G0 feed
//   arc_tolerance_mm: 0.002                           G2/G3 end-radius tolerance (also >= 0.1 % r)
#include <array>
#include <vector>

#include "config/interpolator_config.hpp"
#include "config/yaml_reader.hpp"
#include "control/gcode.hpp"

namespace contour::config {

struct ProgramConfig {
  std::array<std::array<double, 3>, 6> work_offsets_mm{};
  std::vector<control::ToolEntry> tools;
  std::array<double, 3> g28_mm{};
  std::array<double, 3> g30_mm{};
  std::array<double, 3> start_mm{};
  double rapid_mm_min = 5000.0;
  double arc_tolerance_mm = 0.002;
};

ProgramConfig parse_program(Section& s);

// Parser set-up from the program and interpolator sections.
control::ProgramSetup to_program_setup(const ProgramConfig& p, const InterpolatorConfig& i);

}  // namespace contour::config
