// Seed 004 reproduction (paper diamond) and the issue-3 guarantees of the blend planner, checked
// against an error measurement independent of the planner (17 points per output chord, distance
// to the programmed segments).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/path.hpp"

using namespace contour::control;
using Eigen::Vector3d;

namespace {

Block line_block(int line, double feed, BlendMode mode, double tol_mm) {
  Block b;
  b.kind = BlockKind::kMotion;
  b.line = line;
  b.feed_mm_min = feed;
  b.blend = mode;
  b.tolerance_mm = tol_mm;
  return b;
}

std::vector<Block> polyline(const std::vector<Vector3d>& pts, const std::vector<double>& feeds,
                            BlendMode mode, double tol_mm) {
  std::vector<Block> out;
  for (std::size_t i = 1; i < pts.size(); ++i) {
    Block b = line_block(static_cast<int>(i), feeds[(i - 1) % feeds.size()], mode, tol_mm);
    b.seg = PathSegment::line(pts[i - 1], pts[i]);
    out.push_back(b);
  }
  Block e;
  e.kind = BlockKind::kEnd;
  e.line = static_cast<int>(pts.size());
  out.push_back(e);
  return out;
}

struct Sim {
  std::vector<Vector3d> q;  // q[t], t = 0 .. end
  std::vector<PlannedSegment> segs;
  std::vector<CornerReport> corners;
  PlannerStats stats;
};

Sim simulate(const PlannerParams& pp, const std::vector<Block>& blocks, const Vector3d& start,
             double override_ratio = 1.0) {
  Sim s;
  BlendPlanner pl(pp, start);
  pl.on_corner([&](const CornerReport& c) { s.corners.push_back(c); });
  for (const auto& b : blocks) pl.push(b);
  PlannedSegment seg;
  while (pl.pop(seg)) s.segs.push_back(seg);
  s.stats = pl.stats();
  Interpolator ip;
  InterpolatorParams p;
  p.fir_taps = pp.fir_taps;
  p.fir2_taps = pp.fir2_taps;
  p.capacity = s.segs.size() + 8;
  ip.configure(p, start);
  for (const auto& x : s.segs) ip.push(x);
  s.q.push_back(start);
  InterpOutput out;
  for (int guard = 0; guard < 50'000'000; ++guard) {
    const auto st = ip.step(override_ratio, out);
    s.q.push_back(out.position_mm);
    if (st == InterpStatus::kDone) break;
  }
  return s;
}

// Independent measurement: max distance of the output polyline to the programmed polyline
// (chords sampled at 17 points), and max distance from each interior vertex to the output.
struct Measure {
  double path_mm = 0.0;
  double vertex_mm = 0.0;
  double max_speed_mm_min = 0.0;
};

Measure measure(const Sim& s, const std::vector<Vector3d>& pts, double period_s, int taps) {
  Measure m;
  // Active move window per t from the planned segments (moves are in program order).
  std::size_t lo = 0;
  const std::int64_t tail = taps - 1;
  std::vector<double> vbest(pts.size(), 1e300);
  std::size_t hi = 0;
  for (std::size_t t = 1; t < s.q.size(); ++t) {
    const auto tt = static_cast<std::int64_t>(t);
    while (lo + 1 < s.segs.size() && s.segs[lo].start_cycle + s.segs[lo].samples + tail < tt - 1) ++lo;
    while (hi + 1 < s.segs.size() && s.segs[hi + 1].start_cycle <= tt) ++hi;
    const Vector3d a = s.q[t - 1], b = s.q[t];
    m.max_speed_mm_min = std::max(m.max_speed_mm_min, (b - a).norm() / period_s * 60.0);
    for (int k = 0; k <= 16; ++k) {
      const Vector3d x = a + (b - a) * (k / 16.0);
      double d = 1e300;
      for (std::size_t j = (lo > 0 ? lo - 1 : 0); j <= std::min(hi + 1, s.segs.size() - 1); ++j)
        d = std::min(d, distance_point_segment(x, s.segs[j].start_mm, s.segs[j].end_mm));
      m.path_mm = std::max(m.path_mm, d);
    }
    for (std::size_t j = (lo > 0 ? lo - 1 : 0); j <= std::min(hi + 1, s.segs.size() - 1); ++j) {
      const std::size_t vi = j + 1;  // end vertex of move j in pts (no zero-length moves here)
      if (vi < pts.size()) vbest[vi] = std::min(vbest[vi], distance_point_segment(pts[vi], a, b));
    }
  }
  for (std::size_t i = 1; i + 1 < pts.size(); ++i) m.vertex_mm = std::max(m.vertex_mm, vbest[i]);
  return m;
}

const std::vector<Vector3d> kDiamond = {{0, 0, 0}, {10, 10, 0}, {20, 0, 0}, {10, -10, 0}, {0, 0, 0}};
const std::vector<double> kDiamondFeeds = {1200, 600, 1500, 900};

PlannerParams paper_params(BlendMethod m) {
  PlannerParams p;
  p.fir_taps = 101;  // t_A/T + 1 (interpretation.md)
  p.floor_rounding = true;
  p.method = m;
  return p;
}

}  // namespace

