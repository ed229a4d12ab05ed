#include "config/config.hpp"
#include "tests/support/config_errors.hpp"

#include <gtest/gtest.h>

using contour::config::ConfigError;
using contour::config::load_config_string;

namespace {
std::vector<std::string> errors_of(const std::string& yaml) {
  return contour::test::config_errors(yaml, "test.yaml");
}
using contour::test::any_contains;
}  // namespace

TEST(Config, LoadsAxesWithDefaults) {
  auto cfg = load_config_string("machine:\n  axes:\n    - {name: X}\n    - {name: Y}\n    - {name: Z}\n");
  ASSERT_EQ(cfg.machine.axes.size(), 3u);
  EXPECT_DOUBLE_EQ(cfg.machine.axes[0].drive.gain_per_s, 120.0);
  EXPECT_DOUBLE_EQ(cfg.machine.axes[2].drive.tau_s, 0.025);
}

TEST(Config, UnknownKeyIsAnErrorWithLineAndPath) {
  auto errs = errors_of("machine:\n  axes:\n    - name: X\n      gian: 3\n");
  ASSERT_EQ(errs.size(), 1u);
  EXPECT_TRUE(any_contains(errs, "test.yaml:4:7: machine.axes[0].gian: unknown key")) << errs[0];
}

TEST(Config, AllErrorsReportedAtOnce) {
  auto errs = errors_of(
      "machine:\n  axes:\n    - name: X\n      counts_per_mm: -4\n      sim: {tau_ms: abc}\n"
      "bogus: 1\n");
  EXPECT_EQ(errs.size(), 3u);
  EXPECT_TRUE(any_contains(errs, "machine.axes[0].counts_per_mm: value -4 out of range"));
  EXPECT_TRUE(any_contains(errs, "machine.axes[0].sim.tau_ms: expected a number, got 'abc'"));
  EXPECT_TRUE(any_contains(errs, ":6:1: bogus: unknown key"));
}

TEST(Config, SyntaxErrorNamesLine) {
  auto errs = errors_of("machine:\n  axes: [\n");
  ASSERT_EQ(errs.size(), 1u);
  EXPECT_TRUE(any_contains(errs, "test.yaml:3")) << errs[0];
  EXPECT_TRUE(any_contains(errs, "YAML syntax error"));
}

TEST(Config, DuplicateAxisRejected) {
  auto errs = errors_of("machine:\n  axes:\n    - name: X\n    - name: X\n");
  EXPECT_TRUE(any_contains(errs, "axis X is defined twice"));
}

// Issue 16: a configuration without `machine:` is an error (it used to run the paper's Table 1
// machine without a word).
TEST(Config, AFileWithoutAMachineSectionIsAnError) {
  const auto errs = contour::test::config_errors("safety:\n  ferror_mm: 1.0\n", "m.yaml");
  ASSERT_EQ(errs.size(), 1u) << ::testing::PrintToString(errs);
  EXPECT_NE(errs[0].find("m.yaml:1:1: machine: missing section"), std::string::npos) << errs[0];
  EXPECT_TRUE(contour::test::config_errors("safety:\n  ferror_mm: 1.0\n" +
                                           std::string(contour::test::kMachineYaml))
                  .empty());
}

// Issue 18: rapid and spindle override limits (LinuxCNC: rapids at most 100 %; the spindle
// override range must contain 100 %).
TEST(Config, OverrideLimitsAreRangeChecked) {
  const std::string m = "machine:\n  axes:\n    - {name: X}\n";
  auto cfg = load_config_string(m + "interpolator: {rapid_override_max_percent: 80}\n"
                                    "spindle: {type: sim, override_min_percent: 20, override_max_percent: 200}\n");
  EXPECT_EQ(cfg.interpolator.rapid_override_max_percent, 80.0);
  EXPECT_EQ(cfg.spindle.override_min_percent, 20.0);
  EXPECT_EQ(cfg.spindle.override_max_percent, 200.0);
  const auto d = load_config_string(m);
  EXPECT_EQ(d.interpolator.rapid_override_max_percent, 100.0);
  EXPECT_EQ(d.spindle.override_min_percent, 50.0);
  EXPECT_EQ(d.spindle.override_max_percent, 100.0);
  auto errs = errors_of(m + "interpolator: {rapid_override_max_percent: 150}\n");
  EXPECT_TRUE(any_contains(errs, "interpolator.rapid_override_max_percent: value 150 out of range"))
      << ::testing::PrintToString(errs);
  errs = errors_of(m + "spindle: {type: sim, override_min_percent: 120, override_max_percent: 90}\n");
  EXPECT_TRUE(any_contains(errs, "spindle.override_min_percent: value 120 out of range"))
      << ::testing::PrintToString(errs);
  EXPECT_TRUE(any_contains(errs, "spindle.override_max_percent: value 90 out of range"))
      << ::testing::PrintToString(errs);
}
