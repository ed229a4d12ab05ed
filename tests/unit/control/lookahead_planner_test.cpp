// Look-ahead planner (BlendMethod::kLookahead) regressions: the plan is played through the RT
// interpolator and measured by PathMeter against the programmed path (path and vertex error, raw
// per-period acceleration), independently of the planner's own verification.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/path_meter.hpp"
#include "tests/support/plan_into_interpolator.hpp"

using namespace contour::control;
using Eigen::Vector3d;

namespace {

constexpr double kTolMm = 0.05;
constexpr double kVmaxMmMin = 10000.0;
constexpr double kAmaxMmS2 = 2000.0;
constexpr int kTaps = 17;  // tools/bench/tp/contourd.yaml: fir_ms 16

Block motion(int line, const Vector3d& a, const Vector3d& b, double feed, bool rapid) {
  Block k;
  k.kind = BlockKind::kMotion;
  k.line = line;
  k.seg = PathSegment::line(a, b);
  k.rapid = rapid;
  k.feed_mm_min = feed;
  k.blend = BlendMode::kLimited;
  k.tolerance_mm = kTolMm;
  return k;
}

// Feed moves through the points in order (lines 1..n), then the program end.
std::vector<Block> polyline(const std::vector<Vector3d>& pts, double feed) {
  std::vector<Block> b;
  for (std::size_t i = 1; i < pts.size(); ++i)
    b.push_back(motion(static_cast<int>(i), pts[i - 1], pts[i], feed, false));
  Block e;
  e.kind = BlockKind::kEnd;
  e.line = static_cast<int>(pts.size());
  b.push_back(e);
  return b;
}

struct PlanRun {
  PathMeterResult m;
  bool done = false;
  int periods = 0;  // interpolator steps that produced a sample
};

PlanRun run(const std::vector<Block>& blocks, const Vector3d& start) {
  PlannerParams pp;
  pp.method = BlendMethod::kLookahead;
  pp.fir_taps = kTaps;
  pp.force_mode = BlendMode::kLimited;
  pp.force_tolerance_mm = kTolMm;
  pp.default_tolerance_mm = kTolMm;
  pp.max_velocity_mm_min = Vector3d::Constant(kVmaxMmMin);
  pp.max_accel_mm_s2 = Vector3d::Constant(kAmaxMmS2);
  pp.rapid_mm_min = kVmaxMmMin;
  PathMeter meter(pp.period_s, 4.0, 10, kTolMm);
  Interpolator ip;
  contour::test::plan_into_interpolator(pp, blocks, start, meter, ip);
  PlanRun r;
  InterpOutput out;
  for (int guard = 0; guard < 200'000; ++guard) {
    const auto st = ip.step(1.0, out);
    if (st == InterpStatus::kHolding || st == InterpStatus::kSpindleWait) {
      ip.resume();  // the operator / spindle answers at once (as contour-sim blend does)
      continue;
    }
    meter.add_sample(out.position_mm);
    ++r.periods;
    if (st == InterpStatus::kDone) {
      r.done = true;
      break;
    }
  }
  meter.finish();
  r.m = meter.result();
  return r;
}

void expect_limits(const PlanRun& r) {
  ASSERT_TRUE(r.done);
  EXPECT_LE(r.m.max_path_error_mm, kTolMm);
  EXPECT_LE(r.m.max_vertex_error_mm, kTolMm);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(r.m.peak_accel_raw_mm_s2[i], kAmaxMmS2 * (1.0 + 1e-6)) << "axis " << i;
    EXPECT_LE(r.m.peak_accel_mm_s2[i], kAmaxMmS2 * (1.0 + 1e-6)) << "axis " << i;
  }
}

}  // namespace

// Motion right after a hold marker (tool change): the interpolator restarts its time scale at 0 and
// ramps it to 1 over L - 1 periods; motion planned inside the ramp was played time-warped (2875
// mm/s^2 per period, 2150 over 10 ms against 2000 on cam_post before the fix).
TEST(LookaheadPlanner, MotionAfterHoldMarkerKeepsTheAxisLimit) {
  const Vector3d start = Vector3d::Zero();
  std::vector<Block> b;
  Block tc;
  tc.kind = BlockKind::kToolChange;
  tc.line = 1;
  tc.tool = 2;
  b.push_back(tc);
  b.push_back(motion(2, start, Vector3d(-5, -5, 0), kVmaxMmMin, true));
  b.push_back(motion(3, Vector3d(-5, -5, 0), Vector3d(-5, -5, 20), kVmaxMmMin, true));
  Block e;
  e.kind = BlockKind::kEnd;
  e.line = 4;
  b.push_back(e);
  expect_limits(run(b, start));
}

