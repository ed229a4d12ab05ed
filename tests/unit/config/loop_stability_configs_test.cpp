// Issue 16: today's configurations pass the stability check the daemon will run on start-up,
// SIGHUP, `gains set` and `gains save` (control/loop_stability.hpp), with the documented default
// derivative filter and mismatch margin, for the controller each file selects and, for the
// seed-000 machine, for all three (p, pid, ccc).
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "config/config.hpp"
#include "config/control_config.hpp"
#include "control/loop_stability.hpp"
#include "tests/support/config_errors.hpp"

namespace contour::config {
namespace {
using contour::test::kMachineYaml;

control::StabilityVerdict check(const Config& cfg, ControllerType type) {
  std::array<control::FeedDriveParams, 3> dp{};
  int delay = 0;
  const int axes = static_cast<int>(cfg.machine.axes.size());
  for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
    dp[i] = cfg.machine.axes[i].drive;
    dp[i].period_s = cfg.machine.period_s;
    delay = std::max(delay, dp[i].delay_cycles);
  }
  const control::ServoParams p =
      make_servo_params(cfg.control, type, dp, axes, cfg.machine.period_s, delay);
  return control::check_loop_stability(p, make_loop_plant(cfg.machine));
}

TEST(LoopStabilityConfigs, EveryShippedConfigPasses) {
  int checked = 0;
  for (const auto& e : std::filesystem::directory_iterator(CONTOUR_SOURCE_DIR "/config")) {
    if (e.path().extension() != ".yaml") continue;
    // circle_test.yaml is the circle-test tool's own file format, not a contourd config.
    if (e.path().filename() == "circle_test.yaml") continue;
    Config cfg;
    try {
      cfg = load_config_file(e.path().string());
    } catch (const std::exception& ex) {
      ADD_FAILURE() << e.path() << ": " << ex.what();
      continue;
    }
    if (cfg.machine.axes.empty() || cfg.machine.axes.size() > 3) continue;
    const auto v = check(cfg, cfg.control.controller);
    EXPECT_TRUE(v.stable) << e.path().filename() << ": " << v.reason;
    ++checked;
  }
  EXPECT_GE(checked, 5);  // table1, sim, hil, force_*, circle_test (its default machine)
}

TEST(LoopStabilityConfigs, Table1BaselinesPass) {
  const Config cfg = load_config_file(CONTOUR_SOURCE_DIR "/config/table1.yaml");
  for (ControllerType t : {ControllerType::kP, ControllerType::kPid, ControllerType::kCcc}) {
    const auto v = check(cfg, t);
    EXPECT_TRUE(v.stable) << controller_type_name(t) << ": " << v.reason;
  }
}

TEST(LoopStabilityConfigs, PlantFromTheMachineSection) {
  const Config cfg = load_config_file(CONTOUR_SOURCE_DIR "/config/sim.yaml");
  const control::LoopPlant pl = make_loop_plant(cfg.machine);
  ASSERT_EQ(pl.axes, 3);
  EXPECT_DOUBLE_EQ(pl.axis[2].gain_per_s, 115.0);
  EXPECT_DOUBLE_EQ(pl.axis[2].tau_s, 0.025);
  EXPECT_DOUBLE_EQ(pl.axis[0].blu_mm, 0.0005);
  EXPECT_EQ(pl.axis[0].delay_cycles, 1);
  EXPECT_NEAR(pl.axis[0].max_velocity_mm_s, 10000.0 / 60.0, 1e-9);
  EXPECT_DOUBLE_EQ(pl.axis[0].max_accel_mm_s2, 2000.0);
}

TEST(LoopStabilityConfigs, DerivativeKeysParsedAndValidated) {
  Config c = load_config_string(std::string("control: {}\n") + kMachineYaml);
  EXPECT_DOUBLE_EQ(c.control.derivative.model_blend_s, 0.005);  // documented default
  EXPECT_EQ(c.control.derivative.same_geometry, control::SameGeometry::kAhead);
  EXPECT_DOUBLE_EQ(c.control.derivative.lowpass_s, 0.0);
  c = load_config_string(
      std::string("control:\n  derivative: {model_blend_ms: 0, same_geometry: never, lowpass_ms: 1.5}\n") +
      kMachineYaml);
  EXPECT_DOUBLE_EQ(c.control.derivative.model_blend_s, 0.0);
  EXPECT_EQ(c.control.derivative.same_geometry, control::SameGeometry::kNever);
  EXPECT_DOUBLE_EQ(c.control.derivative.lowpass_s, 0.0015);
  EXPECT_THROW(load_config_string(std::string("control:\n  derivative: {model_blend_ms: -1}\n") + kMachineYaml),
               ConfigError);
  EXPECT_THROW(load_config_string(std::string("control:\n  derivative: {same_geometry: sometimes}\n") +
                                  kMachineYaml),
               ConfigError);
  EXPECT_THROW(load_config_string(std::string("control:\n  derivative: {blend_ms: 5}\n") + kMachineYaml),
               ConfigError);
}

}  // namespace
}  // namespace contour::config
