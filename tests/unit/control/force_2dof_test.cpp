// Issue 5 bars on the design (physical plant, 1 kHz), each checked against a detuned design too.
#include "control/force_2dof.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "control/force_controller.hpp"

using namespace contour::control;

namespace {
ForceLimits wide_limits() {
  ForceLimits l;
  l.override_min = 0.0;
  l.override_max = 100.0;
  l.override_rate_per_s = 1e9;
  l.spindle_nominal_rpm = 1e6;
  l.spindle_rpm_per_unit = 1.0;
  l.spindle_min_rpm = 0.0;
  l.spindle_max_rpm = 2e6;
  l.spindle_rate_rpm_s = 1e12;
  l.force_ceiling_N = 1e9;
  return l;
}
// The shipped actuator limits (ForceLimits{} == config/force_physical.yaml): override 0-150 % at
// 1000 %/s, spindle 500-6000 rpm at 6000 rpm/s. The bars are asserted with these.
ForceScenario step_scenario(const ForcePlantParams& p) {
  ForceScenario sc;
  sc.kind = ForceScenarioKind::kStep;
  sc.true_plant = p;
  sc.limits = ForceLimits{};
  sc.feed_mm_s = p.k_v_mm_s;
  return sc;
}
const double kRefModelSettling = 5.8335;  // 2 % settling of 1/(tau s+1)^2, in units of tau

ForceDesignParams detuned() {  // weak feedback, slow observer
  ForceDesignParams p;
  p.weights.r_feed = p.weights.r_spindle = 10.0;
  p.weights.observer_input_noise = 1.0;
  p.weights.observer_measurement_noise = 1e-2;
  return p;
}
}  // namespace

TEST(Force2Dof, FeedForwardIsExactModelMatching) {
  const ForceDesign d = design_force_2dof(ForceDesignParams{});
  Eigen::Matrix<double, 5, 1> w = Eigen::Matrix<double, 5, 1>::Zero();
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  double worst = 0.0;
  for (int k = 0; k < 3000; ++k) {
    const Eigen::Vector2d r(1.0 + (k > 1500 ? 0.5 : 0.0), 4.5 * k * 1e-3);
    const Eigen::Vector2d u = d.ff_cu * w + d.ff_du * r;
    worst = std::max(worst, (d.ff_cy * w - d.plant_c * x).cwiseAbs().maxCoeff());
    x = d.plant_a * x + d.plant_b * u;
    w = d.ff_a * w + d.ff_b * r;
  }
  EXPECT_LT(worst, 1e-9);
  EXPECT_LT(lti::max_pole_radius(d.ff_a), 1.0);
}

TEST(Force2Dof, FeedForwardStableForPrintedPlant) {
  ForceDesignParams p;
  p.plant.spindle_pole = SpindlePole::kPrinted;
  const ForceDesign d = design_force_2dof(p);
  EXPECT_LT(lti::max_pole_radius(d.ff_a), 1.0);
  // The printed plant itself is unstable: its pole is exp(T/0.8) > 1.
  EXPECT_GT(lti::max_pole_radius(d.plant_a), 1.0);
}

TEST(Force2Dof, BezoutIdentitiesHold) {
  for (auto pole : {SpindlePole::kPhysical, SpindlePole::kPrinted}) {
    ForceDesignParams p;
    p.plant.spindle_pole = pole;
    const ForceDesign d = design_force_2dof(p);
    const CoprimeFactors cf = force_coprime_factors(d);
    EXPECT_LT(lti::max_pole_radius(cf.left.a), 1.0);
    EXPECT_LT(lti::max_pole_radius(cf.right.a), 1.0);
    for (double w : lti::frequency_grid(d.period_s, 60)) {
      const lti::CMat l = lti::freq_response(cf.left, w), r = lti::freq_response(cf.right, w);
      const lti::CMat prod = l * r;
      ASSERT_LT((prod - lti::CMat::Identity(4, 4)).cwiseAbs().maxCoeff(), 1e-6) << "w=" << w;
      // P_a = N M^-1 and C2_a = U V^-1.
      const lti::CMat m = r.topLeftCorner(2, 2), u = r.topRightCorner(2, 2);
      const lti::CMat n = r.bottomLeftCorner(2, 2), v = r.bottomRightCorner(2, 2);
      const lti::CMat pa = lti::freq_response(cf.plant_aug, w);
      const lti::CMat ka = lti::freq_response(cf.ctrl_aug, w);
      EXPECT_LT((n * m.inverse() - pa).cwiseAbs().maxCoeff(), 1e-6 * (1.0 + pa.cwiseAbs().maxCoeff()));
      EXPECT_LT((u * v.inverse() - ka).cwiseAbs().maxCoeff(), 1e-6 * (1.0 + ka.cwiseAbs().maxCoeff()));
    }
    EXPECT_LT(d.quality.bezout_residual, 1e-6);
  }
}

