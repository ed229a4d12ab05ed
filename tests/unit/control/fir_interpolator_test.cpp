// FIR filter and RT interpolator: filter algebra, no allocation per cycle, exact end point, feed
// override keeps the path, holds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "tests/support/alloc_counter.hpp"

using namespace contour::control;
using Eigen::Vector3d;

namespace {
double brute_progress(int taps1, int taps2, std::int64_t k, std::int64_t n) {
  // Direct convolution of the command ramp with one or two boxes.
  auto cmd = [&](std::int64_t m) { return static_cast<double>(std::clamp<std::int64_t>(m, 0, n)); };
  auto box1 = [&](std::int64_t kk) {
    double s = 0;
    for (int i = 0; i < taps1; ++i) s += cmd(kk - i);
    return s / taps1;
  };
  if (taps2 == 0) return box1(k);
  double s = 0;
  for (int j = 0; j < taps2; ++j) s += box1(k - j);
  return s / taps2;
}

// Ends the program (M2) and loads every planned segment into a default interpolator; returns the
// kinds of the segments loaded.
std::vector<SegmentKind> end_and_load(BlendPlanner& pl, Interpolator& ip) {
  Block e;
  e.kind = BlockKind::kEnd;
  pl.push(e);
  ip.configure(InterpolatorParams{}, Vector3d::Zero());
  std::vector<SegmentKind> kinds;
  PlannedSegment s;
  while (pl.pop(s)) {
    kinds.push_back(s.kind);
    ip.push(s);
  }
  return kinds;
}

// Plans blocks (a kEnd appended) from the origin and returns every planned segment.
std::vector<PlannedSegment> plan_blocks(const std::vector<Block>& blocks) {
  PlannerParams pp;
  BlendPlanner pl(pp, Vector3d::Zero());
  for (const auto& b : blocks) pl.push(b);
  Block e;
  e.kind = BlockKind::kEnd;
  pl.push(e);
  std::vector<PlannedSegment> out;
  PlannedSegment s;
  while (pl.pop(s)) out.push_back(s);
  return out;
}

// Pushes a 5 mm move along X, a hold of `kind` (line 2) and a 5 mm move along Y at F1200.
void push_move_hold_move(BlendPlanner& pl, BlockKind kind, const std::string& message = "") {
  Block a;
  a.line = 1;
  a.feed_mm_min = 1200;
  a.seg = PathSegment::line(Vector3d::Zero(), Vector3d(5, 0, 0));
  pl.push(a);
  Block h;
  h.kind = kind;
  h.line = 2;
  h.message = message;
  pl.push(h);
  Block b = a;
  b.line = 3;
  b.seg = PathSegment::line(Vector3d(5, 0, 0), Vector3d(5, 5, 0));
  pl.push(b);
}

std::vector<PlannedSegment> plan_square(BlendMode mode) {
  const Vector3d pts[] = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}, {0, 0, 1}};
  std::vector<Block> blocks;
  for (int i = 1; i < 5; ++i) {
    Block b;
    b.line = i;
    b.feed_mm_min = 1500;
    b.blend = mode;
    b.tolerance_mm = 0.02;
    b.seg = PathSegment::line(pts[i - 1], pts[i]);
    blocks.push_back(b);
  }
  return plan_blocks(blocks);
}
}  // namespace

TEST(FirFilter, ClosedFormMatchesConvolution) {
  FirFilter f;
  for (int t2 : {0, 1, 7, 40}) {
    f.configure(11, t2);
    for (std::int64_t n : {1, 3, 10, 11, 25, 200})
      for (std::int64_t k = -3; k < n + 70; ++k)
        EXPECT_NEAR(f.progress(k, n), brute_progress(11, t2, k, n), 1e-9) << t2 << " " << n << " " << k;
  }
}