// Paper §4 Fig: G64 errors 170.5 / 187.3 / 237.2 um (sampled, eq 6), time 3.728 s.
TEST(BlendPaper, DiamondFullOverlap) {
  auto pp = paper_params(BlendMethod::kPaper);
  const auto s = simulate(pp, polyline(kDiamond, kDiamondFeeds, BlendMode::kFull, 0.05), kDiamond[0]);
  ASSERT_EQ(s.corners.size(), 3u);
  const double want[3] = {170.5, 187.3, 237.2};
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(s.corners[static_cast<std::size_t>(i)].model_error_mm * 1e3, want[i], 2.0) << i;
    EXPECT_EQ(s.corners[static_cast<std::size_t>(i)].overlap_cycles, 100);
  }
  const double dur = static_cast<double>(s.q.size() - 1) * 1e-3;
  EXPECT_NEAR(dur, 3.728, 0.005);
  EXPECT_EQ(s.q.back(), kDiamond.back());
}

// After the limit: every corner <= 50 um (paper: 49.1 49.1 48.3), time 3.879 s.
TEST(BlendPaper, DiamondLimited) {
  auto pp = paper_params(BlendMethod::kPaper);
  const auto s = simulate(pp, polyline(kDiamond, kDiamondFeeds, BlendMode::kLimited, 0.05), kDiamond[0]);
  ASSERT_EQ(s.corners.size(), 3u);
  const double want[3] = {49.1, 49.1, 48.3};
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(s.corners[static_cast<std::size_t>(i)].model_error_mm, 0.05);
    EXPECT_NEAR(s.corners[static_cast<std::size_t>(i)].model_error_mm * 1e3, want[i], 0.1) << i;
  }
  EXPECT_NEAR(static_cast<double>(s.q.size() - 1) * 1e-3, 3.879, 0.005);
}

// The paper's incremental search equals the exhaustive search of its own two-block model.
TEST(BlendPaper, IncrementalMatchesExhaustiveTwoBlock) {
  BlendPlanner pl(paper_params(BlendMethod::kPaper), Vector3d::Zero());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ang(0.0, 2 * std::numbers::pi), len(0.2, 20.0), feed(300, 3000),
      eps(0.005, 0.2);
  int mismatches = 0;
  for (int i = 0; i < 300; ++i) {
    const double a1 = ang(rng), a2 = ang(rng), l1 = len(rng), l2 = len(rng), f1 = feed(rng), f2 = feed(rng);
    const Vector3d v(l1 * std::cos(a1), l1 * std::sin(a1), 0);
    const Vector3d e = v + Vector3d(l2 * std::cos(a2), l2 * std::sin(a2), 0);
    const auto na = static_cast<std::int64_t>(std::floor(l1 / (f1 / 60e3)));
    const auto nb = static_cast<std::int64_t>(std::floor(l2 / (f2 / 60e3)));
    if (na < 1 || nb < 1) continue;
    const double ep = eps(rng);
    const auto inc = pl.paper_two_block(Vector3d::Zero(), v, e, na, nb, ep, true);
    const auto exh = pl.paper_two_block(Vector3d::Zero(), v, e, na, nb, ep, false);
    if (inc.overlap_cycles != exh.overlap_cycles) ++mismatches;
  }
  EXPECT_EQ(mismatches, 0);
}

