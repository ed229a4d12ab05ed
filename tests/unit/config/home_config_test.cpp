// machine.axes[].home and machine.allow_unhomed (issue 18): parsed with LinuxCNC's meaning,
// validated on load, errors naming the axis and the field.
#include <gtest/gtest.h>

#include <string>

#include "config/config.hpp"
#include "tests/support/config_errors.hpp"

namespace {

using contour::config::HomeConfig;
using contour::config::load_config_string;
using contour::test::any_contains;
using contour::test::config_errors;

std::string machine(const std::string& x_home, const std::string& extra = "",
                    const std::string& y = "    - {name: Y}\n") {
  return "machine:\n" + extra + "  axes:\n    - name: X\n      min_mm: -200\n      max_mm: 200\n" + x_home + y;
}

const std::string kSwitch =
    "      home: {method: switch, search_vel_mm_min: -1200, latch_vel_mm_min: 60, "
    "home_offset_mm: -199.5, home_position_mm: 0, sequence: 1}\n";

TEST(HomeConfig, NoHomeSectionAnywhereAllowsUnhomedMachines) {
  const auto cfg = load_config_string(machine(""));
  EXPECT_TRUE(cfg.machine.allow_unhomed);
  EXPECT_EQ(cfg.machine.axes[0].home.method, HomeConfig::Method::kNone);
  EXPECT_FALSE(cfg.machine.axes[0].home.present);
}

TEST(HomeConfig, ASwitchHomeIsParsedInMillimetresPerSecond) {
  const auto cfg = load_config_string(machine(kSwitch, "  allow_unhomed: true\n"));
  const HomeConfig& h = cfg.machine.axes[0].home;
  EXPECT_EQ(h.method, HomeConfig::Method::kSwitch);
  EXPECT_DOUBLE_EQ(h.search_vel_mm_s, -20.0);
  EXPECT_DOUBLE_EQ(h.latch_vel_mm_s, 1.0);
  EXPECT_DOUBLE_EQ(h.home_offset_mm, -199.5);
  EXPECT_DOUBLE_EQ(h.home_position_mm, 0.0);
  EXPECT_EQ(h.sequence, 1);
  EXPECT_DOUBLE_EQ(h.search_distance_mm, 480.0);  // 1.2 x the travel by default
  EXPECT_DOUBLE_EQ(h.unhomed_jog_mm_s, 10.0);
  EXPECT_TRUE(cfg.machine.allow_unhomed);
}

TEST(HomeConfig, WithHomingConfiguredAnAxisWithoutItNeedsAllowUnhomed) {
  const auto e = config_errors(machine(kSwitch));
  EXPECT_TRUE(any_contains(e, "axis Y has no homing")) << (e.empty() ? "" : e[0]);
  EXPECT_TRUE(any_contains(e, "machine.allow_unhomed: true"));
  // Explicit method none is the same, and allow_unhomed: false with no home section too.
  EXPECT_TRUE(any_contains(config_errors(machine(kSwitch, "", "    - {name: Y, home: {method: none}}\n")),
                           "axis Y has no homing"));
  EXPECT_TRUE(any_contains(config_errors(machine("", "  allow_unhomed: false\n")), "axis X has no homing"));
  // Absolute encoders are homed from the start.
  const auto cfg = load_config_string(
      machine(kSwitch, "", "    - {name: Y, home: {method: absolute, home_offset_mm: 12.5}}\n"));
  EXPECT_FALSE(cfg.machine.allow_unhomed);
  EXPECT_EQ(cfg.machine.axes[1].home.method, HomeConfig::Method::kAbsolute);
  EXPECT_DOUBLE_EQ(cfg.machine.axes[1].home.home_offset_mm, 12.5);
}

TEST(HomeConfig, BadValuesAreRefusedWithTheirField) {
  auto errs = [](const std::string& home) {
    return config_errors(machine("      home: {" + home + "}\n", "  allow_unhomed: true\n"));
  };
  EXPECT_TRUE(any_contains(errs("method: drive"), "drive_method"));
  EXPECT_TRUE(any_contains(errs("method: switch, search_vel_mm_min: 0, latch_vel_mm_min: 60"),
                           "search_vel_mm_min"));
  EXPECT_TRUE(any_contains(errs("method: switch, search_vel_mm_min: -100, latch_vel_mm_min: 600"),
                           "must not be faster than search_vel_mm_min"));
  EXPECT_TRUE(any_contains(errs("method: switch, latch_vel_mm_min: 60"), "search_vel_mm_min"));
  EXPECT_TRUE(any_contains(errs("method: switch, search_vel_mm_min: -100, latch_vel_mm_min: 60, "
                                "home_position_mm: 500"),
                           "home_position_mm"));
  EXPECT_TRUE(any_contains(errs("method: switch, search_vel_mm_min: -100, latch_vel_mm_min: 60, speed: 3"),
                           "speed"));
  EXPECT_TRUE(any_contains(errs("method: magic"), "method"));
}

TEST(HomeConfig, TheSimulatedPowerUpPositionIsASimKey) {
  const auto cfg = load_config_string(
      "machine:\n  axes:\n    - {name: X, sim: {power_up_mm: -37.5}}\n");
  EXPECT_DOUBLE_EQ(cfg.machine.axes[0].sim_power_up_mm, -37.5);
}

}  // namespace

