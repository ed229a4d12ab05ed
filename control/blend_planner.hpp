#pragma once
// Corner-blending planner with a guaranteed path tolerance: the entry point the planner thread
// (daemon/planner.cpp), contour-sim and the tests use. Non-RT: runs ahead of the RT loop,
// allocates, streams in bounded memory.
//
// Input: Blocks from GcodeParser (lines, arcs as chords with sagitta <= arc_chord_fraction * tol,
// dwell, holds, tool changes, spindle changes, end; a kind it does not know is an exact stop).
// Output: PlannedSegments for control::Interpolator (fir_interpolator.hpp), in start order.
//
// Methods (PlannerParams::method):
//  - kTrue (default) / kPaper / kExhaustive: seed 004's one-feed-per-block overlap methods
//    (overlap_planner.hpp): the true-path-verified overlap search, the paper's reproduction.
//  - kLookahead (experimental): look-ahead velocity plan (lookahead_planner.hpp) — per-axis
//    velocity and acceleration limits held by the planned command itself, corner speeds from the
//    tolerance and the limits, the tolerance verified on the true output path before anything is
//    handed on (samples, between samples, every programmed vertex).
// G61 stops at every vertex, G64 blends as fast as the limits allow, G64 P<tol> holds tol.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"
#include "control/lookahead_planner.hpp"
#include "control/overlap_planner.hpp"
#include "control/planner_types.hpp"

namespace contour::control {

class BlendPlanner {
 public:
  // Throws std::invalid_argument on bad parameters.
  BlendPlanner(const PlannerParams& p, const Eigen::Vector3d& start_mm);

  // Feeds one parsed block; finished segments become available through pop(). Throws
  // std::invalid_argument for a move that cannot be interpolated (naming its line).
  void push(const Block& b);
  bool pop(PlannedSegment& out);
  [[nodiscard]] std::size_t ready() const;
  [[nodiscard]] bool ended() const;

  void on_corner(std::function<void(const CornerReport&)> cb);
  [[nodiscard]] const std::vector<std::string>& messages() const;
  [[nodiscard]] const PlannerStats& stats() const;
  [[nodiscard]] int fir_length() const { return overlap_.fir_length(); }

  // The paper's two-block model alone (exposed for tests): largest overlap (cycles) with
  // e_max <= eps for moves a -> b, each from rest; incremental (true) or exhaustive (false) search.
  struct TwoBlock {
    int overlap_cycles;
    double error_mm;
  };
  TwoBlock paper_two_block(const Eigen::Vector3d& a0, const Eigen::Vector3d& vertex,
                           const Eigen::Vector3d& b1, std::int64_t na, std::int64_t nb, double eps,
                           bool incremental) const;

  // The look-ahead planner's sharp-corner blend model (nullptr for the overlap methods).
  [[nodiscard]] const LookaheadPlanner* lookahead() const { return lookahead_.get(); }

 private:
  OverlapPlanner overlap_;  // the overlap methods, and the paper's two-block model
  std::unique_ptr<LookaheadPlanner> lookahead_;
};

}  // namespace contour::control