// Beyond the paper on the diamond: true path error and vertex distance both <= eps.
TEST(BlendTrue, DiamondHoldsTrueAndVertexTolerance) {
  PlannerParams pp = paper_params(BlendMethod::kTrue);
  const auto s = simulate(pp, polyline(kDiamond, kDiamondFeeds, BlendMode::kLimited, 0.05), kDiamond[0]);
  const auto m = measure(s, kDiamond, 1e-3, 101);
  EXPECT_LE(m.path_mm, 0.05 + 1e-9);
  EXPECT_LE(m.vertex_mm, 0.05 + 1e-9);
  // The paper's own schedule violates the two-sided requirement (vertex ~70 um).
  const auto sp = simulate(paper_params(BlendMethod::kPaper),
                           polyline(kDiamond, kDiamondFeeds, BlendMode::kLimited, 0.05), kDiamond[0]);
  EXPECT_GT(measure(sp, kDiamond, 1e-3, 101).vertex_mm, 0.06);
}

// Closed form for long-block corners (interpretation.md): e = sin(th) t_o^2/(2 t_A) F1F2/(vF1+vF2)^2
// with t_o = (M+1) T, is an upper bound of the sampled error, and tight (within 5 %).
TEST(BlendTrue, ClosedFormBoundsLongBlockCorners) {
  BlendPlanner pl(paper_params(BlendMethod::kPaper), Vector3d::Zero());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> turn(0.2, 2.6), feed(300, 3000);
  for (int i = 0; i < 200; ++i) {
    const double th = turn(rng), f1 = feed(rng), f2 = feed(rng);
    const Vector3d v(50, 0, 0), e = v + 50 * Vector3d(std::cos(th), std::sin(th), 0);
    const auto na = static_cast<std::int64_t>(std::floor(50 / (f1 / 60e3)));
    const auto nb = static_cast<std::int64_t>(std::floor(50 / (f2 / 60e3)));
    const auto r = pl.paper_two_block(Vector3d::Zero(), v, e, na, nb, 1e9, false);
    const double t_o = (r.overlap_cycles + 1) * 1e-3, t_a = 0.1;
    const double F1 = f1 / 60, F2 = f2 / 60;
    const double bound = std::sin(th) * t_o * t_o / (2 * t_a) * F1 * F2 / std::pow(std::sqrt(F1) + std::sqrt(F2), 2);
    EXPECT_LE(r.error_mm, bound * (1 + 1e-9)) << th << " " << f1 << " " << f2;
    EXPECT_GE(r.error_mm, 0.95 * bound) << th << " " << f1 << " " << f2;
  }
}