TEST(Interpolator, StepDoesNotAllocateAndEndsExactly) {
  const auto segs = plan_square(BlendMode::kLimited);
  Interpolator ip;
  InterpolatorParams p;
  ip.configure(p, Vector3d::Zero());
  for (const auto& s : segs) ASSERT_TRUE(ip.push(s));
  InterpOutput out;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ovr(0.0, 1.5);
  int cycles = 0;
  {
    contour::test::AllocGuard g;
    for (; cycles < 10000; ++cycles) {
      if (ip.step(cycles % 500 < 250 ? ovr(rng) : 1.0, out) == InterpStatus::kDone) break;
    }
    EXPECT_EQ(g.counts().total(), 0u);
  }
  while (ip.step(1.0, out) != InterpStatus::kDone) ASSERT_LT(++cycles, 100000);
  EXPECT_EQ(out.position_mm, Vector3d(0, 0, 1));  // exactly the last programmed point
  EXPECT_EQ(out.line, 4);
  // Further steps stay there.
  ip.step(1.0, out);
  EXPECT_EQ(out.position_mm, Vector3d(0, 0, 1));
}

TEST(Interpolator, OverrideScalesTimeNotPath) {
  const auto segs = plan_square(BlendMode::kFull);
  auto run = [&](double ovr, std::vector<Vector3d>& pts) {
    Interpolator ip;
    InterpolatorParams p;
    ip.configure(p, Vector3d::Zero());
    for (const auto& s : segs) ip.push(s);
    InterpOutput out;
    int n = 0;
    while (ip.step(ovr, out) != InterpStatus::kDone && n < 1000000) {
      pts.push_back(out.position_mm);
      ++n;
    }
    return n;
  };
  std::vector<Vector3d> full{Vector3d::Zero()}, half;
  const int n1 = run(1.0, full);
  const int n2 = run(0.5, half);
  EXPECT_NEAR(static_cast<double>(n2) / n1, 2.0, 0.05);
  // Every half-speed point lies on the chord polyline of the 100 % run.
  for (std::size_t i = 0; i < half.size(); i += 7) {
    double d = 1e9;
    for (std::size_t j = 1; j < full.size(); ++j) {
      const Vector3d a = full[j - 1], b = full[j];
      const double l2 = (b - a).squaredNorm();
      const double t = l2 > 0 ? std::clamp((half[i] - a).dot(b - a) / l2, 0.0, 1.0) : 0.0;
      d = std::min(d, (half[i] - (a + t * (b - a))).norm());
    }
    ASSERT_LT(d, 1e-9) << i << " of " << half.size() << " " << half[i].transpose();
  }
}

TEST(Interpolator, HoldsAtProgramStopUntilResumed) {
  PlannerParams pp;
  BlendPlanner pl(pp, Vector3d::Zero());
  push_move_hold_move(pl, BlockKind::kToolChange, "tool 3");
  Interpolator ip;
  end_and_load(pl, ip);
  InterpOutput out;
  int n = 0;
  while (ip.step(1.0, out) != InterpStatus::kHolding) ASSERT_LT(++n, 100000);
  EXPECT_EQ(out.position_mm, Vector3d(5, 0, 0));
  ASSERT_GE(out.message_id, 0);
  EXPECT_EQ(pl.messages()[static_cast<std::size_t>(out.message_id)], "tool 3");
  for (int i = 0; i < 100; ++i) EXPECT_EQ(ip.step(1.0, out), InterpStatus::kHolding);
  ip.resume();
  while (ip.step(1.0, out) != InterpStatus::kDone) ASSERT_LT(++n, 100000);
  EXPECT_EQ(out.position_mm, Vector3d(5, 5, 0));
}

