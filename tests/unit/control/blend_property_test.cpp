// Seeded property test of the blend tolerance (issues 19 and 23): random programs mixing short and
// long lines, rapids, arcs in the three planes, full circles (start == end: one full turn), extra
// turns and helices run through the default (true-path verified) planner in G64 P mode and the
// FIR interpolator; the output is measured by PathMeter against the programmed path (not the
// planner's chords): path error on every output chord, every programmed vertex, per-axis
// acceleration per period, no NaN. The paper's method on the same programs must be seen to break
// the tolerance by the same measurement (so the check can fail).
#include <gtest/gtest.h>

#include <cstdio>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <string>
#include <numbers>
#include <random>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/path.hpp"
#include "control/path_meter.hpp"
#include "tests/support/plan_into_interpolator.hpp"

using namespace contour::control;
using Eigen::Vector3d;

namespace {

constexpr double kTolMm = 0.05;
constexpr double kVmaxMmMin = 10000.0;
constexpr double kAmaxMmS2 = 2000.0;

std::vector<Block> random_program(unsigned seed, Vector3d& start) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto uni = [&](double a, double b) { return a + (b - a) * u(rng); };
  std::vector<Block> out;
  start = Vector3d::Zero();
  Vector3d pos = start;
  int line = 1;
  auto push = [&](PathSegment s, double feed, bool rapid) {
    Block b;
    b.kind = BlockKind::kMotion;
    b.line = line++;
    b.seg = s;
    b.rapid = rapid;
    b.feed_mm_min = feed;
    b.blend = BlendMode::kLimited;
    b.tolerance_mm = kTolMm;
    out.push_back(b);
    pos = s.end;
  };
  double feed = uni(1000, 6000);
  const int n = 16;
  for (int i = 0; i < n; ++i) {
    const double pick = u(rng);
    if (pick < 0.12) feed = uni(1000, 6000);
    if (pick < 0.30) {  // short line, 3-D
      const Vector3d d = Vector3d(uni(-1, 1), uni(-1, 1), uni(-0.3, 0.3)).normalized() * uni(0.05, 2.0);
      push(PathSegment::line(pos, pos + d), feed, false);
    } else if (pick < 0.45) {  // long line
      const Vector3d d = Vector3d(uni(-1, 1), uni(-1, 1), uni(-0.2, 0.2)).normalized() * uni(5.0, 20.0);
      push(PathSegment::line(pos, pos + d), feed, false);
    } else if (pick < 0.55) {  // rapid: retract, move, plunge
      push(PathSegment::line(pos, pos + Vector3d(0, 0, 3)), kVmaxMmMin, true);
      push(PathSegment::line(pos, pos + Vector3d(uni(-15, 15), uni(-15, 15), 0)), kVmaxMmMin, true);
      push(PathSegment::line(pos, pos - Vector3d(0, 0, 3)), 600.0, false);
    } else {  // arc in a random plane: partial, full circle, extra turns, helix
      PathSegment s;
      s.kind = PathSegment::Kind::kArc;
      const int pl = static_cast<int>(u(rng) * 3.0) % 3;
      s.plane = pl == 0 ? Plane::kXY : (pl == 1 ? Plane::kZX : Plane::kYZ);
      s.ccw = u(rng) < 0.5;
      const PlaneAxes ax = plane_axes(s.plane);
      const double r = uni(0.5, 5.0);
      const double th0 = uni(0.0, 2.0 * std::numbers::pi);
      s.start = pos;
      s.center = pos;
      s.center[ax.a] = pos[ax.a] - r * std::cos(th0);
      s.center[ax.b] = pos[ax.b] - r * std::sin(th0);
      const double kind = u(rng);
      const bool full = kind < 0.35;
      s.turns = kind > 0.85 ? 1 : 0;
      const double sweep = full ? 2.0 * std::numbers::pi : uni(0.2, 1.9 * std::numbers::pi);
      const double th1 = th0 + (s.ccw ? 1.0 : -1.0) * sweep;
      s.end = pos;
      if (!full) {
        s.end[ax.a] = s.center[ax.a] + r * std::cos(th1);
        s.end[ax.b] = s.center[ax.b] + r * std::sin(th1);
      }
      if (u(rng) < 0.4) s.end[ax.n] = pos[ax.n] + uni(-3.0, 3.0);  // helix
      push(s, feed, false);
    }
  }
  Block e;
  e.kind = BlockKind::kEnd;
  e.line = line;
  out.push_back(e);
  return out;
}

struct RunResult {
  double brute_mm = 0.0;  // max over samples of the distance to ANY programmed segment (a lower bound)
  PathMeterResult m;
  bool nan = false;
  bool done = false;
};

