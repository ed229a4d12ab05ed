#include "control/servo_controller.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "control/feed_drive.hpp"

using namespace contour::control;

namespace {
ServoParams base(AxisLaw law, bool couple) {
  ServoParams p;
  p.law = law;
  p.coupling.enable = couple;
  p.delay_cycles = 0;
  return p;
}
ContourErrorResult ce_of(const Vec3& eps, const Vec3& t = Vec3::Zero()) {
  ContourErrorResult r;
  r.eps = eps;
  r.tangent = t;
  r.status = ContourStatus::kOk;
  return r;
}
}  // namespace

TEST(ServoController, ProportionalLaw) {
  ServoController c(base(AxisLaw::kP, false));
  Vec3 u;
  c.update(Vec3(1, 2, 3), Vec3(0.5, 2.5, 3), ce_of(Vec3(9, 9, 9)), Vec3::Zero(), u);
  EXPECT_NEAR((u - Vec3(0.3, -0.3, 0.0)).norm(), 0.0, 1e-15);  // coupling off: eps ignored
}

TEST(ServoController, PidEq10FormWithLiteralGainOrder) {
  ServoParams p = base(AxisLaw::kPid, false);
  p.axis[0] = {0.69, 0.03, 0.06};  // kp, ki, kd: the paper's printed P, D, I mapped to P, I, D
  ServoController c(p);
  Vec3 u;
  const double t = 0.001;
  // e(0) = 1: integral includes the current sample (z/(z-1)), no derivative kick on the first cycle.
  c.update(Vec3(1, 0, 0), Vec3::Zero(), ce_of(Vec3::Zero()), Vec3::Zero(), u);
  EXPECT_NEAR(u.x(), 0.69 * 1 + 0.03 * t * 1, 1e-15);
  // e(1) = 2
  c.update(Vec3(2, 0, 0), Vec3::Zero(), ce_of(Vec3::Zero()), Vec3::Zero(), u);
  EXPECT_NEAR(u.x(), 0.69 * 2 + 0.03 * t * 3 + 0.06 * (2 - 1) / t, 1e-12);
}

TEST(ServoController, VelocityFeedForward) {
  ServoParams p = base(AxisLaw::kP, false);
  p.axis[1].ff = 1.0;
  ServoController c(p);
  Vec3 u;
  c.update(Vec3::Zero(), Vec3::Zero(), ce_of(Vec3::Zero()), Vec3(0, 60.0, 0), u);
  EXPECT_NEAR(u.y(), 60.0 / 120.0, 1e-15);  // v = K u
}

TEST(ServoController, CouplingAndTangentialIntegralRemoval) {
  ServoParams p = base(AxisLaw::kP, true);
  ServoController c(p);
  Vec3 u;
  const Vec3 t(1, 0, 0);
  for (int k = 0; k < 100; ++k) {
    c.update(Vec3::Zero(), Vec3::Zero(), ce_of(Vec3(0.01, 0.02, 0), t), Vec3::Zero(), u);
  }
  EXPECT_NEAR(c.coupling_integral().x(), 0.0, 1e-15);       // along the tangent: removed
  EXPECT_NEAR(c.coupling_integral().y(), 100 * 0.001 * 0.02, 1e-12);
  p.coupling.remove_tangential_integral = false;
  ServoController paper(p);
  for (int k = 0; k < 100; ++k) {
    paper.update(Vec3::Zero(), Vec3::Zero(), ce_of(Vec3(0.01, 0.02, 0), t), Vec3::Zero(), u);
  }
  EXPECT_NEAR(paper.coupling_integral().x(), 100 * 0.001 * 0.01, 1e-12);
  // u = Cp eps + Ci I (steady eps: no derivative)
  EXPECT_NEAR(u.y(), 15 * 0.02 + 300 * 100 * 0.001 * 0.02, 1e-10);
}

TEST(ServoController, CommandLimitAndAntiWindup) {
  ServoParams p = base(AxisLaw::kPid, false);
  p.axis[0] = {0.6, 50.0, 0.0, 0.0, 0.1};
  ServoController c(p);
  Vec3 u;
  for (int k = 0; k < 1000; ++k) {
    const auto st = c.update(Vec3(10, 0, 0), Vec3::Zero(), ce_of(Vec3::Zero()), Vec3::Zero(), u);
    EXPECT_EQ(st, ServoStatus::kSaturated);
    EXPECT_LE(std::abs(u.x()), 0.1);
  }
  // Error reverses: without wind-up the command leaves the limit at once.
  c.update(Vec3(-0.1, 0, 0), Vec3::Zero(), ce_of(Vec3::Zero()), Vec3::Zero(), u);
  EXPECT_LT(u.x(), 0.0);
}

TEST(ServoController, SmithPredictorPredictsTheDelayedPlantExactly) {
  ServoParams p = base(AxisLaw::kP, false);
  p.delay_cycles = 1;
  ServoController c(p);
  FeedDriveParams dp;
  dp.delay_cycles = 1;
  FeedDrive plant(dp);
  FeedDrive shadow(dp);  // one step ahead copy to read x(k+1)
  Vec3 u;
  for (int k = 0; k < 300; ++k) {
    const double r = 0.05 * k * 0.001 * 1000.0 / 60.0;
    const Vec3 pm(plant.position_mm(), 0, 0);
    const Vec3 ph = c.predict(pm);
    c.update(Vec3(r, 0, 0), ph, ce_of(Vec3::Zero()), Vec3::Zero(), u);
    plant.step(u.x());
    // The command computed now first acts one cycle later; ph is the position it meets: x(k+1),
    // which the plant already knows after this step (it was fixed by earlier commands).
    EXPECT_NEAR(ph.x(), plant.position_mm(), 1e-12) << k;
  }
}

TEST(LoopMargin, PaperGainsMarginAndDelay) {
  FeedDriveParams x;
  AxisGains ax;
  CouplingGains cg;
  const LoopMargin m0 = loop_margin(x, ax, cg, 0, false);
  EXPECT_LT(m0.spectral_radius, 1.0);
  EXPECT_NEAR(m0.gain_margin, 1.6, 0.05);  // interpretation.md: gain x1.6 makes it unstable
  const LoopMargin m1 = loop_margin(x, ax, cg, 1, false);
  EXPECT_GT(m1.spectral_radius, 1.0);      // one cycle of delay: unstable
  EXPECT_LT(m1.gain_margin, 1.0);
  const LoopMargin m1s = loop_margin(x, ax, cg, 1, true);
  EXPECT_NEAR(m1s.spectral_radius, m0.spectral_radius, 1e-6);  // exact model: as if no delay
  // Mismatch: a 10 % faster plant than the model still stable with the predictor.
  EXPECT_LT(loop_margin(x, ax, cg, 1, true, 1.1).spectral_radius, 1.0);
}

TEST(ServoController, RejectsBadParams) {
  ServoParams p;
  p.axes = 4;
  EXPECT_THROW(ServoController{p}, std::invalid_argument);
  p = ServoParams{};
  p.axis[0].kp = -1;
  EXPECT_THROW(ServoController{p}, std::invalid_argument);
}