// After a hold the time scale ramps up from 0 at the override rate limit. The ramp must bring
// plan time back to a whole number: at 100 % the output samples are then the plan samples the
// planner verified, not points halfway between them (whose polyline cuts a vertex differently:
// the meter found 50.0002 um at P = 50 um after a pcb2gcode program's M0). Both parities of the
// filter length (the plain ramp sums to a half period when L - 1 is even).
TEST(Interpolator, RampAfterAHoldEndsOnAWholePlanPeriod) {
  for (const auto& taps : {std::pair{101, 0}, std::pair{17, 0}, std::pair{16, 0}, std::pair{9, 6}}) {
    PlannerParams pp;
    pp.fir_taps = taps.first;
    pp.fir2_taps = taps.second;
    BlendPlanner pl(pp, Vector3d::Zero());
    push_move_hold_move(pl, BlockKind::kProgramStop);
    Block e;
    e.kind = BlockKind::kEnd;
    pl.push(e);
    InterpolatorParams ipp;
    ipp.fir_taps = taps.first;
    ipp.fir2_taps = taps.second;
    Interpolator ip;
    ip.configure(ipp, Vector3d::Zero());
    PlannedSegment s;
    while (pl.pop(s)) ASSERT_TRUE(ip.push(s));
    const int L = taps.first + (taps.second > 0 ? taps.second - 1 : 0);
    InterpOutput out;
    int n = 0;
    while (ip.step(1.0, out) != InterpStatus::kHolding) ASSERT_LT(++n, 100000);
    double tau = out.plan_time_cycles;
    EXPECT_EQ(tau, std::floor(tau));
    ip.resume();
    double rate_prev = 0.0;
    bool at_full = false;
    int whole = 0;
    while (ip.step(1.0, out) != InterpStatus::kDone) {
      ASSERT_LT(++n, 100000);
      const double adv = out.plan_time_cycles - tau;
      tau = out.plan_time_cycles;
      // A ramp within the rate limit, up to 100 %.
      EXPECT_LE(adv - rate_prev, 1.0 / (L - 1) + 1e-12) << "L " << L;
      EXPECT_LE(adv, 1.0 + 1e-12);
      rate_prev = adv;
      if (adv == 1.0) at_full = true;
      if (at_full) {
        EXPECT_EQ(tau, std::floor(tau)) << "L " << L << " plan time " << tau;
        ++whole;
      }
    }
    EXPECT_TRUE(at_full) << "L " << L;
    EXPECT_GT(whole, 100) << "L " << L;
    EXPECT_EQ(out.position_mm, Vector3d(5, 5, 0));
  }
}

TEST(Interpolator, FeedMoveAfterASpindleChangeWaitsAtAnExactStopWithTheNewSpeedOut) {
  // G0 X5 with the spindle starting (M3 S6000), G1 X10 (waits), G1 X15 S6000 (no wait),
  // G1 X20 S8000 (speed change: waits), M5 G1 X25 (spindle off: no wait).
  PlannerParams pp;
  BlendPlanner pl(pp, Vector3d::Zero());
  auto move = [&](int line, double x, bool rapid, SpindleDir dir, double rpm) {
    Block b;
    b.line = line;
    b.rapid = rapid;
    b.feed_mm_min = 1200;
    b.seg = PathSegment::line(Vector3d(x - 5, 0, 0), Vector3d(x, 0, 0));
    b.spindle = dir;
    b.spindle_rpm = rpm;
    pl.push(b);
  };
  move(1, 5, true, SpindleDir::kCw, 6000);
  move(2, 10, false, SpindleDir::kCw, 6000);
  move(3, 15, false, SpindleDir::kCw, 6000);
  move(4, 20, false, SpindleDir::kCw, 8000);
  move(5, 25, false, SpindleDir::kOff, 0);
  Interpolator ip;
  const auto kinds = end_and_load(pl, ip);
  const auto markers = std::count(kinds.begin(), kinds.end(), SegmentKind::kSpindleSync);
  EXPECT_EQ(markers, 2);
  InterpOutput out;
  std::vector<double> wait_x, wait_rpm;
  for (int n = 0; n < 200000; ++n) {
    const auto st = ip.step(1.0, out);
    if (st == InterpStatus::kDone) break;
    if (st != InterpStatus::kSpindleWait) continue;
    wait_x.push_back(out.position_mm.x());
    wait_rpm.push_back(out.spindle_rpm);
    // Waits until resumed, standing still, the new speed already out.
    for (int i = 0; i < 50; ++i) {
      ASSERT_EQ(ip.step(1.0, out), InterpStatus::kSpindleWait);
      EXPECT_EQ(out.position_mm.x(), wait_x.back());
      EXPECT_EQ(out.spindle, SpindleDir::kCw);
    }
    ip.resume();
  }
  EXPECT_EQ(out.position_mm, Vector3d(25, 0, 0));
  ASSERT_EQ(wait_x.size(), 2u);
  EXPECT_EQ(wait_x[0], 5.0);  // exact stop at the end of the rapid
  EXPECT_EQ(wait_rpm[0], 6000.0);
  EXPECT_EQ(wait_x[1], 15.0);
  EXPECT_EQ(wait_rpm[1], 8000.0);
}

