#pragma once
// Benchmark helper: parse and plan a whole in-memory program (setup-time code, allocates).
#include <cstdint>
#include <string>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/gcode.hpp"

namespace contour::bench {

inline std::vector<control::PlannedSegment> plan_program(const std::vector<std::string>& prog,
                                                         std::int64_t* moves = nullptr) {
  control::GcodeParser parser(control::ProgramSetup{}, "bench.ngc");
  control::BlendPlanner planner(control::PlannerParams{}, Eigen::Vector3d::Zero());
  std::vector<control::Block> blocks;
  std::vector<control::PlannedSegment> out;
  control::PlannedSegment s;
  auto drain = [&] {
    for (const auto& b : blocks) planner.push(b);
    blocks.clear();
    while (planner.pop(s)) out.push_back(s);
  };
  for (const auto& l : prog) {
    parser.parse_line(l, blocks);
    drain();
  }
  parser.finish(blocks);
  drain();
  if (moves != nullptr) *moves = planner.stats().moves;
  return out;
}

}  // namespace contour::bench
