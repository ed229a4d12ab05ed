#pragma once
// Linear time-invariant state-space utilities for controller DESIGN (setup time only).
//
// Everything here may allocate (dynamic-size Eigen) and throws std::invalid_argument /
// std::runtime_error on bad dimensions or a Riccati iteration that does not converge. Nothing here
// is RT-safe; the runtime controllers copy the results into fixed-size matrices.
//
// Conventions
// - Discrete systems: x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k], period T (s).
// - Continuous systems: period_s == 0.
// - LQR gain K: u = -K x minimises sum x'Qx + u'Ru.
// - Kalman (predictor) gain L: x^[k+1] = A x^ + B u + L (y - C x^).
// - Controllers in margin computations use POSITIVE feedback u = K(z) y (the sign is inside K).
//   Loop-at-a-time return ratios are l_i = L_ii - L_io (I + L_oo)^-1 L_oi with L = -K G (at the
//   inputs) or L = -G K (at the outputs); phase margin = 180 deg - |arg l(jw_c)| at each |l| = 1
//   crossing, delay margin = (arg l + pi) / w_c (the smallest over all crossings).
#include <Eigen/Dense>
#include <complex>
#include <vector>

namespace contour::control::lti {

using Mat = Eigen::MatrixXd;
using CMat = Eigen::MatrixXcd;

struct StateSpace {
  Mat a, b, c, d;
  double period_s = 0.0;  // 0 = continuous
  [[nodiscard]] Eigen::Index states() const { return a.rows(); }
  [[nodiscard]] Eigen::Index inputs() const { return b.cols(); }
  [[nodiscard]] Eigen::Index outputs() const { return c.rows(); }
  // Throws std::invalid_argument naming the mismatch.
  void check() const;
};

// Exact zero-order-hold discretisation: [Ad Bd; 0 I] = expm([A B; 0 0] T).
StateSpace c2d_zoh(const StateSpace& sys, double period_s);

struct RiccatiResult {
  Mat p;             // stabilising solution of the DARE
  Mat gain;          // LQR K (u = -K x) or Kalman predictor L
  int iterations = 0;
  double residual = 0.0;  // max |DARE(P)| relative to max(1, |P|)
};

// Discrete LQR by the structure-preserving doubling iteration of the Riccati equation
// (quadratic convergence; ~20-40 doublings for 1 kHz designs whose slowest closed-loop mode
// is seconds, where plain fixed-point iteration would need tens of thousands of steps).
// Throws std::runtime_error if it does not converge or the closed loop is not Schur stable.
RiccatiResult dlqr(const Mat& a, const Mat& b, const Mat& q, const Mat& r);

// Steady-state Kalman predictor gain by duality (dlqr on A', C', W, V). W: process noise
// covariance (n x n), V: measurement noise covariance (p x p).
RiccatiResult dkalman(const Mat& a, const Mat& c, const Mat& w, const Mat& v);

// Spectral radius (discrete) or max real part (continuous) of A.
double max_pole_radius(const Mat& a);

// G(e^{jwT}) (discrete) or G(jw) (continuous).
CMat freq_response(const StateSpace& sys, double w_rad_s);

// Closed loop of plant G and controller K with positive feedback u = K y + v (external v at the
// plant input). Returns the A matrix of the interconnection (states: plant then controller).
// Requires G.d == 0 or K.d == 0 (no algebraic loop). Both must have the same period.
Mat closed_loop_a(const StateSpace& plant, const StateSpace& ctrl);

// Series connection y = G2 (G1 u).
StateSpace series(const StateSpace& g1, const StateSpace& g2);

struct LoopMargin {
  double phase_margin_deg = 180.0;  // +inf-like 180 when |l| never crosses 1
  double crossover_rad_s = 0.0;     // crossover with the smallest phase margin (0 = none)
  double delay_margin_s = 1e9;      // smallest delay that destabilises (1e9 = none found)
  double gain_margin_db = 1e9;      // at the first -180 deg phase crossing (1e9 = none)
  bool crossed = false;
};

// Loop-at-a-time margins at each plant input (loop broken at input i, others closed).
std::vector<LoopMargin> input_margins(const StateSpace& plant, const StateSpace& ctrl,
                                      int points = 3000);
// Loop-at-a-time margins at each plant output.
std::vector<LoopMargin> output_margins(const StateSpace& plant, const StateSpace& ctrl,
                                       int points = 3000);

struct SensitivityPeaks {
  double input_s = 0.0;   // max over w of sigma_max((I - K G)^-1)
  double output_s = 0.0;  // max over w of sigma_max((I - G K)^-1)
  double output_t = 0.0;  // max over w of sigma_max(I - (I - G K)^-1)
};
SensitivityPeaks sensitivity_peaks(const StateSpace& plant, const StateSpace& ctrl,
                                   int points = 3000);

// Log-spaced frequency grid from w_min to the Nyquist frequency (discrete) or w_max.
std::vector<double> frequency_grid(double period_s, int points, double w_min = 1e-3,
                                   double w_max_continuous = 1e4);

}  // namespace contour::control::lti