namespace {
// G1 X10 / G0 Y50 / G1 X0 as planned segments (exact stops between them: G61).
std::vector<PlannedSegment> plan_feed_rapid_feed(bool rapid_first = false) {
  const std::vector<Vector3d> pts = {{0, 0, 0}, {10, 0, 0}, {10, 50, 0}, {0, 50, 0}};
  const std::vector<bool> rapid =
      rapid_first ? std::vector<bool>{true, false, false} : std::vector<bool>{false, true, false};
  std::vector<Block> blocks;
  for (std::size_t i = 1; i < 4; ++i) {
    Block b;
    b.line = static_cast<int>(i);
    b.rapid = rapid[i - 1];
    b.feed_mm_min = b.rapid ? 6000 : 1500;
    b.blend = BlendMode::kExactStop;
    b.seg = PathSegment::line(pts[i - 1], pts[i]);
    blocks.push_back(b);
  }
  return plan_blocks(blocks);
}
}  // namespace

// LinuxCNC's split: the feed override scales feed moves, the rapid override rapids (G0); a change
// between them is rate-limited like any override change.
TEST(Interpolator, RapidOverrideAppliesToRapidsAndFeedOverrideToFeedMoves) {
  Interpolator ip;
  InterpolatorParams p;
  ip.configure(p, Vector3d::Zero());
  for (const auto& s : plan_feed_rapid_feed()) ASSERT_TRUE(ip.push(s));
  InterpOutput out;
  double max_on_rapid = 0.0, max_on_feed = 0.0, prev = -1.0, max_step = 0.0;
  int rapid_cycles = 0, n = 0;
  while (ip.step(0.5, 1.0, out) != InterpStatus::kDone && n < 200000) {
    ++n;
    if (out.rapid) {
      ++rapid_cycles;
      max_on_rapid = std::max(max_on_rapid, out.override_applied);
    } else if (n > p.fir_taps) {  // (the interpolator starts at 100 % and ramps to the first ratio)
      max_on_feed = std::max(max_on_feed, out.override_applied);
    }
    if (prev >= 0.0) max_step = std::max(max_step, std::abs(out.override_applied - prev));
    prev = out.override_applied;
  }
  ASSERT_EQ(out.status, InterpStatus::kDone);
  EXPECT_GT(rapid_cycles, 200);
  EXPECT_NEAR(max_on_rapid, 1.0, 1e-12);  // the rapid at 100 %, though the feed override is 50 %
  EXPECT_LE(max_on_feed, 0.5 + 1.0 / (p.fir_taps - 1) + 1e-12);  // feed moves at 50 % (+ one ramp step)
  EXPECT_LE(max_step, 1.0 / (p.fir_taps - 1) + 1e-12);  // never a step in the time scale
  EXPECT_TRUE((out.position_mm - Vector3d(0, 50, 0)).norm() < 1e-9) << out.position_mm.transpose();
}

// Feed override 0 % does not stop a rapid (LinuxCNC): the program's first move, a rapid, runs to
// its end; the feed move after it does not start (no creep while the time scale ramps down).
TEST(Interpolator, FeedOverrideZeroLetsTheRapidRunAndHoldsTheFeedMove) {
  Interpolator ip;
  ip.configure(InterpolatorParams{}, Vector3d::Zero());
  for (const auto& s : plan_feed_rapid_feed(true)) ASSERT_TRUE(ip.push(s));
  InterpOutput out;
  for (int k = 0; k < 20000; ++k) ip.step(0.0, 1.0, out);
  const Vector3d stands = out.position_mm;
  for (int k = 0; k < 500; ++k) ip.step(0.0, 1.0, out);
  EXPECT_EQ(out.status, InterpStatus::kRunning);
  EXPECT_EQ(out.override_applied, 0.0);
  EXPECT_EQ(out.position_mm, stands);
  // At the rapid's end (10, 0, 0): the path braked in time to stand at the feed move's start.
  EXPECT_LT((out.position_mm - Vector3d(10, 0, 0)).norm(), 0.01) << out.position_mm.transpose();
}