// Seeded random polylines, short and long blocks, random feeds, near-reversals included:
// true error <= eps always; time within 1 % of the exhaustive per-corner search.
TEST(BlendTrue, RandomPolylinesHoldToleranceAndTime) {
  // Unoptimised sanitizer builds (the `dev` preset) run seed 1 only (same checks, ten times
  // slower); optimised builds run seeds 1-3.
#if defined(NDEBUG)
  constexpr unsigned kSeeds = 3;
#else
  constexpr unsigned kSeeds = 1;
  std::printf("debug build: seed 1 of 3 (optimised builds run all)\n");
#endif
  int corners = 0;
  double t_true = 0, t_exh = 0, worst = 0, worst_v = 0;
  for (unsigned seed = 1; seed <= kSeeds; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> ang(-std::numbers::pi, std::numbers::pi), u(0, 1), feed(300, 3000);
    std::vector<Vector3d> pts{Vector3d::Zero()};
    std::vector<double> feeds;
    double heading = 0;
    for (int i = 0; i < 400; ++i) {
      heading += (u(rng) < 0.1) ? std::numbers::pi - 0.3 * u(rng) : 0.8 * ang(rng);  // 10 % near-reversals
      const double l = u(rng) < 0.6 ? 0.05 + 0.6 * u(rng) : 1 + 4 * u(rng);
      pts.push_back(pts.back() + l * Vector3d(std::cos(heading), std::sin(heading), 0));
      feeds.push_back(feed(rng));
    }
    corners += 399;
    const auto blocks = polyline(pts, feeds, BlendMode::kLimited, 0.05);
    PlannerParams pp;
    pp.fir_taps = 101;
    const auto s = simulate(pp, blocks, pts[0]);
    const auto m = measure(s, pts, 1e-3, 101);
    EXPECT_LE(m.path_mm, 0.05 + 1e-9) << "seed " << seed;
    EXPECT_LE(m.vertex_mm, 0.05 + 1e-9) << "seed " << seed;
    EXPECT_LE(m.max_speed_mm_min, 3000 + 1e-6);
    worst = std::max(worst, m.path_mm);
    worst_v = std::max(worst_v, m.vertex_mm);
    EXPECT_EQ(s.q.back(), pts.back());
    pp.method = BlendMethod::kExhaustive;
    const auto se = simulate(pp, blocks, pts[0]);
    t_true += static_cast<double>(s.q.size());
    t_exh += static_cast<double>(se.q.size());
  }
  EXPECT_GE(corners, static_cast<int>(330 * kSeeds));
  EXPECT_LE(t_true / t_exh, 1.01);
  RecordProperty("max_true_error_um", std::to_string(worst * 1e3));
  RecordProperty("time_ratio_vs_exhaustive", std::to_string(t_true / t_exh));
  std::cout << "random polylines: corners " << corners << " max true error " << worst * 1e3 << " um, max vertex error "
            << worst_v * 1e3 << " um, time ratio vs exhaustive " << t_true / t_exh << "\n";
}

// The paper's method on the same kind of path breaks the limit (3+ blocks in motion, reversals).
TEST(BlendPaper, ShortBlocksBreakThePapersModel) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vector3d> pts{Vector3d::Zero()};
  double heading = 0;
  for (int i = 0; i < 200; ++i) {
    heading += 1.2 * (u(rng) - 0.5);
    pts.push_back(pts.back() + (0.1 + 0.4 * u(rng)) * Vector3d(std::cos(heading), std::sin(heading), 0));
  }
  const auto s = simulate(paper_params(BlendMethod::kPaper), polyline(pts, {1500}, BlendMode::kLimited, 0.05), pts[0]);
  EXPECT_GT(measure(s, pts, 1e-3, 101).path_mm, 0.06);
}

TEST(BlendTrue, CollinearFeedChangeDoesNotOvershoot) {
  for (const auto& feeds : {std::vector<double>{600, 1800, 900}, std::vector<double>{1800, 600, 1800}}) {
    const std::vector<Vector3d> pts = {{0, 0, 0}, {10, 0, 0}, {20, 0, 0}, {30, 0, 0}};
    PlannerParams pp;
    const auto s = simulate(pp, polyline(pts, feeds, BlendMode::kLimited, 0.05), pts[0]);
    const auto m = measure(s, pts, 1e-3, 101);
    EXPECT_LE(m.max_speed_mm_min, *std::max_element(feeds.begin(), feeds.end()) + 1e-6);
    EXPECT_LE(m.path_mm, 1e-9);
    for (const auto& c : s.corners) EXPECT_EQ(c.overlap_cycles, 100);  // collinear: full overlap
  }
}

