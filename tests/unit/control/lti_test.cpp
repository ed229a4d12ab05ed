#include "control/lti.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

using namespace contour::control::lti;

TEST(Lti, ZohOfFirstOrderLagIsExact) {
  StateSpace g{Mat::Constant(1, 1, -2.0), Mat::Constant(1, 1, 6.0), Mat::Constant(1, 1, 1.0),
               Mat::Zero(1, 1), 0.0};
  const StateSpace d = c2d_zoh(g, 0.01);
  EXPECT_NEAR(d.a(0, 0), std::exp(-0.02), 1e-14);
  EXPECT_NEAR(d.b(0, 0), 3.0 * (1.0 - std::exp(-0.02)), 1e-14);
  EXPECT_THROW(c2d_zoh(d, 0.01), std::invalid_argument);
}

TEST(Lti, DlqrSolvesTheRiccatiEquation) {
  // Double integrator at 1 kHz: slow modes, where plain iteration would need ~1e5 steps.
  StateSpace g{Mat::Zero(2, 2), Mat::Zero(2, 1), Mat::Identity(2, 2), Mat::Zero(2, 1), 0.0};
  g.a(0, 1) = 1.0;
  g.b(1, 0) = 1.0;
  const StateSpace d = c2d_zoh(g, 0.001);
  const Mat q = Mat::Identity(2, 2) * 1e-3, r = Mat::Identity(1, 1) * 1e-3;
  const RiccatiResult res = dlqr(d.a, d.b, q, r);
  EXPECT_LT(res.residual, 1e-10);
  EXPECT_LT(res.iterations, 80);
  EXPECT_LT(max_pole_radius(d.a - d.b * res.gain), 1.0);
  // Continuous LQR of the double integrator with Q = I, R = 1: K = [1, sqrt(3)].
  EXPECT_NEAR(res.gain(0, 0), 1.0, 2e-3);
  EXPECT_NEAR(res.gain(0, 1), std::sqrt(3.0), 2e-3);
}

TEST(Lti, DlqrRejectsUnstabilisable) {
  Mat a = Mat::Identity(2, 2) * 1.1;
  Mat b = Mat::Zero(2, 1);
  b(0, 0) = 1.0;
  EXPECT_ANY_THROW(dlqr(a, b, Mat::Identity(2, 2), Mat::Identity(1, 1)));
}

TEST(Lti, KalmanGainStabilisesObserver) {
  Mat a(2, 2);
  a << 1.0, 0.001, 0.0, 1.0;
  Mat c(1, 2);
  c << 1.0, 0.0;
  const RiccatiResult k = dkalman(a, c, Mat::Identity(2, 2) * 1e-4, Mat::Identity(1, 1) * 1e-2);
  EXPECT_LT(max_pole_radius(a - k.gain * c), 1.0);
}

TEST(Lti, MarginsOfIntegratorLoopWithDelayFreeCrossover) {
  // Continuous L(s) = w_c/s with positive-feedback controller K = -w_c/s, plant G = 1:
  // PM = 90 deg, delay margin = (pi/2)/w_c.
  const double wc = 10.0;
  StateSpace g{Mat::Zero(0, 0), Mat::Zero(0, 1), Mat::Zero(1, 0), Mat::Identity(1, 1), 0.0};
  StateSpace k{Mat::Zero(1, 1), Mat::Constant(1, 1, 1.0), Mat::Constant(1, 1, -wc),
               Mat::Zero(1, 1), 0.0};
  const auto m = input_margins(g, k, 4000);
  ASSERT_EQ(m.size(), 1u);
  EXPECT_NEAR(m[0].phase_margin_deg, 90.0, 0.1);
  EXPECT_NEAR(m[0].crossover_rad_s, wc, 1e-3);
  EXPECT_NEAR(m[0].delay_margin_s, std::numbers::pi / 2.0 / wc, 1e-4);
}

TEST(Lti, FrequencyResponseAndSeries) {
  StateSpace g{Mat::Constant(1, 1, -1.0), Mat::Constant(1, 1, 1.0), Mat::Constant(1, 1, 1.0),
               Mat::Zero(1, 1), 0.0};
  const CMat r = freq_response(g, 1.0);
  EXPECT_NEAR(std::abs(r(0, 0)), 1.0 / std::sqrt(2.0), 1e-12);
  const StateSpace gg = series(g, g);
  EXPECT_NEAR(std::abs(freq_response(gg, 1.0)(0, 0)), 0.5, 1e-12);
}
