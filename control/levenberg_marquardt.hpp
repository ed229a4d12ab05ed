#pragma once
// Small Levenberg-Marquardt solver for dense nonlinear least squares: minimise 0.5 * |r(p)|^2.
//
// The residual function fills r (already sized to residual_count) from p. The Jacobian is formed
// by central differences with a per-parameter step h_i = rel_step * max(|p_i|, typical_i), so
// parameters of very different scale (mm amplitudes vs rad phases) are handled through
// `typical`. Marquardt's scaling (damping on diag(J^T J)) with the Nielsen update of lambda.
//
// Offline analysis code (circle test): allocates, not for the RT cycle. Never throws for
// numerical trouble: the status says what happened (non-finite residuals stop the iteration).
#include <Eigen/Core>
#include <functional>

namespace contour::control {

struct LmOptions {
  int max_iterations = 100;
  double rel_step = 1e-6;      // finite-difference step relative to max(|p|, typical)
  double step_tolerance = 1e-12;  // stop when |dp_i| <= step_tolerance * max(|p_i|, typical_i)
  double cost_tolerance = 1e-15;  // stop when the relative cost decrease is below this
  double initial_lambda = 1e-3;
};

enum class LmStatus {
  kConverged,       // step or cost tolerance met
  kMaxIterations,   // iteration budget spent (result is the best point seen)
  kNonFinite,       // the residual function returned NaN/inf at the start point
  kBadInput,        // sizes inconsistent
};

struct LmResult {
  Eigen::VectorXd params;
  double cost = 0.0;  // 0.5 * |r|^2 at params
  int iterations = 0;
  LmStatus status = LmStatus::kBadInput;
  // (J^T J)^-1 at the solution (unscaled); multiply by 2*cost/(m-n) for the parameter covariance.
  Eigen::MatrixXd jtj_inverse;
};

using ResidualFunction = std::function<void(const Eigen::VectorXd& p, Eigen::VectorXd& r)>;

// typical: positive scale per parameter (same size as p0), or empty for all-ones.
LmResult levenberg_marquardt(const ResidualFunction& f, Eigen::Index residual_count,
                             const Eigen::VectorXd& p0, const Eigen::VectorXd& typical = {},
                             const LmOptions& options = {});

const char* to_string(LmStatus s) noexcept;

}  // namespace contour::control