// 29 chords of tests/data/tp/gen/cam_dense_random.ngc (lines 930-958): across chords 945-948 the
// velocity change over one window exceeded the axis limit at the corner cap the planner chose
// (its acceleration check looked +-v rr / 2 around each vertex, the window spans v (L1 + 1)); the
// window repair then capped a chord at 7e-10 mm/period and the final plan never ended (12 GB of
// pulses: before the fix this test does not finish).
TEST(LookaheadPlanner, DenseChordsAcrossTheWindowEndAndKeepTheLimits) {
  const std::vector<Vector3d> pts = {
      {62.6134, -206.3862, 0.3993}, {63.2351, -206.8050, 0.3996}, {63.4703, -207.0704, 0.3999},
      {64.2394, -207.6327, 0.4002}, {64.9018, -207.9070, 0.4005}, {65.7787, -208.3236, 0.4008},
      {66.2096, -208.5611, 0.4011}, {66.8604, -209.1635, 0.4014}, {67.4826, -209.8003, 0.4017},
      {67.8036, -210.0183, 0.4020}, {68.3194, -210.3440, 0.4023}, {68.6847, -210.6986, 0.4026},
      {69.2073, -211.3419, 0.4029}, {69.3480, -211.5593, 0.4032}, {70.0534, -212.2174, 0.4035},
      {70.2745, -212.3512, 0.4038}, {70.4053, -212.4595, 0.4041}, {71.0297, -213.1023, 0.4044},
      {71.3447, -213.3402, 0.4047}, {72.1790, -213.7239, 0.4050}, {72.3036, -213.8255, 0.4052},
      {73.0290, -214.1448, 0.4055}, {73.3073, -214.1842, 0.4058}, {74.1157, -214.1519, 0.4061},
      {74.8495, -214.1102, 0.4064}, {75.1376, -214.1732, 0.4067}, {76.0034, -214.3241, 0.4070},
      {76.2409, -214.4178, 0.4073}, {76.6312, -214.5090, 0.4076}};
  const Vector3d start = pts.front();
  const std::vector<Block> b = polyline(pts, 4000.0);
  expect_limits(run(b, start));
}

// pcb2gcode-style output: 1 um and 8 um chords alternating along a gentle curve (radius 20 mm) at
// F600. Each chord lasting one period capped the feed at 1 um/period = 60 mm/min (13x LinuxCNC's
// time on pcb2gcode-D1MiniGSR-front); merged within 0.04 P the path runs near F600, with P and the
// axis limits still held at every programmed vertex.
TEST(LookaheadPlanner, TinyAlternatingChordsAreMergedInsideTheTolerance) {
  std::vector<Vector3d> pts;
  double s = 0.0;
  const double r = 20.0;
  for (int i = 0; i <= 600; ++i) {
    pts.emplace_back(r * std::sin(s / r), r - r * std::cos(s / r), 0.0);
    s += (i % 2 == 0) ? 0.001 : 0.008;
  }
  const Vector3d start = pts.front();
  const std::vector<Block> b = polyline(pts, 600.0);
  const PlanRun run_result = run(b, start);
  expect_limits(run_result);
  // 2.7 mm at 10 mm/s: 270 periods plus ramps and the FIR (about 300); unmerged: about 2400.
  EXPECT_LT(run_result.periods, 400);
}

