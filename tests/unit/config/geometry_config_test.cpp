#include "config/geometry_config.hpp"

#include <gtest/gtest.h>

#include "config/circle_test_config.hpp"
#include "tests/support/config_errors.hpp"

using contour::config::ConfigError;
using contour::config::load_circle_test_config;
using contour::config::load_circle_test_config_string;
using contour::config::load_geometry_file;
using contour::config::load_geometry_string;

namespace {
template <class F>
std::vector<std::string> errors_of(F f) {
  return contour::test::config_errors_of(f);
}
using contour::test::any_contains;
}  // namespace

TEST(GeometryConfig, UnitsAreMicrometresAndMicroradians) {
  const auto g = load_geometry_string(
      "tool_offset_mm: [0, 0, 100]\nsquareness_urad: {xy: 100}\n"
      "axes:\n  X: {dx_um: [1, 0.02], ey_urad: [20]}\n");
  const Eigen::Vector3d e = g.error_mm({50.0, 80.0, 0.0});
  // 1 + 0.02*50 um positioning, 100 urad * 80 mm squareness, 20 urad * 100 mm Abbe.
  EXPECT_NEAR(e.x() * 1000.0, 2.0 + 8.0 + 2.0, 1e-3);
}

TEST(GeometryConfig, ExampleFileLoadsAndIsAbout20um) {
  const auto g = load_geometry_file(CONTOUR_SOURCE_DIR "/config/geometry/example.yaml");
  double worst = 0.0;
  for (int i = 0; i < 360; ++i) {
    const double t = i * 3.14159265358979 / 180.0;
    worst = std::max(worst, g.error_mm({100.0 * std::cos(t), 100.0 * std::sin(t), 0.0}).norm());
  }
  EXPECT_GT(worst * 1000.0, 10.0);
  EXPECT_LT(worst * 1000.0, 30.0);
}

TEST(GeometryConfig, ErrorsNameLineAndKey) {
  const auto errs = errors_of([] {
    load_geometry_string("axes:\n  X: {dx_um: [1, a], dq_um: [1]}\n  W: {}\nsquareness_urad: {xy: 1e9}\n",
                         "g.yaml");
  });
  EXPECT_TRUE(any_contains(errs, "g.yaml:2:")) << (errs.empty() ? "" : errs[0]);
  EXPECT_TRUE(any_contains(errs, "axes.X.dx_um[1]"));
  EXPECT_TRUE(any_contains(errs, "axes.X.dq_um: unknown key"));
  EXPECT_TRUE(any_contains(errs, "axes.W: unknown key"));
  EXPECT_TRUE(any_contains(errs, "squareness_urad.xy"));
  const auto too_many = errors_of([] { load_geometry_string("axes: {Y: {dy_um: [1,2,3,4,5,6,7,8,9]}}\n"); });
  EXPECT_TRUE(any_contains(too_many, "axes.Y.dy_um"));
}

TEST(CircleTestConfig, ShippedFileHasTheIssueMismatch) {
  const auto c = load_circle_test_config(CONTOUR_SOURCE_DIR "/config/circle_test.yaml");
  EXPECT_DOUBLE_EQ(c.axes[0].kp_per_s(), 30.0);
  EXPECT_DOUBLE_EQ(c.axes[1].kp_per_s(), 27.0);
  EXPECT_DOUBLE_EQ(c.axes[0].drive.tau_s, 0.010);
  EXPECT_DOUBLE_EQ(c.axes[1].drive.tau_s, 0.012);
  EXPECT_DOUBLE_EQ(c.axes[0].drive.period_s, 0.001);
  EXPECT_NE(c.geometry_file.find("config/geometry/example.yaml"), std::string::npos);
  EXPECT_NO_THROW(load_geometry_file(c.geometry_file));
}

TEST(CircleTestConfig, MissingAxisAndBadValues) {
  const auto errs = errors_of([] {
    load_circle_test_config_string(
        "axes:\n  X: {gain_per_s: 30}\ntest: {direction: up, radius_mm: -3}\ncircle_test: 1\n", "c.yaml");
  });
  EXPECT_TRUE(any_contains(errs, "axis Y is required"));
  EXPECT_TRUE(any_contains(errs, "test.direction"));
  EXPECT_TRUE(any_contains(errs, "test.radius_mm"));
  EXPECT_TRUE(any_contains(errs, "c.yaml:4:1: circle_test: unknown key"));
}
