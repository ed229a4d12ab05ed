// Runtime of the 2-DOF force channel: no allocation, anti-windup, ceiling, stale fallback, bumpless.
#include "control/force_controller.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/support/alloc_counter.hpp"

using namespace contour::control;

namespace {
const ForceDesign& design() {
  static const ForceDesign d = design_force_2dof(ForceDesignParams{});
  return d;
}
ForceInput in_at(double t, double force, double progress) {
  ForceInput in;
  in.force_ref_N = 1.0;
  in.planned_progress_mm = 4.5 * t;
  in.force_N = force;
  in.progress_mm = progress;
  return in;
}
}  // namespace

TEST(ForceController, StepDoesNotAllocateOver10kCycles) {
  ForceController c;
  c.configure(design(), ForceLimits{});
  ForcePlantSim p;
  p.configure(ForcePlantParams{}, 0.001);
  c.enable(ForceEnableState{1.0, 3000.0, 0.0, 0.0});
  double sink = 0.0;
  {
    contour::test::AllocGuard g;
    for (int k = 0; k < 10000; ++k) {
      ForceInput in = in_at(k * 1e-3, p.force_N(k > 5000 ? 0.3 : 0.0), p.progress_mm());
      in.force_valid = (k % 997) != 0;  // exercise the fallback path too
      const ForceOutput o = c.step(in);
      if (!c.active()) c.enable(ForceEnableState{o.feed_override, o.spindle_rpm, in.force_N, in.progress_mm});
      p.step(o.feed_override, (o.spindle_rpm - 3000.0) / 1000.0);
      sink += o.feed_override;
    }
    EXPECT_EQ(g.counts().total(), 0u);
  }
  EXPECT_TRUE(std::isfinite(sink));
}

TEST(ForceController, SaturationWithForcePulseRecoversWithoutWindup) {
  ForceScenario sc;
  sc.kind = ForceScenarioKind::kImpulse;
  sc.disturbance_N = 2.0;   // 20 ms pulse of twice the reference: far beyond what the limits give
  sc.pulse_s = 0.02;
  sc.limits = ForceLimits{};  // shipped: 0..150 %, 10 /s; spindle 500..6000 rpm, 6000 rpm/s
  ForceTrace tr;
  const ForceMetrics m = run_force_scenario(design(), sc, &tr);
  bool saturated = false;
  const double drpm = sc.limits.spindle_rate_rpm_s * 1e-3, dov = sc.limits.override_rate_per_s * 1e-3;
  for (std::size_t i = 1; i < tr.t_s.size(); ++i) {
    const bool at_rate = std::abs(tr.spindle_rpm[i] - tr.spindle_rpm[i - 1]) >= drpm - 1e-9 ||
                         std::abs(tr.feed_override[i] - tr.feed_override[i - 1]) >= dov - 1e-12;
    if (tr.t_s[i] > 5.0 && at_rate) saturated = true;
  }
  EXPECT_TRUE(saturated) << "the pulse must drive an output into its rate limit";
  EXPECT_LE(m.disturbance_recovery_s, 0.5);
  sc.limits.anti_windup = false;
  const ForceMetrics bad = run_force_scenario(design(), sc);
  EXPECT_GT(bad.disturbance_recovery_s, 0.5);
}

TEST(ForceController, OutputsRespectRangesAndRates) {
  ForceScenario sc;
  sc.kind = ForceScenarioKind::kImpulse;
  sc.disturbance_N = 2.0;
  ForceTrace tr;
  run_force_scenario(design(), sc, &tr);
  const ForceLimits l{};
  for (std::size_t i = 1; i < tr.t_s.size(); ++i) {
    ASSERT_GE(tr.feed_override[i], l.override_min - 1e-12);
    ASSERT_LE(tr.feed_override[i], l.override_max + 1e-12);
    ASSERT_LE(std::abs(tr.feed_override[i] - tr.feed_override[i - 1]), l.override_rate_per_s * 1e-3 + 1e-12);
    ASSERT_GE(tr.spindle_rpm[i], l.spindle_min_rpm - 1e-9);
    ASSERT_LE(tr.spindle_rpm[i], l.spindle_max_rpm + 1e-9);
    ASSERT_LE(std::abs(tr.spindle_rpm[i] - tr.spindle_rpm[i - 1]), l.spindle_rate_rpm_s * 1e-3 + 1e-9);
  }
}

