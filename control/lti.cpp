#include "control/lti.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <numbers>
#include <stdexcept>
#include <string>
#include <unsupported/Eigen/MatrixFunctions>

namespace contour::control::lti {

namespace {
using Cplx = std::complex<double>;

std::string dims(const Mat& m) {
  return std::to_string(m.rows()) + "x" + std::to_string(m.cols());
}

Cplx eval_point(double period_s, double w) {
  if (period_s > 0.0) return std::exp(Cplx(0.0, w * period_s));
  return Cplx(0.0, w);
}

// Loop-at-a-time return ratio for channel i of the square return-ratio matrix l.
Cplx loop_at_a_time(const CMat& l, Eigen::Index i) {
  const Eigen::Index n = l.rows();
  if (n == 1) return l(0, 0);
  std::vector<Eigen::Index> others;
  for (Eigen::Index j = 0; j < n; ++j) {
    if (j != i) others.push_back(j);
  }
  const auto m = static_cast<Eigen::Index>(others.size());
  CMat loo(m, m), lio(1, m), loi(m, 1);
  for (Eigen::Index a = 0; a < m; ++a) {
    lio(0, a) = l(i, others[static_cast<std::size_t>(a)]);
    loi(a, 0) = l(others[static_cast<std::size_t>(a)], i);
    for (Eigen::Index b = 0; b < m; ++b) {
      loo(a, b) = l(others[static_cast<std::size_t>(a)], others[static_cast<std::size_t>(b)]);
    }
  }
  const CMat iloo = CMat::Identity(m, m) + loo;
  const CMat corr = lio * iloo.partialPivLu().solve(loi);
  return l(i, i) - corr(0, 0);
}

LoopMargin margins_of(const std::function<Cplx(double)>& l, const std::vector<double>& grid) {
  LoopMargin out;
  auto mag = [&](double w) { return std::abs(l(w)) - 1.0; };
  double best_pm = 1e9;
  for (std::size_t k = 0; k + 1 < grid.size(); ++k) {
    const double w0 = grid[k], w1 = grid[k + 1];
    const Cplx l0 = l(w0), l1 = l(w1);
    const double m0 = std::abs(l0) - 1.0, m1 = std::abs(l1) - 1.0;
    if ((m0 > 0.0) != (m1 > 0.0)) {
      double lo = w0, hi = w1, flo = m0;
      for (int it = 0; it < 60; ++it) {
        const double mid = std::sqrt(lo * hi);
        const double fm = mag(mid);
        if ((fm > 0.0) == (flo > 0.0)) {
          lo = mid;
          flo = fm;
        } else {
          hi = mid;
        }
      }
      const double wc = std::sqrt(lo * hi);
      const double ph = std::arg(l(wc));  // (-pi, pi]
      const double pm = (std::numbers::pi - std::abs(ph)) * 180.0 / std::numbers::pi;
      const double dm = (ph + std::numbers::pi) / wc;
      out.crossed = true;
      if (pm < best_pm) {
        best_pm = pm;
        out.phase_margin_deg = pm;
        out.crossover_rad_s = wc;
      }
      out.delay_margin_s = std::min(out.delay_margin_s, dm);
    }
    // Phase crossing of the negative real axis: imag changes sign while real < 0.
    if ((l0.imag() > 0.0) != (l1.imag() > 0.0) && l0.real() < 0.0 && l1.real() < 0.0) {
      const double gm = -20.0 * std::log10(0.5 * (std::abs(l0) + std::abs(l1)));
      if (out.gain_margin_db >= 1e9) out.gain_margin_db = gm;
    }
  }
  return out;
}
}  // namespace

void StateSpace::check() const {
  const Eigen::Index n = a.rows();
  if (a.cols() != n) throw std::invalid_argument("state space: A must be square, got " + dims(a));
  if (b.rows() != n) throw std::invalid_argument("state space: B rows != states: " + dims(b));
  if (c.cols() != n) throw std::invalid_argument("state space: C cols != states: " + dims(c));
  if (d.rows() != c.rows() || d.cols() != b.cols()) {
    throw std::invalid_argument("state space: D must be " + std::to_string(c.rows()) + "x" +
                                std::to_string(b.cols()) + ", got " + dims(d));
  }
  if (!(period_s >= 0.0)) throw std::invalid_argument("state space: negative period");
}

StateSpace c2d_zoh(const StateSpace& sys, double period_s) {
  sys.check();
  if (sys.period_s != 0.0) throw std::invalid_argument("c2d_zoh: system is already discrete");
  if (!(period_s > 0.0)) throw std::invalid_argument("c2d_zoh: period must be > 0");
  const Eigen::Index n = sys.states(), m = sys.inputs();
  Mat big = Mat::Zero(n + m, n + m);
  big.topLeftCorner(n, n) = sys.a * period_s;
  big.topRightCorner(n, m) = sys.b * period_s;
  const Mat e = big.exp();
  StateSpace out;
  out.a = e.topLeftCorner(n, n);
  out.b = e.topRightCorner(n, m);
  out.c = sys.c;
  out.d = sys.d;
  out.period_s = period_s;
  return out;
}

RiccatiResult dlqr(const Mat& a, const Mat& b, const Mat& q, const Mat& r) {
  const Eigen::Index n = a.rows(), m = b.cols();
  if (a.cols() != n || b.rows() != n || q.rows() != n || q.cols() != n || r.rows() != m ||
      r.cols() != m) {
    throw std::invalid_argument("dlqr: dimension mismatch A " + dims(a) + " B " + dims(b) +
                                " Q " + dims(q) + " R " + dims(r));
  }
  Eigen::LLT<Mat> rllt(r);
  if (rllt.info() != Eigen::Success) throw std::invalid_argument("dlqr: R is not positive definite");
  // Structure-preserving doubling (Chu, Fan, Lin 2005): H_k -> P.
  Mat ak = a;
  Mat gk = b * rllt.solve(b.transpose());
  Mat hk = 0.5 * (q + q.transpose());
  const Mat eye = Mat::Identity(n, n);
  RiccatiResult res;
  bool converged = false;
  for (int it = 1; it <= 200; ++it) {
    const Mat w = eye + gk * hk;
    const Eigen::PartialPivLU<Mat> lu(w);
    const Mat wa = lu.solve(ak);          // W^-1 A
    const Mat wg = lu.solve(gk);          // W^-1 G
    const Mat a1 = ak * wa;
    Mat g1 = gk + ak * wg * ak.transpose();
    Mat h1 = hk + ak.transpose() * hk * wa;
    g1 = 0.5 * (g1 + g1.transpose()).eval();
    h1 = 0.5 * (h1 + h1.transpose()).eval();
    const double change = (h1 - hk).cwiseAbs().maxCoeff() / std::max(1.0, h1.cwiseAbs().maxCoeff());
    ak = a1;
    gk = g1;
    hk = h1;
    res.iterations = it;
    if (!hk.allFinite()) break;
    if (change < 1e-14) {
      converged = true;
      break;
    }
  }
  if (!converged) throw std::runtime_error("dlqr: Riccati doubling did not converge");
  const Mat& p = hk;
  const Mat s = r + b.transpose() * p * b;
  res.gain = s.ldlt().solve(b.transpose() * p * a);
  res.p = p;
  const Mat dare = a.transpose() * p * a - p -
                   a.transpose() * p * b * res.gain + q;
  res.residual = dare.cwiseAbs().maxCoeff() / std::max(1.0, p.cwiseAbs().maxCoeff());
  if (res.residual > 1e-8) {
    throw std::runtime_error("dlqr: Riccati residual " + std::to_string(res.residual) +
                             " too large");
  }
  if (max_pole_radius(a - b * res.gain) >= 1.0) {
    throw std::runtime_error("dlqr: closed loop not stable (is (A,B) stabilisable, (A,Q) detectable?)");
  }
  return res;
}

RiccatiResult dkalman(const Mat& a, const Mat& c, const Mat& w, const Mat& v) {
  // Dual LQR: K_dual = (V + C P C')^-1 C P A'. The predictor gain is L = A P C' (V + C P C')^-1
  // = K_dual'.
  RiccatiResult dual = dlqr(a.transpose(), c.transpose(), w, v);
  dual.gain = dual.gain.transpose().eval();
  return dual;
}

double max_pole_radius(const Mat& a) {
  if (a.rows() == 0) return 0.0;
  const Eigen::EigenSolver<Mat> es(a, false);
  return es.eigenvalues().cwiseAbs().maxCoeff();
}

CMat freq_response(const StateSpace& sys, double w_rad_s) {
  const Cplx s = eval_point(sys.period_s, w_rad_s);
  const Eigen::Index n = sys.states();
  const CMat m = s * CMat::Identity(n, n) - sys.a.cast<Cplx>();
  const CMat x = m.partialPivLu().solve(sys.b.cast<Cplx>());
  return sys.c.cast<Cplx>() * x + sys.d.cast<Cplx>();
}

Mat closed_loop_a(const StateSpace& g, const StateSpace& k) {
  g.check();
  k.check();
  if (g.inputs() != k.outputs() || g.outputs() != k.inputs()) {
    throw std::invalid_argument("closed_loop_a: plant/controller dimensions do not match");
  }
  const bool gd = g.d.cwiseAbs().maxCoeff() > 0.0;
  const bool kd = k.d.size() > 0 && k.d.cwiseAbs().maxCoeff() > 0.0;
  if (gd && kd) throw std::invalid_argument("closed_loop_a: algebraic loop (both D nonzero)");
  const Eigen::Index ng = g.states(), nk = k.states();
  Mat a = Mat::Zero(ng + nk, ng + nk);
  // u = Ck xk + Dk y,  y = Cg xg + Dg u
  if (!gd) {
    a.topLeftCorner(ng, ng) = g.a + g.b * k.d * g.c;
    a.topRightCorner(ng, nk) = g.b * k.c;
    a.bottomLeftCorner(nk, ng) = k.b * g.c;
    a.bottomRightCorner(nk, nk) = k.a;
  } else {
    a.topLeftCorner(ng, ng) = g.a;
    a.topRightCorner(ng, nk) = g.b * k.c;
    a.bottomLeftCorner(nk, ng) = k.b * g.c;
    a.bottomRightCorner(nk, nk) = k.a + k.b * g.d * k.c;
  }
  return a;
}

StateSpace series(const StateSpace& g1, const StateSpace& g2) {
  g1.check();
  g2.check();
  if (g1.outputs() != g2.inputs()) throw std::invalid_argument("series: dimension mismatch");
  const Eigen::Index n1 = g1.states(), n2 = g2.states();
  StateSpace s;
  s.period_s = g1.period_s;
  s.a = Mat::Zero(n1 + n2, n1 + n2);
  s.a.topLeftCorner(n1, n1) = g1.a;
  s.a.bottomLeftCorner(n2, n1) = g2.b * g1.c;
  s.a.bottomRightCorner(n2, n2) = g2.a;
  s.b = Mat::Zero(n1 + n2, g1.inputs());
  s.b.topRows(n1) = g1.b;
  s.b.bottomRows(n2) = g2.b * g1.d;
  s.c = Mat::Zero(g2.outputs(), n1 + n2);
  s.c.leftCols(n1) = g2.d * g1.c;
  s.c.rightCols(n2) = g2.c;
  s.d = g2.d * g1.d;
  return s;
}

std::vector<double> frequency_grid(double period_s, int points, double w_min,
                                   double w_max_continuous) {
  const double w_max = period_s > 0.0 ? 0.999 * std::numbers::pi / period_s : w_max_continuous;
  std::vector<double> g(static_cast<std::size_t>(std::max(points, 2)));
  const double l0 = std::log(w_min), l1 = std::log(w_max);
  for (std::size_t i = 0; i < g.size(); ++i) {
    g[i] = std::exp(l0 + (l1 - l0) * static_cast<double>(i) / static_cast<double>(g.size() - 1));
  }
  return g;
}

std::vector<LoopMargin> input_margins(const StateSpace& plant, const StateSpace& ctrl,
                                      int points) {
  const auto grid = frequency_grid(plant.period_s, points);
  std::vector<LoopMargin> out;
  for (Eigen::Index i = 0; i < plant.inputs(); ++i) {
    auto l = [&](double w) {
      const CMat lm = -(freq_response(ctrl, w) * freq_response(plant, w));
      return loop_at_a_time(lm, i);
    };
    out.push_back(margins_of(l, grid));
  }
  return out;
}

std::vector<LoopMargin> output_margins(const StateSpace& plant, const StateSpace& ctrl,
                                       int points) {
  const auto grid = frequency_grid(plant.period_s, points);
  std::vector<LoopMargin> out;
  for (Eigen::Index i = 0; i < plant.outputs(); ++i) {
    auto l = [&](double w) {
      const CMat lm = -(freq_response(plant, w) * freq_response(ctrl, w));
      return loop_at_a_time(lm, i);
    };
    out.push_back(margins_of(l, grid));
  }
  return out;
}

SensitivityPeaks sensitivity_peaks(const StateSpace& plant, const StateSpace& ctrl, int points) {
  SensitivityPeaks p;
  const auto grid = frequency_grid(plant.period_s, points);
  for (double w : grid) {
    const CMat g = freq_response(plant, w), k = freq_response(ctrl, w);
    const Eigen::Index m = g.cols(), n = g.rows();
    const CMat si = (CMat::Identity(m, m) - k * g).inverse();
    const CMat so = (CMat::Identity(n, n) - g * k).inverse();
    const CMat to = CMat::Identity(n, n) - so;
    // si, so and to are square: no QR preconditioner needed (and a third of the compile time).
    auto smax = [](const CMat& x) {
      return Eigen::JacobiSVD<CMat, Eigen::NoQRPreconditioner>(x).singularValues()(0);
    };
    p.input_s = std::max(p.input_s, smax(si));
    p.output_s = std::max(p.output_s, smax(so));
    p.output_t = std::max(p.output_t, smax(to));
  }
  return p;
}

}  // namespace contour::control::lti
