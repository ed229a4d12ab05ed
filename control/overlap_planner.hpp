#pragma once
// Seed 004's corner-overlap planners (BlendMethod kPaper, kTrue, kExhaustive): every move is one
// rectangular feed command at its feed and the blend is decided per corner by the overlap of two
// consecutive commands. Non-RT: runs ahead of the RT loop, allocates, streams in bounded memory.
// BlendPlanner (blend_planner.hpp) selects it; kLookahead selects the look-ahead plan instead.
//
// Input: Blocks from GcodeParser. Arcs become chords (sagitta <= arc_chord_fraction * tolerance),
// zero-length moves are dropped, feeds are clamped to the axis velocity limits and to the axis
// acceleration limits (|v_axis| <= a_max * t_A / 2: the FIR output's acceleration is the difference
// of two command velocities over t_A). Each move gets N samples: ceil(L / (F T)) by default (never
// faster than programmed), floor(L / (F T)) in the paper's convention (`floor_rounding`), with the
// per-sample step scaled so the move ends exactly.
// Output: PlannedSegments with their command start s_{k+1} = s_k + N_k + g_k; gap g in
// [0, L-1] periods: g = 0 is G64 (full overlap t_o = t_A), g = L-1 is G61 (stop at the vertex).
// overlap_cycles = L-1-g.
//
// Tolerance-limited blending (G64 P eps), three methods:
//  - kPaper: the paper's two-block model (eqs 2-6: error of the sampled points against the LINES
//    of the two adjacent blocks, max over the overlap) and its incremental search (eqs 13-27: when
//    the overlap shrinks by one period only the points next to the previous maximum are
//    re-evaluated). Reproduces the paper; does NOT bound the real path with 3+ blocks in motion or
//    at reversals.
//  - kTrue: the paper's result is only the first candidate; each candidate is verified
//    on the TRUE path: every block still in motion is summed, the error is the distance to the
//    programmed segments (not lines), evaluated on every chord between samples (max of the min of
//    convex distance functions: endpoints + the crossing point of the two nearest segments), and
//    every programmed vertex must lie within eps of the sampled polyline (two-sided). On failure the
//    overlap shrinks one period at a time; on success it grows while it still passes.
//    Causality: a candidate is verified assuming the machine stops after the new block; the next
//    decision only changes samples after its own start, which it verifies again, so by induction
//    the whole output path holds eps; g = L-1 always passes, so a schedule always exists.
//  - kExhaustive: same verification, every overlap from full down to zero, first that passes
//    (the per-corner optimum of the greedy schedule; the reference for the time comparison).
// Arc chords: eps_verify = eps * (1 - arc_chord_fraction) so chord + blend error <= eps.
#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"
#include "control/planner_types.hpp"

namespace contour::control {

class OverlapPlanner {
 public:
  OverlapPlanner(const PlannerParams& p, const Eigen::Vector3d& start_mm);

  // Feeds one parsed block; finished segments become available through pop().
  void push(const Block& b);
  bool pop(PlannedSegment& out);
  [[nodiscard]] std::size_t ready() const { return out_.size(); }
  [[nodiscard]] bool ended() const { return ended_; }

  void on_corner(std::function<void(const CornerReport&)> cb) { corner_cb_ = std::move(cb); }
  [[nodiscard]] const std::vector<std::string>& messages() const { return messages_; }
  [[nodiscard]] const PlannerStats& stats() const { return stats_; }
  [[nodiscard]] int fir_length() const { return fir_.length(); }

  // The paper's two-block model alone (exposed for tests): largest overlap (cycles) with
  // e_max <= eps for moves a -> b, each from rest; incremental (true) or exhaustive (false) search.
  struct TwoBlock {
    int overlap_cycles;
    double error_mm;
  };
  TwoBlock paper_two_block(const Eigen::Vector3d& a0, const Eigen::Vector3d& vertex,
                           const Eigen::Vector3d& b1, std::int64_t na, std::int64_t nb, double eps,
                           bool incremental) const;