TEST(BlendTrue, ReversalKeepsTheTip) {
  for (double deg : {150.0, 170.0, 179.0, 180.0}) {
    const double th = deg * std::numbers::pi / 180;
    const std::vector<Vector3d> pts = {{0, 0, 0}, {10, 0, 0}, Vector3d(10, 0, 0) + 10 * Vector3d(std::cos(th), std::sin(th), 0)};
    const auto s = simulate(PlannerParams{}, polyline(pts, {1500}, BlendMode::kLimited, 0.05), pts[0]);
    const auto m = measure(s, pts, 1e-3, 101);
    EXPECT_LE(m.vertex_mm, 0.05 + 1e-9) << deg;
    EXPECT_LE(m.path_mm, 0.05 + 1e-9) << deg;
  }
}

TEST(BlendTrue, ZeroLengthBlocksDropped) {
  std::vector<Vector3d> pts = {{0, 0, 0}, {5, 0, 0}, {5, 0, 0}, {5, 5, 0}};
  PlannerParams pp;
  BlendPlanner pl(pp, pts[0]);
  for (const auto& b : polyline(pts, {1000}, BlendMode::kLimited, 0.05)) pl.push(b);
  EXPECT_EQ(pl.stats().dropped_zero_length, 1);
  EXPECT_EQ(pl.stats().moves, 2);
}

TEST(BlendTrue, CeilRoundingNeverExceedsFeedOnShortBlocks) {
  // 0.0105 mm at 600 mm/min is 1.05 samples: floor would give 1 (5 % fast), ceil gives 2.
  std::vector<Vector3d> pts{Vector3d::Zero()};
  for (int i = 0; i < 400; ++i) pts.push_back(pts.back() + Vector3d(0.0105, 0, 0));
  PlannerParams pp;
  const auto s = simulate(pp, polyline(pts, {600}, BlendMode::kFull, 0.05), pts[0]);
  EXPECT_LE(measure(s, pts, 1e-3, 101).max_speed_mm_min, 600 + 1e-6);
  pp.floor_rounding = true;
  const auto sf = simulate(pp, polyline(pts, {600}, BlendMode::kFull, 0.05), pts[0]);
  EXPECT_GT(measure(sf, pts, 1e-3, 101).max_speed_mm_min, 600 * 1.01);
}

TEST(BlendTrue, AxisVelocityAndAccelerationLimits) {
  PlannerParams pp;
  pp.max_velocity_mm_min = Vector3d(1000, 2000, 1000);
  pp.max_accel_mm_s2 = Vector3d(200, 200, 200);
  const std::vector<Vector3d> pts = {{0, 0, 0}, {20, 0, 0}, {20, 20, 0}, {0, 0, 0}};
  const auto s = simulate(pp, polyline(pts, {3000}, BlendMode::kFull, 0.05), pts[0]);
  double vmax[3] = {0, 0, 0}, amax[3] = {0, 0, 0};
  for (std::size_t t = 2; t < s.q.size(); ++t) {
    const Vector3d v = (s.q[t] - s.q[t - 1]) / 1e-3, v0 = (s.q[t - 1] - s.q[t - 2]) / 1e-3;
    for (int i = 0; i < 3; ++i) {
      vmax[i] = std::max(vmax[i], std::abs(v[i]) * 60);
      amax[i] = std::max(amax[i], std::abs(v[i] - v0[i]) / 1e-3);
    }
  }
  EXPECT_LE(vmax[0], 1000 + 1e-6);
  EXPECT_LE(vmax[1], 2000 + 1e-6);
  for (double a : amax) EXPECT_LE(a, 200 * (1 + 1e-6));
}
