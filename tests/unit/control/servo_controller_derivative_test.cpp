// The derivative filter (issue 16 command chatter): with an exact drive model the model blend
// leaves the loop as it is and removes the encoder's counts from the derivative; the drive models
// follow clamped commands (command_applied); the per-cycle update stays allocation-free.
#include <gtest/gtest.h>

#include <cmath>

#include "control/chatter_monitor.hpp"
#include "control/contour_error.hpp"
#include "control/feed_drive.hpp"
#include "control/servo_controller.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::control {
namespace {

ServoParams table1(double blend_s, SameGeometry sg = SameGeometry::kNever) {
  ServoParams p;
  p.delay_cycles = 1;
  p.drive[2].gain_per_s = 115.0;
  p.drive[2].tau_s = 0.025;
  p.derivative.model_blend_s = blend_s;
  p.derivative.same_geometry = sg;
  return p;
}

struct LineRun {
  std::vector<std::array<double, 3>> v;  // velocity commands K u
  double max_error_mm = 0.0;             // |R - P| across the path (the line is along X+Y)
};

// A 60 mm/s move along a 3-D line through the real controller, contour-error model and three
// FeedDrive plants (delay 1), with or without BLU quantisation.
LineRun run_line(const ServoParams& p, double blu_mm, int cycles = 1500) {
  ServoController c(p);
  ContourErrorModel model;
  std::array<FeedDrive, 3> d{};
  for (std::size_t i = 0; i < 3; ++i) {
    FeedDriveParams f = p.drive[i];
    f.delay_cycles = 1;
    f.blu_mm = blu_mm;
    d[i].configure(f);
    d[i].reset(0.0);
  }
  const Vec3 dir = Vec3(3, 2, -1).normalized();
  LineRun out;
  for (int k = 0; k < cycles; ++k) {
    const double s = k < 1000 ? 0.06 * k : 60.0;  // mm: 60 mm/s for 1 s, then rest
    const Vec3 r = dir * s;
    const Vec3 pm(d[0].measured_mm(), d[1].measured_mm(), d[2].measured_mm());
    const Vec3 ph = c.predict(pm);
    model.push_reference(r);
    const ContourErrorResult ce = model.update(ph);
    Vec3 u;
    c.update(r, ph, ce, Vec3::Zero(), u);
    for (std::size_t i = 0; i < 3; ++i) d[i].step(u[static_cast<Eigen::Index>(i)]);
    out.v.push_back({120.0 * u[0], 120.0 * u[1], 115.0 * u[2]});
    const Vec3 pt(d[0].position_mm(), d[1].position_mm(), d[2].position_mm());
    const Vec3 e = r - pt;
    out.max_error_mm = std::max(out.max_error_mm, (e - dir * dir.dot(e)).norm());
  }
  return out;
}

TEST(DerivativeFilter, ExactModelLeavesTheLoopUnchanged) {
  // No quantisation, exact model: P_hat - m is zero, the commands are the paper law's.
  const LineRun a = run_line(table1(0.0), 0.0);
  const LineRun b = run_line(table1(0.005), 0.0);
  double worst = 0.0;
  for (std::size_t k = 0; k < a.v.size(); ++k) {
    for (std::size_t i = 0; i < 3; ++i) worst = std::max(worst, std::abs(a.v[k][i] - b.v[k][i]));
  }
  EXPECT_LT(worst, 1e-6);  // mm/s
}

TEST(DerivativeFilter, RemovesTheEncoderCountsFromTheCommand) {
  const LineRun raw = run_line(table1(0.0), 0.0005);
  const LineRun blended = run_line(table1(0.005), 0.0005);
  const ChatterFigure fr = command_chatter(raw.v, 3);
  const ChatterFigure fb = command_chatter(blended.v, 3);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_GT(fr.rms_mm_s[i], 5.0) << i;  // the round-1 law: counts x Cd K / T
    EXPECT_LT(fb.rms_mm_s[i], 1.0) << i;
    EXPECT_LT(fb.rms_mm_s[i], 0.1 * fr.rms_mm_s[i]) << i;
  }
  // The contour error stays what it was (within one count).
  EXPECT_NEAR(blended.max_error_mm, raw.max_error_mm, 0.0005);
}