// CAM output of round pads and curves: chords of 0.15 mm turning ~5.7 degrees each (a circle of
// radius 1.5 mm, pcb2gcode-multivibrator-clockwise-back), at F9000. The speed the axis limits allow
// on the circle is about sqrt(a r) = 55 mm/s. The corner cap's fixed-point search stopped at its
// first lower bound (the cap at the block feed's span), about half of that: 85.4 s on the
// multivibrator program against LinuxCNC's 49.4 s. The largest speed the window rule allows is
// now searched (bisection), and P and the limits still hold. Mean speed over 4 turns from rest to
// rest: 20.1 mm/s before (1879 periods), 43.4 mm/s after (868 periods).
TEST(LookaheadPlanner, ChordedCircleRunsNearTheSpeedTheAxisLimitsAllow) {
  const double r = 1.5;
  const int per_turn = 63;  // chord 0.1496 mm, turn 5.71 degrees
  const int turns = 4;
  std::vector<Vector3d> pts;
  for (int i = 0; i <= per_turn * turns; ++i) {
    const double a = 2.0 * std::numbers::pi * i / per_turn;
    pts.emplace_back(r * std::sin(a), r - r * std::cos(a), 0.0);
  }
  const Vector3d start = pts.front();
  const std::vector<Block> b = polyline(pts, 9000.0);
  const PlanRun run_result = run(b, start);
  expect_limits(run_result);
  const double path_mm = 2.0 * std::numbers::pi * r * turns;
  const double mean_mm_s = path_mm / (run_result.periods * 1e-3);
  std::printf("chorded circle: %.2f mm in %d periods, mean %.1f mm/s\n", path_mm,
              run_result.periods, mean_mm_s);
  EXPECT_GT(mean_mm_s, 35.0);
}

// An isolated sharp corner holds its tolerance cap only over the window of the output nearest the
// vertex (+-C (L/2 + 2) periods); the window rule across it caps the L1 periods before it (the
// chord before it alone), not +-C (L + 1) periods on both sides. A square and a zigzag with 90 and
// 166 degree turns at 100 mm/s: 1898 periods with the symmetric regions, 1837 with the short ones.
TEST(LookaheadPlanner, IsolatedSharpCornersHoldTheirCapOnlyOverTheOutputWindow) {
  const std::vector<Vector3d> pts = {{0, 0, 0},  {20, 0, 0}, {20, 20, 0}, {0, 20, 0},
                                     {0, 0, 0},  {20, 5, 0}, {0, 10, 0},  {20, 10, 0}};
  const PlanRun r = run(polyline(pts, 6000.0), pts.front());
  expect_limits(r);
  EXPECT_LE(r.periods, 1860);
  std::printf("square + zigzag at 100 mm/s: %d periods\n", r.periods);
}

// Out-and-back spikes shorter than 0.4 P (pcb2gcode: 14-16 um at 177 vertices of
// multivibrator-clockwise-back) are dropped; the vertex they return to is held within P minus the
// spike's length, so the spike's tip stays within P (the meter checks every programmed vertex,
// the tips included). 768 periods when the spikes were planned as two reversals each, 685 now.
TEST(LookaheadPlanner, ShortOutAndBackSpikesAreDroppedInsideTheTolerance) {
  const std::vector<Vector3d> pts = {{0, 0, 0},      {10, 0, 0},  {10.01, -0.015, 0},
                                     {10, 0, 0},     {10, 10, 0}, {10.012, 10.012, 0},
                                     {10, 10, 0},    {0, 10, 0}};
  const PlanRun r = run(polyline(pts, 3000.0), pts.front());
  expect_limits(r);
  EXPECT_GE(r.m.vertices, 6);  // the two tips among them
  EXPECT_LE(r.periods, 700);
  std::printf("two spikes of 18 and 17 um: %d periods, %lld vertices, vertex error %.1f um\n",
              r.periods, static_cast<long long>(r.m.vertices), r.m.max_vertex_error_mm * 1000.0);
}

// Hatching with near-reversals (170 degrees) at a feed below the speed the command may drop to
// zero from in one step: each turn is a stop entered without braking (the output brakes at the
// full axis rate while the command rests), not a held corner cap (tools/bench/tp short_reversals:
// 11.07 -> 10.71 s, LinuxCNC 10.43 s). 12 strokes of 2 mm at F2500: 1034 periods before, 1010 now.
TEST(LookaheadPlanner, NearReversalsAtALowFeedStopWithoutBraking) {
  std::vector<Vector3d> pts;
  for (int i = 0; i <= 12; ++i) pts.emplace_back(0.5 * i + (i % 2 ? 1.65 : 0.0), i % 2 ? 2.0 : 0.0, 0.0);
  const PlanRun r = run(polyline(pts, 2500.0), pts.front());
  expect_limits(r);
  EXPECT_LE(r.periods, 1020);
  std::printf("12 hatch strokes at F2500: %d periods\n", r.periods);
}
