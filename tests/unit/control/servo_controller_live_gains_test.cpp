// ServoController::set_gains: a live swap keeps the controller state (integrators, previous
// errors, Smith predictor history) and keeps the integral contribution continuous (bumpless),
// where configure() restarts from zero; structural changes are refused by check_live_compatible.
#include <gtest/gtest.h>

#include <cmath>

#include "control/servo_controller.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::control {
namespace {

ServoParams pid_params() {
  ServoParams p;
  p.axes = 2;
  p.law = AxisLaw::kPid;
  for (auto& a : p.axis) {
    a.kp = 0.6;
    a.ki_per_s = 5.0;
    a.kd_s = 0.001;
  }
  p.coupling = CouplingGains{true, 15.0, 300.0, 0.3, false};
  for (auto& d : p.drive) {
    d.gain_per_s = 120.0;
    d.tau_s = 0.03;
    d.period_s = 0.001;
  }
  p.period_s = 0.001;
  p.delay_cycles = 1;
  p.delay_compensation = true;
  return p;
}

// A slowly varying error pattern; the "plant" is left out on purpose: the same inputs go to every
// controller, so the difference of their outputs is the effect of the swap alone.
struct Inputs {
  Vec3 r, p;
  ContourErrorResult ce;
};
Inputs inputs_at(int k) {
  const double t = k * 0.001;
  Inputs in;
  in.r = Vec3(10.0 * t, 5.0 * t, 0.0);
  in.p = in.r - Vec3(0.02 + 0.01 * std::sin(3.0 * t), 0.015 * std::cos(2.0 * t), 0.0);
  in.ce.eps = Vec3(0.004 * std::sin(5.0 * t), -0.003 * std::cos(4.0 * t), 0.0);
  in.ce.status = ContourStatus::kOk;
  return in;
}

TEST(ServoControllerLiveGains, SwapKeepsStateAndTheIntegralContributionIsContinuous) {
  const ServoParams p0 = pid_params();
  ServoParams p1 = p0;
  for (auto& a : p1.axis) a.ki_per_s = 10.0;  // doubled
  p1.coupling.ci_per_s = 150.0;               // halved
  ServoController keep(p0), swapped(p0), restarted(p0);
  const int k_swap = 2000;
  Vec3 u_keep, u_swap, u_restart, u_prev_swap = Vec3::Zero();
  double jump_swap = 0.0, jump_restart = 0.0, max_step_before = 0.0;
  for (int k = 0; k <= k_swap; ++k) {
    if (k == k_swap) {
      swapped.check_live_compatible(p1);
      swapped.set_gains(p1);
      restarted.configure(p1);  // the old way: state reset
    }
    const Inputs in = inputs_at(k);
    keep.update(in.r, keep.predict(in.p), in.ce, Vec3::Zero(), u_keep);
    swapped.update(in.r, swapped.predict(in.p), in.ce, Vec3::Zero(), u_swap);
    restarted.update(in.r, restarted.predict(in.p), in.ce, Vec3::Zero(), u_restart);
    if (k > 0 && k < k_swap)
      max_step_before = std::max(max_step_before, (u_swap - u_prev_swap).norm());
    if (k == k_swap) {
      jump_swap = (u_swap - u_keep).norm();
      jump_restart = (u_restart - u_keep).norm();
    }
    u_prev_swap = u_swap;
  }
  // Bumpless: at the swap the output differs from the unswapped controller only by this cycle's
  // integrator increments weighted with the gain change (dKi T |e| + dCi T |eps| ~ 1e-4 mm).
  const Inputs in = inputs_at(k_swap);
  const double bound = 5.0 * 0.001 * (in.r - in.p).norm() + 150.0 * 0.001 * in.ce.eps.norm() + 1e-9;
  EXPECT_LT(jump_swap, bound) << "restart would jump " << jump_restart;
  EXPECT_LT(jump_swap, max_step_before + 1e-9);
  // The restart loses the integral contribution and the predictor history: a visible jump.
  EXPECT_GT(jump_restart, 10.0 * jump_swap);
  EXPECT_DOUBLE_EQ(swapped.params().axis[0].ki_per_s, 10.0);
  EXPECT_DOUBLE_EQ(swapped.params().coupling.ci_per_s, 150.0);
  // Ci * I kept: the coupling integral was rescaled by 300/150.
  EXPECT_NEAR(swapped.coupling_integral()[0] * 150.0, keep.coupling_integral()[0] * 300.0,
              1e-9 + 300.0 * 0.001 * std::abs(in.ce.eps[0]) * 2.0);
}

TEST(ServoControllerLiveGains, DroppedIntegralIsClearedAndANewOneStartsAtZero) {
  ServoParams p0 = pid_params();
  ServoController c(p0);
  for (int k = 0; k < 500; ++k) {
    const Inputs in = inputs_at(k);
    Vec3 u;
    c.update(in.r, c.predict(in.p), in.ce, Vec3::Zero(), u);
  }
  ASSERT_GT(c.coupling_integral().norm(), 0.0);
  ServoParams p1 = p0;
  p1.coupling.enable = false;
  c.set_gains(p1);
  EXPECT_EQ(c.coupling_integral().norm(), 0.0);
  // Re-enabled: starts from zero (it did not contribute before).
  c.set_gains(p0);
  EXPECT_EQ(c.coupling_integral().norm(), 0.0);
}

TEST(ServoControllerLiveGains, StructuralChangesAreRefused) {
  const ServoParams p0 = pid_params();
  const ServoController c(p0);
  ServoParams p = p0;
  p.drive[0].gain_per_s = 100.0;
  EXPECT_THROW(c.check_live_compatible(p), std::invalid_argument);
  p = p0;
  p.axes = 3;
  EXPECT_THROW(c.check_live_compatible(p), std::invalid_argument);
  p = p0;
  p.delay_cycles = 0;
  EXPECT_THROW(c.check_live_compatible(p), std::invalid_argument);
  p = p0;
  p.axis[1].kp = -1.0;
  EXPECT_THROW(c.check_live_compatible(p), std::invalid_argument);
  p = p0;
  p.axis[1].kp = 2.0;
  p.coupling.cp = 3.0;
  EXPECT_NO_THROW(c.check_live_compatible(p));
}

TEST(ServoControllerLiveGains, SetGainsDoesNotAllocate) {
  const ServoParams p0 = pid_params();
  ServoParams p1 = p0;
  p1.axis[0].kp = 0.7;
  ServoController c(p0);
  std::size_t n = 0;
  {
    test::AllocGuard g;
    for (int i = 0; i < 1000; ++i) c.set_gains(i % 2 == 0 ? p1 : p0);
    n = g.counts().total();
  }
  EXPECT_EQ(n, 0u);
}

}  // namespace
}  // namespace contour::control
