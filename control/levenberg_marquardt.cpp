#include "control/levenberg_marquardt.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace contour::control {

namespace {
bool all_finite(const Eigen::VectorXd& v) { return v.allFinite(); }
}  // namespace

const char* to_string(LmStatus s) noexcept {
  switch (s) {
    case LmStatus::kConverged:
      return "converged";
    case LmStatus::kMaxIterations:
      return "max_iterations";
    case LmStatus::kNonFinite:
      return "non_finite";
    case LmStatus::kBadInput:
      return "bad_input";
  }
  return "unknown";
}

LmResult levenberg_marquardt(const ResidualFunction& f, Eigen::Index m, const Eigen::VectorXd& p0,
                             const Eigen::VectorXd& typical_in, const LmOptions& o) {
  LmResult res;
  const Eigen::Index n = p0.size();
  res.params = p0;
  if (n == 0 || m < n || (typical_in.size() != 0 && typical_in.size() != n)) return res;
  Eigen::VectorXd typical = Eigen::VectorXd::Ones(n);
  if (typical_in.size() == n) typical = typical_in.cwiseAbs();

  Eigen::VectorXd p = p0;
  Eigen::VectorXd r(m), r_try(m), r_plus(m), r_minus(m);
  f(p, r);
  if (!all_finite(r)) {
    res.status = LmStatus::kNonFinite;
    return res;
  }
  double cost = 0.5 * r.squaredNorm();
  Eigen::MatrixXd jac(m, n);
  double lambda = o.initial_lambda;
  double nu = 2.0;
  res.status = LmStatus::kMaxIterations;
  Eigen::MatrixXd jtj(n, n);
  for (int it = 0; it < o.max_iterations; ++it) {
    res.iterations = it + 1;
    for (Eigen::Index i = 0; i < n; ++i) {
      const double h = o.rel_step * std::max(std::abs(p(i)), typical(i));
      Eigen::VectorXd pp = p;
      pp(i) = p(i) + h;
      f(pp, r_plus);
      pp(i) = p(i) - h;
      f(pp, r_minus);
      jac.col(i) = (r_plus - r_minus) / (2.0 * h);
    }
    jtj = jac.transpose() * jac;
    const Eigen::VectorXd g = jac.transpose() * r;
    // Marquardt scaling; a floor keeps a parameter the data cannot see from making A singular.
    Eigen::VectorXd d = jtj.diagonal().cwiseMax(1e-30 + 1e-12 * jtj.diagonal().maxCoeff());
    bool accepted = false;
    for (int inner = 0; inner < 30 && !accepted; ++inner) {
      Eigen::MatrixXd a = jtj;
      a.diagonal() += lambda * d;
      const Eigen::VectorXd dp = a.ldlt().solve(-g);
      if (!dp.allFinite()) {
        lambda *= nu;
        nu *= 2.0;
        continue;
      }
      const Eigen::VectorXd p_try = p + dp;
      f(p_try, r_try);
      const double cost_try = all_finite(r_try) ? 0.5 * r_try.squaredNorm() : HUGE_VAL;
      const double predicted = -(g.dot(dp) + 0.5 * dp.dot(jtj * dp));
      const double rho = predicted > 0.0 ? (cost - cost_try) / predicted : -1.0;
      if (cost_try < cost && rho > 0.0) {
        accepted = true;
        bool small_step = true;
        for (Eigen::Index i = 0; i < n; ++i) {
          if (std::abs(dp(i)) > o.step_tolerance * std::max(std::abs(p(i)), typical(i))) {
            small_step = false;
          }
        }
        const double rel_decrease = (cost - cost_try) / std::max(cost, 1e-300);
        p = p_try;
        r = r_try;
        cost = cost_try;
        lambda *= std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
        nu = 2.0;
        if (small_step || rel_decrease < o.cost_tolerance) res.status = LmStatus::kConverged;
      } else {
        lambda *= nu;
        nu *= 2.0;
      }
    }
    if (!accepted) res.status = LmStatus::kConverged;  // no descent left at machine precision
    if (res.status == LmStatus::kConverged) break;
  }
  res.params = p;
  res.cost = cost;
  res.jtj_inverse = jtj.ldlt().solve(Eigen::MatrixXd::Identity(n, n));
  return res;
}

}  // namespace contour::control
