#include "config/force_config.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "config/config.hpp"
#include "control/force_controller.hpp"

using namespace contour::config;

namespace {
const char* kMachine = "machine:\n  axes:\n    - {name: X}\n";
std::vector<std::string> errors_of(const std::string& yaml) {
  try {
    load_config_string(std::string(kMachine) + yaml, "f.yaml");
  } catch (const ConfigError& e) {
    return e.errors();
  }
  return {};
}
bool any(const std::vector<std::string>& v, const std::string& s) {
  for (const auto& e : v) {
    if (e.find(s) != std::string::npos) return true;
  }
  return false;
}
}  // namespace

TEST(ForceConfig, DefaultsArePhysicalPaperPlant) {
  const Config c = load_config_string(kMachine);
  EXPECT_FALSE(c.force.enable);
  EXPECT_EQ(c.force.design.plant.spindle_pole, contour::control::SpindlePole::kPhysical);
  EXPECT_DOUBLE_EQ(c.force.design.plant.tau_f_s, 0.6);
  EXPECT_EQ(c.force.design.position_model, contour::control::PositionModel::kType2);
}

TEST(ForceConfig, ExampleFilesLoadAndDesign) {
  for (const char* f : {"config/force_physical.yaml", "config/force_printed.yaml"}) {
    const Config c = load_config_file(std::string(CONTOUR_SOURCE_DIR) + "/" + f);
    EXPECT_TRUE(c.force.enable);
    auto p = c.force.design;
    p.period_s = c.machine.period_s;
    const auto d = contour::control::design_force_2dof(p);
    EXPECT_LT(d.quality.max_pole_radius, 1.0) << f;
  }
  const Config pr = load_config_file(std::string(CONTOUR_SOURCE_DIR) + "/config/force_printed.yaml");
  EXPECT_EQ(pr.force.design.plant.spindle_pole, contour::control::SpindlePole::kPrinted);
}

TEST(ForceConfig, ParsesUnitsAndChoices) {
  const Config c = load_config_string(std::string(kMachine) +
                                      "force:\n  plant: {tau_f_ms: 500, spindle_pole: printed}\n"
                                      "  reference_model: {tau_m_ms: 150, position: paper}\n"
                                      "  limits: {override_max_pct: 120, force_ceiling_N: 800}\n"
                                      "  fallback: programmed_feed\n  stale_ms: 50\n");
  EXPECT_DOUBLE_EQ(c.force.design.plant.tau_f_s, 0.5);
  EXPECT_DOUBLE_EQ(c.force.design.tau_m_s, 0.15);
  EXPECT_EQ(c.force.design.position_model, contour::control::PositionModel::kPaper);
  EXPECT_DOUBLE_EQ(c.force.limits.override_max, 1.2);
  EXPECT_DOUBLE_EQ(c.force.limits.force_ceiling_N, 800.0);
  EXPECT_EQ(c.force.limits.fallback, contour::control::ForceFallback::kProgrammedFeed);
  EXPECT_DOUBLE_EQ(c.force.limits.stale_age_s, 0.05);
}

TEST(ForceConfig, ErrorsNameLineAndKey) {
  auto e = errors_of("force:\n  plant:\n    tau_f_ms: -3\n");
  EXPECT_TRUE(any(e, "f.yaml:6:15: force.plant.tau_f_ms")) << (e.empty() ? "" : e[0]);
  e = errors_of("force:\n  fallback: maybe\n");
  EXPECT_TRUE(any(e, "force.fallback")) << (e.empty() ? "" : e[0]);
  e = errors_of("force:\n  reference_model: {tau_m_ms: 900}\n");
  EXPECT_TRUE(any(e, "force.reference_model.tau_m_ms")) << (e.empty() ? "" : e[0]);
  e = errors_of("force:\n  bogus: 1\n");
  EXPECT_TRUE(any(e, "force.bogus: unknown key")) << (e.empty() ? "" : e[0]);
  e = errors_of("force:\n  spindle: {min_rpm: 5000, max_rpm: 4000}\n");
  EXPECT_TRUE(any(e, "force.spindle.max_rpm")) << (e.empty() ? "" : e[0]);
}

// Issue 5 bars with the SHIPPED example file (its limits and weights), physical plant, 1 kHz.
TEST(ForceConfig, ShippedPhysicalConfigMeetsTheBars) {
  using namespace contour::control;
  const Config c = load_config_file(std::string(CONTOUR_SOURCE_DIR) + "/config/force_physical.yaml");
  auto p = c.force.design;
  p.period_s = c.machine.period_s;
  ASSERT_DOUBLE_EQ(p.period_s, 0.001);
  const ForceDesign d = design_force_2dof(p);
  EXPECT_GE(d.quality.input_phase_margin_deg[0], 60.0);
  EXPECT_GE(d.quality.input_phase_margin_deg[1], 60.0);
  EXPECT_GE(d.quality.delay_margin_s, 0.020);
  // Sensible limits: the interpolator's override range, a real spindle range and rate.
  EXPECT_LE(c.force.limits.override_max, 1.5);
  EXPECT_LE(c.force.limits.override_rate_per_s, 10.0);
  EXPECT_LE(c.force.limits.spindle_rate_rpm_s, 6000.0);
  EXPECT_LE(c.force.limits.spindle_max_rpm, 12000.0);
  ForceScenario sc;
  sc.kind = ForceScenarioKind::kStep;
  sc.true_plant = p.plant;
  sc.limits = c.force.limits;
  sc.force_ref_N = c.force.reference_N;
  sc.feed_mm_s = p.plant.k_v_mm_s;
  sc.disturbance_N = 0.5 * c.force.reference_N;  // as contour-sim force --scenario step
  const ForceMetrics m = run_force_scenario(d, sc);
  const double ts_model = 5.8335 * p.tau_m_s;
  EXPECT_TRUE(m.stable);
  EXPECT_LE(m.force_overshoot_pct, 0.0);
  EXPECT_NEAR(m.force_settling_s, ts_model, 0.05 * ts_model);
  EXPECT_LT(m.steady_force_error, 1e-6);
  EXPECT_LE(m.disturbance_recovery_s, 0.3);
  EXPECT_LE(std::abs(m.position_ramp_lag_mm), 0.01);
  sc.kind = ForceScenarioKind::kImpulse;
  sc.disturbance_N = 2.0 * c.force.reference_N;
  EXPECT_LE(run_force_scenario(d, sc).disturbance_recovery_s, 0.5);
  sc.limits.anti_windup = false;
  EXPECT_GT(run_force_scenario(d, sc).disturbance_recovery_s, 0.5);
}