TEST(ForceController, CeilingRequestsFeedHoldAndLatches) {
  ForceController c;
  ForceLimits l;
  l.force_ceiling_N = 2.0;
  c.configure(design(), l);
  c.enable(ForceEnableState{1.0, 3000.0, 1.0, 0.0});
  EXPECT_EQ(c.step(in_at(0.0, 1.0, 0.0)).status, ForceStatus::kActive);
  ForceOutput o = c.step(in_at(0.001, 2.5, 0.0045));
  EXPECT_EQ(o.status, ForceStatus::kCeilingHold);
  EXPECT_TRUE(o.feed_hold_request);
  EXPECT_EQ(o.feed_override, 0.0);
  o = c.step(in_at(0.002, 1.0, 0.0045));  // latched although the force is back
  EXPECT_EQ(o.status, ForceStatus::kCeilingHold);
  c.enable(ForceEnableState{0.0, o.spindle_rpm, 1.0, 0.0045});
  EXPECT_NE(c.step(in_at(0.003, 1.0, 0.0045)).status, ForceStatus::kCeilingHold);
  // Ceiling also applies while force control is off.
  c.disable();
  EXPECT_EQ(c.step(in_at(0.004, 2.1, 0.0045)).status, ForceStatus::kCeilingHold);
}

TEST(ForceController, StaleSampleFallbacks) {
  for (auto fb : {ForceFallback::kHold, ForceFallback::kProgrammedFeed}) {
    ForceController c;
    ForceLimits l;
    l.fallback = fb;
    c.configure(design(), l);
    c.enable(ForceEnableState{0.8, 3300.0, 1.0, 0.0});
    ForceInput in = in_at(0.0, 1.0, 0.0);
    in.force_age_s = 0.05;  // older than stale_age_s = 20 ms
    ForceOutput o = c.step(in);
    if (fb == ForceFallback::kHold) {
      EXPECT_EQ(o.status, ForceStatus::kStaleHold);
      EXPECT_EQ(o.feed_override, 0.0);
      EXPECT_TRUE(o.feed_hold_request);
      EXPECT_DOUBLE_EQ(o.spindle_rpm, 3300.0);
    } else {
      EXPECT_EQ(o.status, ForceStatus::kStaleProgrammed);
      EXPECT_FALSE(o.feed_hold_request);
      for (int k = 0; k < 2000; ++k) o = c.step(in);
      EXPECT_DOUBLE_EQ(o.feed_override, 1.0);
      EXPECT_DOUBLE_EQ(o.spindle_rpm, l.spindle_nominal_rpm);
    }
    in.force_N = std::nan("");
    in.force_age_s = 0.0;
    c.enable(ForceEnableState{1.0, 3000.0, 1.0, 0.0});
    EXPECT_NE(c.step(in).status, ForceStatus::kActive);
  }
}

TEST(ForceController, BumplessEnableAndDisable) {
  ForceController c;
  const ForceLimits l{};
  c.configure(design(), l);
  ForcePlantSim p;
  p.configure(ForcePlantParams{}, 0.001);
  p.reset(0.9, 0.2, 10.0);  // steady cut at 90 %, 3200 rpm
  c.enable(ForceEnableState{0.9, 3200.0, p.force_N(), p.progress_mm()});
  double prev_o = 0.9, prev_n = 3200.0, max_jump_o = 0.0, max_jump_n = 0.0;
  for (int k = 0; k < 500; ++k) {
    ForceInput in;
    in.force_ref_N = p.force_N();
    in.planned_progress_mm = 10.0 + 4.5 * 0.9 * k * 1e-3;
    in.force_N = p.force_N();
    in.progress_mm = p.progress_mm();
    const ForceOutput o = c.step(in);
    max_jump_o = std::max(max_jump_o, std::abs(o.feed_override - prev_o));
    max_jump_n = std::max(max_jump_n, std::abs(o.spindle_rpm - prev_n));
    prev_o = o.feed_override;
    prev_n = o.spindle_rpm;
    p.step(o.feed_override, (o.spindle_rpm - 3000.0) / 1000.0);
  }
  // First cycles: no jump beyond a few per mille of override / a few rpm per ms.
  EXPECT_LT(max_jump_o, 0.005);
  EXPECT_LT(max_jump_n, 5.0);
  c.disable();
  ForceOutput o = c.step(ForceInput{});
  EXPECT_LE(std::abs(o.feed_override - prev_o), l.override_rate_per_s * 1e-3 + 1e-12);
  EXPECT_EQ(o.status, ForceStatus::kDisabled);
}

TEST(ForceController, UnconfiguredIsSafe) {
  ForceController c;
  const ForceOutput o = c.step(ForceInput{});
  EXPECT_EQ(o.status, ForceStatus::kNotConfigured);
  EXPECT_EQ(o.feed_override, 1.0);
}

TEST(ForceController, RejectsBadLimits) {
  ForceController c;
  ForceLimits l;
  l.override_max = -1.0;
  EXPECT_THROW(c.configure(design(), l), std::invalid_argument);
}
