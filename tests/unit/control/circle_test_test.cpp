#include "control/circle_test.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace cc = contour::control::circle;

namespace {
std::array<cc::SimAxis, 2> issue_axes() {
  std::array<cc::SimAxis, 2> a{};
  a[0].drive = {30.0, 0.010, 0.001, 0.0, 0};
  a[1].drive = {27.0, 0.012, 0.001, 0.0, 0};
  return a;
}
}  // namespace

TEST(CircleTest, Eq3RoundTripAndLagSign) {
  for (double w : {0.5, 5.0, 20.0}) {
    const cc::AxisDynamics d{27.0, 0.012};
    const cc::AxisResponse r = cc::response_of(d, 100.0, w);
    EXPECT_LT(r.phi_rad, 0.0);  // lag
    const cc::AxisDynamics back = cc::dynamics_from_response(r, 100.0, w);
    EXPECT_NEAR(back.kp_per_s, 27.0, 1e-9);
    EXPECT_NEAR(back.tau_s, 0.012, 1e-11);
  }
}

TEST(CircleTest, Eq4AsPrintedEqualsPhaseMatching) {
  const double w = 8.0, r = 10.0;
  const cc::AxisDynamics dx{30.0, 0.0105}, dy{27.0, 0.0125};
  const auto rx = cc::response_of(dx, r, w);
  const auto ry = cc::response_of(dy, r, w);
  const double k4 = cc::matched_gain_eq4(rx, ry, dx, r, w);
  EXPECT_NEAR(k4, cc::matched_gain(dx, dy, w), 1e-9);
  EXPECT_NEAR(k4, 30.0 + 64.0 * 0.002, 1e-9);
  // The matched gain gives both axes the same phase.
  const auto ry2 = cc::response_of({k4, dy.tau_s}, r, w);
  EXPECT_NEAR(ry2.phi_rad, rx.phi_rad, 1e-12);
}

TEST(CircleTest, EllipseMetricsOfASynthetic45DegreeEllipse) {
  std::vector<double> th, dev;
  for (int i = 0; i < 3600; ++i) {
    const double t = 2.0 * std::numbers::pi * i / 3600.0;
    th.push_back(t);
    dev.push_back(5.0 + 40.0 * std::sin(2.0 * t) + 3.0 * std::cos(t) + 1.0 * std::cos(3.0 * t));
  }
  const auto e = cc::ellipse_metrics(th, dev);
  EXPECT_NEAR(e.ellipse_um, 80.0, 1e-9);
  EXPECT_NEAR(e.ellipse_45_um, 80.0, 1e-9);
  EXPECT_NEAR(e.major_axis_deg, 45.0, 1e-9);
  EXPECT_NEAR(e.mean_um, 5.0, 1e-9);
  EXPECT_GT(e.circularity_um, 80.0);
}

TEST(CircleTest, SimulatedPaperCircleGivesThe185umEllipse) {
  cc::Circle c;  // R 100 mm, 3 m/min, CW
  const auto run = cc::simulate_circle(issue_axes(), c, {});
  const auto e = cc::ellipse_metrics(run.servo_angle_rad, run.servo_deviation_um);
  EXPECT_NEAR(e.ellipse_45_um, 185.0, 2.0);
  EXPECT_EQ(run.record.t_s.size(), 12566u);
}

TEST(CircleTest, EncoderRecordRecoversLoopGainAndLoopTau) {
  cc::Circle c;
  c.radius_mm = 10.0;
  c.feed_mm_min = 5000.0;
  c.direction = cc::Direction::kCcw;
  const auto axes = issue_axes();
  const auto run = cc::simulate_circle(axes, c, {});
  const auto f = cc::fit_machine_record(c, run.record);
  for (std::size_t a = 0; a < 2; ++a) {
    EXPECT_NEAR(f.dynamics[a].kp_per_s / axes[a].kp_per_s(), 1.0, 1e-3) << a;
    // tau_est = tau + T/2 (ZOH) in the sampled loop.
    EXPECT_NEAR(f.dynamics[a].tau_s / axes[a].tau_loop_s(), 1.0, 5e-3) << a;
  }
}

TEST(CircleTest, BallbarFitWithoutGeometryOnAGeometryFreeMachine) {
  cc::Circle c;
  const auto axes = issue_axes();
  const auto run = cc::simulate_circle(axes, c, {});
  cc::BallbarFitOptions o;
  o.kp_ref_x_per_s = 30.0;
  const auto f = cc::fit_ballbar(c, run.ballbar, o);
  EXPECT_TRUE(f.converged);
  EXPECT_NEAR(f.dynamics[1].kp_per_s, 27.0, 0.01);
  const auto g = cc::match_y_to_x(f, c.omega_rad_s());
  EXPECT_NEAR(g.ratio_y, 30.0 / 27.0, 1e-3);
}

TEST(CircleTest, BadInputThrows) {
  cc::Circle c;
  cc::BallbarTrace tr;
  tr.t_s = {0.0, 1.0};
  tr.angle_rad = {0.0};
  tr.deviation_um = {0.0, 0.0};
  EXPECT_THROW(cc::fit_ballbar(c, tr, {nullptr, 30.0, 0.01}), std::invalid_argument);
  c.radius_mm = -1.0;
  EXPECT_THROW(cc::simulate_circle(issue_axes(), c, {}), std::invalid_argument);
  cc::Circle ok;
  const auto run = cc::simulate_circle(issue_axes(), ok, {});
  EXPECT_THROW(cc::fit_ballbar(ok, run.ballbar, {nullptr, 0.0, 0.01}), std::invalid_argument);
  EXPECT_THROW(cc::fit_reversal(ok, run.ballbar, ok, run.ballbar, {30.0, {0.01, 0.01}, 6}),
               std::invalid_argument);
}