// LinuxCNC's HOME_USE_INDEX as home.use_index (method switch only); the simulated encoder's index
// pitch and phase are sim keys.
TEST(HomeConfig, UseIndexIsASwitchOptionAndTheSimulatedIndexIsASimKey) {
  const std::string with_index =
      "      home: {method: switch, search_vel_mm_min: -1200, latch_vel_mm_min: 60, use_index: true}\n"
      "      sim: {index_pitch_mm: 5, index_phase_mm: 0.25}\n";
  const auto cfg = load_config_string(machine(with_index, "  allow_unhomed: true\n"));
  EXPECT_TRUE(cfg.machine.axes[0].home.use_index);
  EXPECT_DOUBLE_EQ(cfg.machine.axes[0].sim_index_pitch_mm, 5.0);
  EXPECT_DOUBLE_EQ(cfg.machine.axes[0].sim_index_phase_mm, 0.25);
  EXPECT_FALSE(load_config_string(machine(kSwitch, "  allow_unhomed: true\n")).machine.axes[0].home.use_index);
  const auto e = config_errors(
      machine("      home: {method: absolute, use_index: true}\n", "  allow_unhomed: true\n"));
  EXPECT_TRUE(any_contains(e, "use_index")) << (e.empty() ? "" : e[0]);
  EXPECT_TRUE(any_contains(e, "needs method switch"));
  EXPECT_TRUE(any_contains(config_errors(machine("      sim: {index_pitch_mm: -1}\n", "  allow_unhomed: true\n")),
                           "index_pitch_mm"));
}

// method drive (CiA 402 homing mode 6).
TEST(HomeConfig, ADriveHomeIsParsedWithItsMethodSpeedsAndTimeout) {
  const auto cfg = load_config_string(machine(
      "      home: {method: drive, drive_method: 21, search_vel_mm_min: -1200, latch_vel_mm_min: 60, "
      "accel_mm_s2: 250, home_offset_mm: -199.5, home_position_mm: 0, sequence: 2}\n",
      "  allow_unhomed: true\n"));
  const HomeConfig& h = cfg.machine.axes[0].home;
  EXPECT_EQ(h.method, HomeConfig::Method::kDrive);
  EXPECT_EQ(h.drive_method, 21);
  EXPECT_DOUBLE_EQ(h.search_vel_mm_s, 20.0);  // magnitudes: the method fixes the direction
  EXPECT_DOUBLE_EQ(h.latch_vel_mm_s, 1.0);
  EXPECT_DOUBLE_EQ(h.drive_accel_mm_s2, 250.0);
  EXPECT_DOUBLE_EQ(h.drive_timeout_s, 60.0);
  EXPECT_DOUBLE_EQ(h.home_offset_mm, -199.5);
  EXPECT_DOUBLE_EQ(h.home_position_mm, 0.0);
  EXPECT_EQ(h.sequence, 2);
  // The current-position methods need no speeds.
  const auto c35 = load_config_string(
      machine("      home: {method: drive, drive_method: 35, drive_timeout_s: 5}\n", "  allow_unhomed: true\n"));
  EXPECT_EQ(c35.machine.axes[0].home.drive_method, 35);
  EXPECT_DOUBLE_EQ(c35.machine.axes[0].home.drive_timeout_s, 5.0);
}

TEST(HomeConfig, BadDriveHomesAreRefusedWithTheirField) {
  auto errs = [](const std::string& home) {
    return config_errors(machine("      home: {" + home + "}\n", "  allow_unhomed: true\n"));
  };
  const std::string sp = ", search_vel_mm_min: 600, latch_vel_mm_min: 60";
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 1" + sp), "drive_method: 1 is not a CiA 402 homing method"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 36" + sp), "drive_method"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, latch_vel_mm_min: 60"), "search_vel_mm_min"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, search_vel_mm_min: 60"), "latch_vel_mm_min"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, search_vel_mm_min: 60, latch_vel_mm_min: 600"),
                           "must not be faster than search_vel_mm_min"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, accel_mm_s2: 0" + sp), "accel_mm_s2"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, drive_timeout_s: 0" + sp), "drive_timeout_s"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, use_index: true" + sp), "use_index"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, search_distance_mm: 5" + sp), "search_distance_mm"));
  EXPECT_TRUE(any_contains(errs("method: drive, drive_method: 21, home_position_mm: 900" + sp), "home_position_mm"));
  // The switch method's own keys are not the drive's.
  EXPECT_TRUE(any_contains(errs("method: switch, search_vel_mm_min: -100, latch_vel_mm_min: 60, drive_method: 21"),
                           "drive_method"));
}
