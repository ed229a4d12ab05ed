#pragma once
// Parameters, corner reports and statistics shared by the blend planners (blend_planner.hpp is
// the entry point; overlap_planner.hpp holds seed 004's per-corner overlap methods,
// lookahead_planner.hpp the look-ahead velocity plan). Units: mm, mm/min, mm/s^2, s.
#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>

#include "control/gcode.hpp"

namespace contour::control {

// kTrue (default): seed 004's overlap per corner, each candidate verified on the true path.
// kPaper: seed 004's two-block model and incremental search (the paper's figures).
// kExhaustive: kTrue with every overlap tried from full down to zero.
// kLookahead: EXPERIMENTAL look-ahead velocity plan (lookahead_planner.hpp), tolerance verified on
//   the true path; selectable for benchmarks (contour-sim blend --method lookahead), not yet
//   faster than kTrue on dense chord programs, so not the default.
enum class BlendMethod { kPaper, kTrue, kExhaustive, kLookahead };

struct PlannerParams {
  double period_s = 0.001;
  int fir_taps = 101;   // t_A / T + 1
  int fir2_taps = 0;    // 0 = one stage
  bool floor_rounding = false;
  BlendMethod method = BlendMethod::kTrue;
  std::optional<BlendMode> force_mode;          // overrides the program's G61/G64
  std::optional<double> force_tolerance_mm;     // overrides G64 P
  double default_tolerance_mm = 0.05;           // chord budget for arcs in G61/G64
  double arc_chord_fraction = 0.25;
  Eigen::Vector3d max_velocity_mm_min = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d max_accel_mm_s2 = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  // Look-ahead planner (kLookahead) only:
  // Rapids (G0) run at min(their programmed rapid feed, rapid_mm_min) per path, each axis still
  // within max_velocity_mm_min (LinuxCNC: G0 at the axis limits). Infinity: as programmed.
  double rapid_mm_min = std::numeric_limits<double>::infinity();
  // Shortest command segment (periods): bounds the segments in motion for Interpolator::step
  // (<= (L - 1) / min + 2); a chord shorter than speed * min runs slower (LinuxCNC: one cycle).
  double min_segment_cycles = 1.0;
  // Path length held ahead of the committed plan (mm), 0 = automatic (braking distance from the
  // highest speed plus the corner regions); and the most chords held (bounded memory).
  double lookahead_mm = 0.0;
  std::size_t max_lookahead_chords = 20000;
};

struct CornerReport {
  std::int64_t move_index = 0;  // index of the move after the corner (0-based, after splitting)
  int line = 0;                 // source line of the block after the corner
  int prev_line = 0;            // source line of the block before (== line inside an arc)
  Eigen::Vector3d vertex_mm = Eigen::Vector3d::Zero();
  double angle_deg = 0.0;       // turning angle, 0 = straight on, 180 = reversal
  int overlap_cycles = 0;       // L - 1 - gap (the command rests `gap` periods at the vertex)
  double model_error_mm = 0.0;  // the method's own error estimate at the chosen overlap
  double tolerance_mm = 0.0;    // 0 when not tolerance-limited
  double corner_speed_mm_min = 0.0;  // look-ahead plan: command speed cap around the vertex
};

struct PlannerStats {
  std::int64_t moves = 0;
  std::int64_t dropped_zero_length = 0;
  std::int64_t verifications = 0;  // true-path candidate checks (look-ahead: plan verifications)
  std::size_t max_window = 0;      // largest number of moves held at once (bounded memory)
  // Look-ahead planner only.
  std::int64_t segments = 0;         // command segments emitted
  std::int64_t plans = 0;            // plan passes (backward + forward + verification)
  std::int64_t tolerance_repairs = 0;  // corners tightened after a failed verification
  std::int64_t accel_repairs = 0;      // speed caps lowered after an infeasible window
  std::int64_t fallbacks = 0;          // verified continuation to rest used instead of a new plan
};

}  // namespace contour::control