// The optional stop switch is live (LinuxCNC): judged when the path reaches the M1.
TEST(Interpolator, OptionalStopSwitchIsJudgedWhenThePathReachesTheM1) {
  auto plan_with_m1 = [] {
    Block a;
    a.line = 1;
    a.feed_mm_min = 1500;
    a.blend = BlendMode::kExactStop;
    a.seg = PathSegment::line(Vector3d::Zero(), Vector3d(5, 0, 0));
    Block m1;
    m1.kind = BlockKind::kOptionalStop;
    m1.line = 2;
    Block b = a;
    b.line = 3;
    b.seg = PathSegment::line(Vector3d(5, 0, 0), Vector3d(5, 5, 0));
    return plan_blocks({a, m1, b});
  };
  for (const bool on : {false, true}) {
    Interpolator ip;
    InterpolatorParams p;
    p.optional_stop = !on;  // configured the other way; the switch flips it before the M1
    ip.configure(p, Vector3d::Zero());
    for (const auto& s : plan_with_m1()) ASSERT_TRUE(ip.push(s));
    InterpOutput out;
    ip.step(1.0, out);
    ip.set_optional_stop(on);
    bool held = false;
    for (int k = 0; k < 20000 && out.status != InterpStatus::kDone; ++k) {
      ip.step(1.0, out);
      if (out.status == InterpStatus::kHolding) {
        held = true;
        EXPECT_LT((out.position_mm - Vector3d(5, 0, 0)).norm(), 1e-9);
        ip.resume();
      }
    }
    EXPECT_EQ(held, on) << "switch " << on;
    EXPECT_EQ(out.status, InterpStatus::kDone);
  }
}

namespace {
// The square of plan_square (4 lines) blended at 20 um, plus an arc line as its 5th line (planned
// as several chords: one line, several segments).
std::vector<PlannedSegment> plan_square_and_arc() {
  const Vector3d pts[] = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}, {0, 0, 0}};
  std::vector<Block> blocks;
  for (int i = 1; i < 5; ++i) {
    Block b;
    b.line = i;
    b.feed_mm_min = 1500;
    b.blend = BlendMode::kLimited;
    b.tolerance_mm = 0.02;
    b.seg = PathSegment::line(pts[i - 1], pts[i]);
    blocks.push_back(b);
  }
  Block arc = blocks.back();
  arc.line = 5;
  arc.seg.kind = PathSegment::Kind::kArc;  // G2 X0 Y10 J5: a half circle through (-5, 5)
  arc.seg.start = Vector3d(0, 0, 0);
  arc.seg.end = Vector3d(0, 10, 0);
  arc.seg.center = Vector3d(0, 5, 0);
  blocks.push_back(arc);
  return plan_blocks(blocks);
}

// Distance from p to the polyline of the square's four sides and the arc's circle (the programmed
// path; blended corners lie within the 20 um tolerance of it).
double off_square_path(const Vector3d& p) {
  const Vector3d pts[] = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}, {0, 0, 0}};
  double d = std::abs((p - Vector3d(0, 5, 0)).norm() - 5.0) + std::abs(p.z());
  for (int i = 1; i < 5; ++i) {
    const Vector3d a = pts[i - 1], b = pts[i];
    const double u = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
    d = std::min(d, (p - (a + u * (b - a))).norm());
  }
  return d;
}
}  // namespace

// Single block (LinuxCNC's step): the path stands before each new line, on the path, and resume
// runs the next line; the chords of one line (the arc) never stop between them.
TEST(Interpolator, SingleBlockStandsBeforeEachNewLineOnThePath) {
  const auto segs = plan_square_and_arc();
  std::size_t arc_segments = 0;
  for (const auto& s : segs) arc_segments += s.kind == SegmentKind::kMotion && s.line == 5 ? 1 : 0;
  ASSERT_GT(arc_segments, 1u);
  Interpolator ip;
  ip.configure(InterpolatorParams{}, Vector3d::Zero());
  for (const auto& s : segs) ASSERT_TRUE(ip.push(s));
  ip.set_single_block(true);
  InterpOutput out;
  std::vector<int> stop_lines;
  double worst_off = 0.0, prev_ovr = 1.0, max_step = 0.0;
  int k = 0;
  for (; k < 200000 && out.status != InterpStatus::kDone; ++k) {
    ip.step(1.0, out);
    worst_off = std::max(worst_off, off_square_path(out.position_mm));
    max_step = std::max(max_step, std::abs(out.override_applied - prev_ovr));
    prev_ovr = out.override_applied;
    if (out.status == InterpStatus::kHolding) {
      ASSERT_TRUE(out.single_block_stop);
      EXPECT_EQ(out.hold_kind, SegmentKind::kMotion);
      EXPECT_EQ(out.override_applied, 0.0);
      stop_lines.push_back(out.line);
      // It stands: more cycles do not move it.
      const Vector3d p = out.position_mm;
      for (int i = 0; i < 50; ++i) ip.step(1.0, out);
      EXPECT_EQ(out.position_mm, p);
      EXPECT_EQ(out.status, InterpStatus::kHolding);
      ip.resume();
    }
  }
  ASSERT_EQ(out.status, InterpStatus::kDone);
  EXPECT_EQ(stop_lines, (std::vector<int>{1, 2, 3, 4}));  // before lines 2..5, never inside the arc
  EXPECT_LT(worst_off, 0.02 + 1e-6);  // on the verified path throughout
  EXPECT_LE(max_step, 1.0 / (InterpolatorParams{}.fir_taps - 1) + 1e-12);  // ramps, never a step
  EXPECT_LT((out.position_mm - Vector3d(0, 10, 0)).norm(), 1e-9);
  EXPECT_FALSE(out.single_block_stop);
}