RunResult run(const std::vector<Block>& blocks, const Vector3d& start, BlendMethod method, int taps) {
  PlannerParams pp;
  pp.method = method;
  pp.fir_taps = taps;
  pp.floor_rounding = method == BlendMethod::kPaper;
  pp.force_mode = BlendMode::kLimited;
  pp.force_tolerance_mm = kTolMm;
  pp.default_tolerance_mm = kTolMm;
  pp.max_velocity_mm_min = Vector3d::Constant(kVmaxMmMin);
  pp.max_accel_mm_s2 = Vector3d::Constant(kAmaxMmS2);
  PathMeter meter(pp.period_s, std::max(2.0, kVmaxMmMin / 60.0 * taps * pp.period_s), 10, kTolMm);
  Interpolator ip;
  contour::test::plan_into_interpolator(pp, blocks, start, meter, ip);
  RunResult r;
  InterpOutput out;
  for (int guard = 0; guard < 2'000'000; ++guard) {
    const auto st = ip.step(1.0, out);
    if (!out.position_mm.allFinite()) {
      r.nan = true;
      break;
    }
    meter.add_sample(out.position_mm);
    {
      double d = 1e300;
      for (const auto& b : blocks)
        if (b.kind == BlockKind::kMotion) d = std::min(d, distance_to_segment(out.position_mm, b.seg));
      r.brute_mm = std::max(r.brute_mm, d);
    }
    if (st == InterpStatus::kDone) {
      r.done = true;
      break;
    }
  }
  meter.finish();
  r.m = meter.result();
  return r;
}

}  // namespace

// Unoptimised sanitizer builds (the `dev` preset) run seeds 1 and 3 (seed 3: the 101-tap
// filter): the same checks at a tenth of the speed; optimised builds run all six.
#if defined(NDEBUG)
constexpr unsigned kLastSeed = 6;
constexpr bool kDebugSubset = false;
#else
constexpr unsigned kLastSeed = 3;
constexpr bool kDebugSubset = true;
#endif

TEST(BlendProperty, RandomArcsCirclesHelicesRapidsHoldToleranceAndLimits) {
  int paper_broke = 0;
  const char* one = std::getenv("CONTOUR_BLEND_SEED");
  if (kDebugSubset) std::printf("debug build: seeds 1 and 3 of 6 (optimised builds run all)\n");
  for (unsigned seed = 1; seed <= kLastSeed; ++seed) {
    if (one != nullptr && std::to_string(seed) != one) continue;
    if (kDebugSubset && one == nullptr && seed == 2) continue;
    const auto t0 = std::chrono::steady_clock::now();
    Vector3d start;
    const auto prog = random_program(seed, start);
    const int taps = seed % 3 == 0 ? 101 : 17;
    const RunResult r = run(prog, start, BlendMethod::kTrue, taps);
    SCOPED_TRACE("seed " + std::to_string(seed) + ", taps " + std::to_string(taps));
    ASSERT_FALSE(r.nan);
    ASSERT_TRUE(r.done);
    EXPECT_LE(r.m.max_path_error_mm, kTolMm + 1e-9) << "worst at line " << r.m.worst_line << ", brute-force lower bound " << r.brute_mm;
    EXPECT_LE(r.m.max_vertex_error_mm, kTolMm + 1e-9) << "worst vertex line " << r.m.worst_vertex_line;
    EXPECT_GT(r.m.vertices, 0);
    for (int i = 0; i < 3; ++i) EXPECT_LE(r.m.peak_accel_raw_mm_s2[i], kAmaxMmS2 * (1.0 + 1e-6)) << "axis " << i;
    EXPECT_LE(r.m.peak_speed_mm_s * 60.0, kVmaxMmMin * std::sqrt(3.0) * (1.0 + 1e-9));
    if (paper_broke >= 1) continue;
    const RunResult rp = run(prog, start, BlendMethod::kPaper, taps);
    if (rp.m.max_path_error_mm > kTolMm + 1e-6 || rp.m.max_vertex_error_mm > kTolMm + 1e-6) ++paper_broke;
    if (one != nullptr)
      std::cout << "seed " << seed << ": " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s\n";
  }
  // The measurement sees violations when there are some: the paper's two-block model breaks the
  // tolerance on one of these programs (3+ blocks in motion, arcs as short chords).
  if (one == nullptr) {
    EXPECT_GE(paper_broke, 1);
  }
}

// A full circle (start == end) is one full turn everywhere: its length is 2 pi r, and the output
// runs the whole turn within the tolerance (issue 19's 3dtest.ngc: the path the error was measured
// against was zero-length while the interpolator ran the circle).
TEST(BlendProperty, FullCircleIsOneFullTurn) {
  PathSegment s;
  s.kind = PathSegment::Kind::kArc;
  s.plane = Plane::kXY;
  s.start = s.end = Vector3d(10, 0, 0);
  s.center = Vector3d(12, 0, 0);
  EXPECT_NEAR(segment_length_mm(s), 4.0 * std::numbers::pi, 1e-12);
  Block b;
  b.kind = BlockKind::kMotion;
  b.line = 1;
  b.seg = PathSegment::line(Vector3d::Zero(), s.start);
  b.feed_mm_min = 1000;
  b.blend = BlendMode::kLimited;
  b.tolerance_mm = kTolMm;
  Block c = b;
  c.line = 2;
  c.seg = s;
  Block e;
  e.kind = BlockKind::kEnd;
  e.line = 3;
  const RunResult r = run({b, c, e}, Vector3d::Zero(), BlendMethod::kTrue, 101);
  ASSERT_TRUE(r.done);
  EXPECT_NEAR(r.m.length_mm, 10.0 + 4.0 * std::numbers::pi, 1e-9);
  EXPECT_LE(r.m.max_path_error_mm, kTolMm + 1e-9);
  // The output went round: it passed the far side of the circle (14, 0).
  EXPECT_GT(r.m.duration_s, (10.0 + 4.0 * std::numbers::pi) / (1000.0 / 60.0));
}