TEST(Force2Dof, StepHasNoOvershootAndSettlesWithTheReferenceModel) {
  ForceDesignParams p;
  const ForceDesign d = design_force_2dof(p);
  const ForceMetrics m = run_force_scenario(d, step_scenario(p.plant));
  const double ts_model = kRefModelSettling * p.tau_m_s;
  EXPECT_TRUE(m.stable);
  EXPECT_LE(m.force_overshoot_pct, 0.0);
  EXPECT_NEAR(m.force_settling_s, ts_model, 0.05 * ts_model);
  EXPECT_LT(m.steady_force_error, 1e-6);
  // Detuned: a design for a plant with 30 % less spindle gain, run on the true one.
  ForceDesignParams wrong = detuned();
  wrong.plant.k_s_N *= 0.7;
  const ForceMetrics bad = run_force_scenario(design_force_2dof(wrong), step_scenario(p.plant));
  EXPECT_TRUE(bad.force_overshoot_pct > 0.0 ||
              std::abs(bad.force_settling_s - ts_model) > 0.05 * ts_model);
}

TEST(Force2Dof, RampLagType2VersusPaperModel) {
  // Paper's feed: 0.01 m/s (Fig 2.6) = 10 mm/s, programmed at 100 % override (K_v = 10 mm/s):
  // with the shipped 150 % override ceiling a 4.5 mm/s plant could not follow 10 mm/s at all.
  for (auto pm : {PositionModel::kType2, PositionModel::kPaper}) {
    ForceDesignParams p;
    p.plant.k_v_mm_s = 10.0;
    p.position_model = pm;
    const ForceDesign d = design_force_2dof(p);
    ForceScenario sc = step_scenario(p.plant);
    sc.feed_mm_s = 10.0;
    const ForceMetrics m = run_force_scenario(d, sc);
    if (pm == PositionModel::kType2) {
      EXPECT_LE(std::abs(m.position_ramp_lag_mm), 0.01);
    } else {
      EXPECT_NEAR(m.position_ramp_lag_mm, 2.0 * p.tau_m_s * 10.0, 0.02);  // 2 tau_m v, fails the bar
      EXPECT_GT(m.position_ramp_lag_mm, 0.01);
    }
  }
}

TEST(Force2Dof, SteadyStateErrorStepForceRampPosition) {
  ForceDesignParams p;
  const ForceDesign d = design_force_2dof(p);
  ForceScenario sc = step_scenario(p.plant);
  sc.kind = ForceScenarioKind::kStep;
  sc.disturbance_N = 0.0;
  sc.duration_s = 5.0;
  sc.disturbance_at_s = 5.0;
  const ForceMetrics m = run_force_scenario(d, sc);
  EXPECT_LT(m.steady_force_error, 1e-6);
  // Position: the ramp error is the half-sample ZOH offset v T / 2, constant: its change over the
  // last second (the steady-state drift) must be < 1e-6.
  ForceTrace tr;
  run_force_scenario(d, sc, &tr);
  const std::size_t n = tr.t_s.size();
  const double e_end = tr.plan_mm[n - 1] - tr.progress_mm[n - 1];
  const double e_1s = tr.plan_mm[n - 1001] - tr.progress_mm[n - 1001];
  EXPECT_LT(std::abs(e_end - e_1s), 1e-6);
}

TEST(Force2Dof, AllCornersStableWithSmallOvershoot) {
  for (bool tuned : {true, false}) {
    ForceDesignParams p = tuned ? ForceDesignParams{} : detuned();
    const ForceDesign d = design_force_2dof(p);
    double worst_os = 0.0;
    bool all_stable = true;
    for (int c = 0; c < 32; ++c) {
      ForcePlantParams q = p.plant;
      auto f = [&](int bit) { return (c >> bit & 1) ? 1.3 : 0.7; };
      q.k_f_N *= f(0);
      q.tau_f_s *= f(1);
      q.k_s_N *= f(2);
      q.tau_s_s *= f(3);
      q.k_v_mm_s *= f(4);
      ForceScenario sc = step_scenario(q);
      sc.duration_s = 5.0;
      sc.feed_mm_s = p.plant.k_v_mm_s;
      const ForceMetrics m = run_force_scenario(d, sc);
      all_stable = all_stable && m.stable;
      worst_os = std::max(worst_os, m.force_overshoot_pct);
    }
    if (tuned) {
      EXPECT_TRUE(all_stable);
      EXPECT_LE(worst_os, 10.0);
    } else {
      EXPECT_TRUE(!all_stable || worst_os > 10.0) << "detuned worst overshoot " << worst_os;
    }
  }
}

