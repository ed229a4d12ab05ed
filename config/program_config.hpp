#pragma once
// `program:` section (issues 3, 18, 19): what the G-code interpreter needs from the machine set-up.
// Keys (all optional; the defaults keep older configs valid):
//   work_offsets: {G54: [x, y, z], ..., G59: [...]}   mm, machine coords of each work zero
//   tools: [{number: 1, length_mm: 42.5}, ...]        G43 H tool table (without a .tbl file)
//   g28_mm: [x, y, z], g30_mm: [x, y, z]              reference positions (machine coords)
//   start_mm: [x, y, z]                               where the program starts (machine coords)
//   rapid_mm_min: 5000                                G0 feed
//   arc_tolerance_mm: 0.0282843                       LinuxCNC's CENTER_ARC_RADIUS_TOLERANCE_MM:
//   arc_tolerance_inch: 0.00282843                    an IJK arc whose end radius differs by more
//                                                     than 100x this, or this and 0.1 %, is
//                                                     refused (1e-6..1 mm, 4e-8..0.04 in)
//   subroutine_path: [/abs/dir, ...]                  where `o<name> call` finds <name>.ngc when
//                                                     the program does not define it (each dir,
//                                                     then its subdirectories, as LinuxCNC does);
//                                                     absolute paths of existing directories
//   block_delete: false                               '/' switch at start-up (`switches`)
//   require_program_end: false                        true: a program without M2/M30/'%' is
//                                                     refused at its end (LinuxCNC's rule)
//   var_file: state/machine.var                       LinuxCNC parameter file the daemon loads
//                                                     and rewrites atomically (offsets, G92,
//                                                     G28/G30); relative to the config file,
//                                                     ${VAR:-default} expanded; absent: no
//                                                     persistence (today's behaviour)
//   tool_table: sim.tbl                               LinuxCNC tool table (must exist); it is the
//                                                     tool table, so `tools` is refused with it
#include <array>
#include <functional>
#include <optional>
#include <string>
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
  double arc_tolerance_mm = 0.028284271247461903;
  double arc_tolerance_inch = 0.0028284271247461905;
  std::vector<std::string> subroutine_path;
  bool require_program_end = false;
  bool block_delete = false;  // '/' lines skipped (the switch's start-up state)
  std::string var_file;    // as written in the YAML ("" = none)
  std::string tool_table;  // as written in the YAML ("" = none)
};

ProgramConfig parse_program(Section& s);

// Parser set-up from the program and interpolator sections (subroutine files are read through
// make_subroutine_loader).
control::ProgramSetup to_program_setup(const ProgramConfig& p, const InterpolatorConfig& i);

// The ProgramSetup::load_subroutine callback for a subroutine path: "<name>.ngc" in the first
// directory that has it, searching each directory then its subdirectories (LinuxCNC's findFile).
// Reads the file when called (the planner thread); nullopt when no directory has it.
std::function<std::optional<std::string>(const std::string&)> make_subroutine_loader(
    std::vector<std::string> dirs);

}  // namespace contour::config