TEST(DerivativeFilter, LowpassAddsLagAndDoesNotRemoveTheCounts) {
  // The textbook filtered D at 1 ms: less chatter than the raw law, far from the model blend.
  ServoParams p = table1(0.0);
  p.derivative.lowpass_s = 0.001;
  const ChatterFigure f = command_chatter(run_line(p, 0.0005).v, 3);
  const ChatterFigure fb = command_chatter(run_line(table1(0.005), 0.0005).v, 3);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_GT(f.rms_mm_s[i], 3.0 * fb.rms_mm_s[i]) << i;
}

TEST(DerivativeFilter, SameGeometryOnAStraightLineChangesNothing) {
  const LineRun a = run_line(table1(0.005), 0.0005);
  const LineRun b = run_line(table1(0.005, SameGeometry::kAlways), 0.0005);
  double worst = 0.0;
  for (std::size_t k = 0; k < a.v.size(); ++k) {
    for (std::size_t i = 0; i < 3; ++i) worst = std::max(worst, std::abs(a.v[k][i] - b.v[k][i]));
  }
  EXPECT_LT(worst, 1e-6);
}

TEST(DerivativeFilter, CommandAppliedKeepsThePredictorOnTheRealDrive) {
  // The caller halves the command (a clamp): with command_applied the prediction is the real
  // drive's next position exactly; without, it is off by what the clamp took away.
  for (bool tell : {true, false}) {
    ServoParams p = table1(0.005);
    p.axes = 1;
    ServoController c(p);
    FeedDriveParams f;
    f.delay_cycles = 1;
    FeedDrive plant(f);
    ContourErrorResult ce;
    double worst = 0.0;
    for (int k = 0; k < 200; ++k) {
      const Vec3 ph = c.predict(Vec3(plant.position_mm(), 0, 0));
      Vec3 u;
      c.update(Vec3(1.0, 0, 0), ph, ce, Vec3::Zero(), u);
      const Vec3 applied = 0.5 * u;
      if (tell) c.command_applied(applied);
      plant.step(applied.x());
      // ph is the position the command computed at k meets: x(k+1) of the delayed plant.
      worst = std::max(worst, std::abs(ph.x() - plant.position_mm()));
    }
    if (tell) {
      EXPECT_LT(worst, 1e-12);
    } else {
      EXPECT_GT(worst, 1e-3);
    }
  }
}

TEST(DerivativeFilter, UpdateWithTheFilterDoesNotAllocate) {
  ServoParams p = table1(0.005, SameGeometry::kAhead);
  p.derivative.lowpass_s = 0.001;
  p.law = AxisLaw::kPid;
  ServoController c(p);
  ContourErrorResult ce;
  ce.status = ContourStatus::kOk;
  ce.branch = ContourBranch::kCircle;
  ce.centre = Vec3(0, 0, 0);
  ce.plane_normal = Vec3(0, 0, 1);
  ce.radius_mm = 5.0;
  ce.k_point = Vec3(5, 0, 0);
  ce.tangent = Vec3(0, 1, 0);
  std::size_t total = 0;
  {
    test::AllocGuard g;
    Vec3 u;
    for (int k = 0; k < 10000; ++k) {
      const Vec3 pm(5.0 + 1e-4 * std::sin(k * 0.01), 0.0, 0.0);
      ce.eps = ce.k_point - pm;
      c.update(Vec3(5, 0, 0), c.predict(pm), ce, Vec3::Zero(), u);
      c.command_applied(0.9 * u);
    }
    total = g.counts().total();
  }
  EXPECT_EQ(total, 0u);
}

TEST(DerivativeFilter, RejectsNegativeTimeConstants) {
  ServoParams p = table1(-0.001);
  EXPECT_THROW(ServoController{p}, std::invalid_argument);
  p = table1(0.005);
  p.derivative.lowpass_s = std::nan("");
  EXPECT_THROW(ServoController{p}, std::invalid_argument);
}

}  // namespace
}  // namespace contour::control