// With exact stop (G61) the single-block stand is the block's end point; switching single block
// off while standing does not move the path until resume, then it runs to the end without stops.
TEST(Interpolator, SingleBlockWithExactStopStandsAtTheVertexAndSwitchesOffLive) {
  Interpolator ip;
  ip.configure(InterpolatorParams{}, Vector3d::Zero());
  for (const auto& s : plan_square(BlendMode::kExactStop)) ASSERT_TRUE(ip.push(s));
  ip.set_single_block(true);
  InterpOutput out;
  int k = 0;
  while (ip.step(1.0, out) != InterpStatus::kHolding && k < 100000) ++k;
  ASSERT_EQ(out.status, InterpStatus::kHolding);
  EXPECT_LT((out.position_mm - Vector3d(10, 0, 0)).norm(), 1e-9) << out.position_mm.transpose();
  ip.set_single_block(false);
  for (int i = 0; i < 100; ++i) ip.step(1.0, out);
  EXPECT_EQ(out.status, InterpStatus::kHolding);
  ip.resume();
  int holds = 0;
  for (k = 0; k < 100000 && out.status != InterpStatus::kDone; ++k) {
    ip.step(1.0, out);
    holds += out.status == InterpStatus::kHolding ? 1 : 0;
  }
  EXPECT_EQ(holds, 0);
  EXPECT_EQ(out.status, InterpStatus::kDone);
}

// Switched on too late to stand before the next line, the path stands inside it and, after
// resume, runs to that line's end and stops there (no line runs past unseen).
TEST(Interpolator, SingleBlockSwitchedOnLateStandsInsideTheLineAndStopsAtItsEnd) {
  Interpolator ip;
  ip.configure(InterpolatorParams{}, Vector3d::Zero());
  for (const auto& s : plan_square(BlendMode::kExactStop)) ASSERT_TRUE(ip.push(s));
  InterpOutput out;
  // Run until line 2 (X10 Y0 -> X10 Y10) is in its last few cycles: less than the ramp from
  // 100 % to 0 needs before line 3 starts.
  int k = 0;
  while (k < 100000 && !(out.line == 2 && out.position_mm.y() > 9.9)) {
    ip.step(1.0, out);
    ++k;
  }
  ASSERT_EQ(out.line, 2);
  ip.set_single_block(true);
  while (ip.step(1.0, out) != InterpStatus::kHolding && k < 200000) ++k;
  ASSERT_TRUE(out.single_block_stop);
  EXPECT_EQ(out.line, 3);  // inside line 3 (X10 Y10 -> X0 Y10)
  EXPECT_LT(out.position_mm.x(), 10.0);
  EXPECT_GT(out.position_mm.x(), 9.0);
  EXPECT_NEAR(out.position_mm.y(), 10.0, 1e-9);
  ip.resume();
  while (ip.step(1.0, out) != InterpStatus::kHolding && k < 300000) ++k;
  ASSERT_TRUE(out.single_block_stop);
  EXPECT_LT((out.position_mm - Vector3d(0, 10, 0)).norm(), 1e-9) << out.position_mm.transpose();
}
