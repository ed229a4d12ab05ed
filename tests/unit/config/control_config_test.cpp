#include "config/control_config.hpp"

#include <gtest/gtest.h>

#include "config/config.hpp"
#include "tests/support/config_errors.hpp"

using namespace contour::config;

namespace {
std::vector<std::string> errors_of(const std::string& yaml) {
  return contour::test::config_errors(yaml, "c.yaml");
}
using contour::test::any_contains;
}  // namespace

TEST(ControlConfig, DefaultsAreThePapersTable1) {
  const Config c = load_config_string(std::string("control: {}\n") + contour::test::kMachineYaml);
  EXPECT_EQ(c.control.controller, ControllerType::kCcc);
  EXPECT_DOUBLE_EQ(c.control.kp[2], 0.6);
  EXPECT_DOUBLE_EQ(c.control.coupling.cp, 15.0);
  EXPECT_DOUBLE_EQ(c.control.coupling.ci_per_s, 300.0);
  EXPECT_DOUBLE_EQ(c.control.coupling.cd_s, 0.3);
  EXPECT_DOUBLE_EQ(c.control.pid_kd_s[0], 0.06);
  EXPECT_DOUBLE_EQ(c.control.pid_ki_per_s[2], 0.02);
  EXPECT_TRUE(c.control.delay_compensation);
  EXPECT_EQ(c.control.window_capacity, 256);
}

TEST(ControlConfig, ParsesEveryKey) {
  const Config c = load_config_string(
      "control:\n  controller: pid\n  kp: 0.5\n  pid: {kp: [1, 2, 3], kd_s: [0.1, 0.2, 0.3], "
      "ki_per_s: [4, 5, 6]}\n  feed_forward: 0.5\n  velocity_limit_mm_min: [6000, 6000, 3000]\n"
      "  coupling: {cp: 10, ci_per_s: 100, cd_s: 0.1, remove_tangential_integral: false}\n"
      "  model: linear\n  window_rule: literal\n  window_capacity: 64\n"
      "  delay_compensation: false\n" + std::string(contour::test::kMachineYaml));
  EXPECT_EQ(c.control.controller, ControllerType::kPid);
  EXPECT_DOUBLE_EQ(c.control.kp[1], 0.5);
  EXPECT_DOUBLE_EQ(c.control.pid_ki_per_s[1], 5.0);
  EXPECT_FALSE(c.control.coupling.remove_tangential_integral);
  EXPECT_EQ(c.control.model, contour::control::ModelKind::kLinear);
  EXPECT_EQ(c.control.window_rule, contour::control::WindowRule::kLiteral);
  EXPECT_FALSE(c.control.delay_compensation);
  std::array<contour::control::FeedDriveParams, 3> d{};
  const auto sp = make_servo_params(c.control, ControllerType::kPid, d, 3, 0.001, 1);
  EXPECT_NEAR(sp.axis[2].u_max_mm, 3000.0 / 60.0 / d[2].gain_per_s, 1e-12);
  EXPECT_FALSE(sp.coupling.enable);
  EXPECT_EQ(sp.law, contour::control::AxisLaw::kPid);
}

TEST(ControlConfig, ErrorsNameLineAndKey) {
  const auto errs = errors_of(
      "control:\n  controller: pd\n  coupling: {cp: -1, cq: 3}\n  window_capacity: 2\n");
  EXPECT_TRUE(any_contains(errs, "c.yaml:2:15: control.controller: 'pd' is not one of")) << errs.size();
  EXPECT_TRUE(any_contains(errs, "control.coupling.cp: value -1 out of range"));
  EXPECT_TRUE(any_contains(errs, "control.coupling.cq: unknown key"));
  EXPECT_TRUE(any_contains(errs, "control.window_capacity: value 2 out of range"));
}

TEST(ControlConfig, Table1FileLoads) {
  const Config c = load_config_file(CONTOUR_SOURCE_DIR "/config/table1.yaml");
  ASSERT_EQ(c.machine.axes.size(), 3u);
  EXPECT_DOUBLE_EQ(c.machine.axes[2].drive.gain_per_s, 115.0);
  EXPECT_EQ(c.machine.axes[0].drive.delay_cycles, 1);
  EXPECT_DOUBLE_EQ(c.control.pid_kp[0], 0.69);
}
