#pragma once
// Path meter: measures a sampled tool trajectory (any source: contourd's interpolator, LinuxCNC's
// commanded position, a servo's actual position) against the programmed path, independently of
// any planner. Streaming, bounded memory. Setup-time code (allocates), not RT.
//
// Programmed path: PathSegments in program order (lines, arcs, full circles, helices — a full
// circle is one full turn: its length is 2 pi r, never zero). Output: positions, one per period.
//  - path error: the largest distance from the output polyline (straight between samples) to the
//    programmed path near it, by branch and bound on each output chord (distance to a line is
//    convex along the chord, to an arc 1-Lipschitz; intervals that cannot beat the maximum found
//    by more than max(1 nm, 1e-4 of it) are dropped: the figure is exact to that);
//  - vertex error: for every programmed vertex (a segment end where the path turns, the last
//    point excepted), the distance to the output polyline (two-sided tolerance);
//  - duration: from the first sample that moves to the last one that moves;
//  - per-axis peak acceleration, averaged over `accel_avg_periods` periods (velocity difference
//    over that time), and per period; peak speed.
// "Near": the segments within `reach_mm` of path length around the segment nearest to the
// previous sample (the cursor), so a path that passes the same place twice (stacked circles,
// pockets) is measured against the pass that is being run, not a later one. The cursor leaves its
// segment once the tool has run past its end, or back along it, by more than the cursor slack (a
// path that retraces itself: a Z retract and the plunge down the same line, a second lap).
#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <vector>

#include "control/path.hpp"

namespace contour::control {

struct PathMeterResult {
  std::int64_t samples = 0;
  double duration_s = 0.0;
  double max_path_error_mm = 0.0;
  double max_vertex_error_mm = 0.0;
  std::int64_t worst_sample = -1;         // index of the sample ending the worst output chord
  Eigen::Vector3d worst_point_mm = Eigen::Vector3d::Zero();
  int worst_line = 0;                     // line of the nearest segment there
  Eigen::Vector3d worst_vertex_mm = Eigen::Vector3d::Zero();
  int worst_vertex_line = 0;
  std::int64_t vertices = 0;              // vertices checked
  Eigen::Vector3d peak_accel_mm_s2 = Eigen::Vector3d::Zero();      // averaged (see above)
  Eigen::Vector3d peak_accel_raw_mm_s2 = Eigen::Vector3d::Zero();  // per period
  double peak_speed_mm_s = 0.0;
  double length_mm = 0.0;                 // programmed path length seen
};

class PathMeter {
 public:
  // reach_mm > 0; period_s > 0; accel_avg_periods >= 1 (10 at 1 ms: a 10 ms average);
  // cursor_slack_mm >= 0: the cursor stays on the earliest segment within this of the nearest (set
  // it to the tolerance being checked: a later pass crossing the current one cannot take it).
  PathMeter(double period_s, double reach_mm, int accel_avg_periods = 10, double cursor_slack_mm = 1e-3);

  // Programmed segments, in order, ahead of the samples that run along them. Zero-length lines
  // are ignored. `vertex_check`: the segment's end counts as a vertex (false for the end of the
  // program and for the inside joints of one arc's chords).
  void add_segment(const PathSegment& s, int line);
  // One output sample per period; the first one is the start position.
  void add_sample(const Eigen::Vector3d& p);
  // Closes the measurement (open vertices are counted).
  void finish();
  [[nodiscard]] const PathMeterResult& result() const { return r_; }
  // Error of the last output chord (mm) and the line of the nearest segment.
  [[nodiscard]] double last_error_mm() const { return last_err_; }
  [[nodiscard]] int last_line() const { return last_line_; }

 private:
  struct Seg {
    PathSegment seg;
    int line;
    double s0, s1;       // path length at its start and end
    bool vertex;         // its end is a vertex to check
    double vbest = 1e300;
    bool vdone = false;
  };
  double dist(const Eigen::Vector3d& x, std::size_t* arg) const;
  // Path length along segment `s` of the point of it nearest to x, unclamped (< 0 before its
  // start, > its length past its end); arcs: the angle unwrapped to the turn nearest `ref_mm`.
  // NaN when x is too near an arc's axis to tell.
  static double progress_mm(const Eigen::Vector3d& x, const PathSegment& s, double ref_mm);
  void window();

  double T_, reach_;
  double slack_ = 1e-3;
  int avg_;
  std::deque<Seg> segs_;
  std::size_t cursor_ = 0;   // index in segs_
  double cursor_progress_mm_ = 0.0;  // furthest progress along the cursor's segment
  std::size_t w0_ = 0, w1_ = 0;  // window [w0, w1)
  double s_total_ = 0.0;
  bool have_prev_ = false;
  Eigen::Vector3d prev_ = Eigen::Vector3d::Zero();
  std::deque<Eigen::Vector3d> hist_;  // last avg + 2 samples (accelerations)
  std::int64_t first_move_ = -1, last_move_ = -1;
  std::vector<double> pool_, upool_, tpar_;  // branch and bound work buffers
  double last_err_ = 0.0;
  int last_line_ = 0;
  PathMeterResult r_;
};

}  // namespace contour::control