TEST(Force2Dof, MarginsAtEachInput) {
  const ForceDesign d = design_force_2dof(ForceDesignParams{});
  EXPECT_GE(d.quality.input_phase_margin_deg[0], 60.0);
  EXPECT_GE(d.quality.input_phase_margin_deg[1], 60.0);
  EXPECT_GE(d.quality.delay_margin_s, 0.020);
  // Detuned (observer trusted far too much: small measurement noise, big input noise, with the
  // old cheap-control weights r = 1e-5): the delay margin falls to ~5.5 ms, below the bar.
  ForceDesignParams p;
  p.weights.observer_measurement_noise = 1e-9;
  p.weights.observer_input_noise = 1e6;
  p.weights.r_feed = p.weights.r_spindle = 1e-5;
  const ForceDesign bad = design_force_2dof(p);
  EXPECT_TRUE(bad.quality.delay_margin_s < 0.020 ||
              std::min(bad.quality.input_phase_margin_deg[0], bad.quality.input_phase_margin_deg[1]) < 60.0);
}

TEST(Force2Dof, OutputDisturbanceRecovery) {
  ForceDesignParams p;
  ForceScenario sc = step_scenario(p.plant);  // shipped (realistic) limits
  sc.disturbance_N = 0.5;
  const ForceMetrics m = run_force_scenario(design_force_2dof(p), sc);
  EXPECT_LE(m.disturbance_recovery_s, 0.3);
  // No controller beats the time-optimal bound; the bound itself is below the bar.
  EXPECT_GT(m.disturbance_recovery_bound_s, 0.1);
  EXPECT_GE(m.disturbance_recovery_s, m.disturbance_recovery_bound_s);
  EXPECT_LE(m.disturbance_recovery_bound_s, 0.3);
  const ForceMetrics bad = run_force_scenario(design_force_2dof(detuned()), sc);
  EXPECT_GT(bad.disturbance_recovery_s, 0.3);
  // The previous tuning (integrator zero at 5 rad/s, r = 1e-5) misses the bar with these limits.
  ForceDesignParams old = p;
  old.weights.q_force_integral = 25.0;
  old.weights.r_feed = old.weights.r_spindle = 1e-5;
  EXPECT_GT(run_force_scenario(design_force_2dof(old), sc).disturbance_recovery_s, 0.3);
}

TEST(Force2Dof, SlowSpindleDriveMakesTheDisturbanceBarUnreachable) {
  // At 3000 rpm/s (0 -> 6000 rpm in 2 s) even the time-optimal input needs >= 0.29 s just to
  // reach the 2 % band (and more to stay in it): the bound is what the limits allow.
  ForceDesignParams p;
  ForceScenario sc = step_scenario(p.plant);
  sc.disturbance_N = 0.5;
  sc.limits.spindle_rate_rpm_s = 3000.0;
  const ForceMetrics slow = run_force_scenario(design_force_2dof(p), sc);
  EXPECT_GT(slow.disturbance_recovery_bound_s, 0.29);
  EXPECT_GE(slow.disturbance_recovery_s, slow.disturbance_recovery_bound_s);
  EXPECT_GT(slow.disturbance_recovery_s, 0.3);
  // Unlimited actuators: the bound collapses to the first sample.
  sc.limits = wide_limits();
  EXPECT_LT(run_force_scenario(design_force_2dof(p), sc).disturbance_recovery_bound_s, 0.01);
}

TEST(Force2Dof, PrintedPlantDesignedForItIsStable) {
  ForceDesignParams p;
  p.plant.spindle_pole = SpindlePole::kPrinted;
  const ForceDesign d = design_force_2dof(p);
  EXPECT_LT(d.quality.max_pole_radius, 1.0);
  for (auto k : {ForceScenarioKind::kStep, ForceScenarioKind::kTrack, ForceScenarioKind::kImpulse}) {
    ForceScenario sc = step_scenario(p.plant);
    sc.kind = k;
    const ForceMetrics m = run_force_scenario(d, sc);
    EXPECT_TRUE(m.stable);
    EXPECT_LT(m.steady_force_error, 1e-3);
  }
  // The physical-plant design does not stabilise the printed plant (parity interlacing), and
  // vice versa.
  const ForceDesign phys = design_force_2dof(ForceDesignParams{});
  const auto printed_d = lti::c2d_zoh(force_plant_model(p.plant), 0.001);
  const auto phys_d = lti::c2d_zoh(force_plant_model(ForcePlantParams{}), 0.001);
  EXPECT_GE(lti::max_pole_radius(lti::closed_loop_a(printed_d, force_feedback_controller(phys))), 1.0);
  EXPECT_GE(lti::max_pole_radius(lti::closed_loop_a(phys_d, force_feedback_controller(d))), 1.0);
}

TEST(Force2Dof, BadParametersAreRejected) {
  ForceDesignParams p;
  p.tau_m_s = 0.7;  // not faster than tau_f = 0.6 (eq 3.6)
  EXPECT_THROW(design_force_2dof(p), std::invalid_argument);
  p = ForceDesignParams{};
  p.plant.k_s_N = 0.0;
  EXPECT_THROW(design_force_2dof(p), std::invalid_argument);
}
