#include "control/levenberg_marquardt.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using contour::control::levenberg_marquardt;
using contour::control::LmStatus;

TEST(LevenbergMarquardt, Rosenbrock) {
  auto f = [](const Eigen::VectorXd& p, Eigen::VectorXd& r) {
    r(0) = 10.0 * (p(1) - p(0) * p(0));
    r(1) = 1.0 - p(0);
  };
  const auto res = levenberg_marquardt(f, 2, Eigen::Vector2d(-1.2, 1.0));
  EXPECT_EQ(res.status, LmStatus::kConverged);
  EXPECT_NEAR(res.params(0), 1.0, 1e-8);
  EXPECT_NEAR(res.params(1), 1.0, 1e-8);
}

TEST(LevenbergMarquardt, NoisyExponentialFitWithScaledParameters) {
  // y = a exp(-b t) + c with a ~ 1e3, b ~ 1e-2: parameters 5 decades apart.
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 0.01);
  const int m = 200;
  Eigen::VectorXd t(m), y(m);
  for (int i = 0; i < m; ++i) {
    t(i) = i;
    y(i) = 1000.0 * std::exp(-0.012 * i) + 3.0 + n(rng);
  }
  auto f = [&](const Eigen::VectorXd& p, Eigen::VectorXd& r) {
    r = (p(0) * (-p(1) * t.array()).exp() + p(2)).matrix() - y;
  };
  Eigen::VectorXd p0(3), typ(3);
  p0 << 500.0, 0.03, 0.0;
  typ << 1000.0, 0.01, 1.0;
  const auto res = levenberg_marquardt(f, m, p0, typ);
  EXPECT_EQ(res.status, LmStatus::kConverged);
  EXPECT_NEAR(res.params(0), 1000.0, 0.05);
  EXPECT_NEAR(res.params(1), 0.012, 1e-6);
  EXPECT_NEAR(res.params(2), 3.0, 0.01);
  EXPECT_LT(std::sqrt(2.0 * res.cost / m), 0.012);
}

TEST(LevenbergMarquardt, BadInputAndNonFinite) {
  auto f = [](const Eigen::VectorXd& p, Eigen::VectorXd& r) { r.setConstant(std::log(p(0))); };
  EXPECT_EQ(levenberg_marquardt(f, 0, Eigen::VectorXd::Ones(1)).status, LmStatus::kBadInput);
  EXPECT_EQ(levenberg_marquardt(f, 3, Eigen::VectorXd::Constant(1, -1.0)).status,
            LmStatus::kNonFinite);
  EXPECT_EQ(levenberg_marquardt(f, 3, Eigen::VectorXd::Ones(1), Eigen::VectorXd::Ones(2)).status,
            LmStatus::kBadInput);
}