 private:
  struct Move {
    std::int64_t id = 0;
    Eigen::Vector3d a, b;
    double len = 0.0;
    double feed_mm_min = 0.0;
    std::int64_t n = 1;
    std::int64_t s = 0;
    int line = 0;
    BlendMode mode = BlendMode::kFull;
    double eps = 0.0;  // verification tolerance (chord budget removed)
    double tol = 0.0;  // programmed tolerance
    double path_start = 0.0;
    const Block* src = nullptr;
    SpindleDir spindle = SpindleDir::kOff;
    double rpm = 0.0;
    bool mist = false, flood = false;
    int tool = 0;
    bool rapid = false;
    [[nodiscard]] std::int64_t finish(std::int64_t tail) const { return s + n + tail; }
  };
  struct Vertex {
    std::int64_t move_id;  // the move starting at this vertex
    Eigen::Vector3d p;
    double eps;
    double fixed_best = std::numeric_limits<double>::infinity();
    std::int64_t fixed_from = 0;
  };

  void add_move(const Block& b, const Eigen::Vector3d& a, const Eigen::Vector3d& e, double chord_err);
  void decide(Move& m);
  void barrier(SegmentKind kind, const std::string& msg, const Block& b, double extra_s);
  void emit(const Move& m);
  Eigen::Vector3d q(std::int64_t t) const;  // true path at plan time t from the window
  // The window's cache that q() and dist_path() read (planning speed, same results to the bit):
  // verify() and extend_fixed() refresh it before they evaluate the window; see win_cache_.
  void refresh_window_cache();
  double dist_path(const Eigen::Vector3d& x, int* arg) const;
  double dist_seg(const Eigen::Vector3d& x, std::size_t i) const;
  // Largest distance to the path along the chord A-B, given the ends' distances to the path and
  // their nearest moves (dist_path).
  double chord_max(const Eigen::Vector3d& A, double da, int ia, const Eigen::Vector3d& B, double db,
                   int ib) const;
  // Checks gap g for the newest window move; returns the max error (mm) or +inf on failure.
  double verify(std::int64_t g, double eps);
  void extend_fixed(std::int64_t until);

  PlannerParams p_;
  FirFilter fir_;
  std::int64_t tail_;  // L - 1
  Eigen::Vector3d pos_;
  double path_mm_ = 0.0;
  std::int64_t next_id_ = 0;
  std::deque<Move> win_;
  // Window cache (holds while win_ and its start times stay as refresh_window_cache() saw them):
  //   sum[k]: win_[0].a + the displacements of moves 0..k-1, added in q()'s order (a move whose
  //           FIR output has ended contributes exactly its displacement: progress = n, n / n = 1);
  //   fin[k]: the latest finish(tail_) of moves 0..k-1 (q(t) starts at sum[k] for the largest k
  //           with fin[k] <= t);
  //   mid/half: each move's midpoint and half length (dist_path skips a move whose bounding
  //           sphere lies farther than a distance already found).
  struct WinCache {
    std::vector<Eigen::Vector3d> sum;
    std::vector<std::int64_t> fin;
    std::vector<Eigen::Vector3d> mid;
    std::vector<double> half;
  };
  WinCache win_cache_;
  std::vector<Eigen::Vector3d> q_buf_;  // verify(): q(fixed + i), computed once per verification
  std::vector<char> q_have_;
  mutable std::size_t dist_hint_ = 0;  // the move dist_path found nearest last time
  std::deque<Vertex> vtx_;
  std::deque<PlannedSegment> out_;
  std::int64_t earliest_start_ = 0;  // after barriers
  bool stop_before_next_ = true;
  // Spindle state the last kSpindleSync marker waited for (feed moves after a change wait).
  SpindleDir synced_spindle_ = SpindleDir::kOff;
  double synced_rpm_ = 0.0;
  std::vector<Eigen::Vector3d> chord_buf_;
  std::vector<std::string> messages_;
  std::function<void(const CornerReport&)> corner_cb_;
  PlannerStats stats_;
  bool ended_ = false;
};

}  // namespace contour::control
