#include "control/force_2dof.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace contour::control {

namespace {
using lti::Mat;

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("force 2-DOF design: " + what);
}

void check_params(const ForceDesignParams& p) {
  const auto& pl = p.plant;
  require(std::isfinite(pl.k_f_N) && pl.k_f_N != 0.0, "K_f must be finite and non-zero");
  require(std::isfinite(pl.k_s_N) && pl.k_s_N != 0.0, "K_s must be finite and non-zero");
  require(std::isfinite(pl.k_v_mm_s) && pl.k_v_mm_s > 0.0, "K_v must be > 0");
  require(pl.tau_f_s > 0.0 && pl.tau_s_s > 0.0, "tau_f and tau_s must be > 0");
  require(p.period_s > 0.0 && p.period_s < 0.1, "period must be in (0, 0.1) s");
  require(p.tau_m_s > 0.0, "tau_m must be > 0");
  // Eq 3.6: the reference model must be faster than the process (else the feed-forward asks
  // for less than the plant can do and the 2-DOF structure degenerates to 1-DOF).
  require(p.tau_m_s < pl.tau_f_s && p.tau_m_s < pl.tau_s_s,
          "tau_m must be smaller than tau_f and tau_s (eq 3.6)");
  const auto& w = p.weights;
  for (double v : {w.q_force, w.q_position, w.q_force_integral, w.q_position_integral, w.r_feed,
                   w.r_spindle, w.observer_input_noise, w.observer_measurement_noise}) {
    require(std::isfinite(v) && v > 0.0, "weights and noise intensities must be > 0");
  }
  require(std::isfinite(w.observer_state_noise) && w.observer_state_noise >= 0.0,
          "observer_state_noise must be >= 0");
}

// Reference model G_M = diag(G_M1, G_M2) in continuous time, states [force (2); position (2)].
lti::StateSpace reference_model(double tau, PositionModel pm) {
  lti::StateSpace g;
  g.a = Mat::Zero(4, 4);
  g.b = Mat::Zero(4, 2);
  g.c = Mat::Zero(2, 4);
  g.d = Mat::Zero(2, 2);
  for (int ch = 0; ch < 2; ++ch) {
    const int i = 2 * ch;
    g.a(i, i) = -1.0 / tau;
    g.a(i + 1, i + 1) = -1.0 / tau;
    g.a(i + 1, i) = 1.0 / tau;
    g.b(i, ch) = 1.0 / tau;
  }
  g.c(0, 1) = 1.0;
  if (pm == PositionModel::kPaper) {
    g.c(1, 3) = 1.0;  // 1/(tau s + 1)^2
  } else {
    // (2 tau s + 1)/(tau s + 1)^2 = 2/(tau s + 1) - 1/(tau s + 1)^2
    g.c(1, 2) = 2.0;
    g.c(1, 3) = -1.0;
  }
  return g;
}

std::string fmt(double v, int prec = 3, bool sci = false) {
  std::ostringstream os;
  if (sci) {
    os.setf(std::ios::scientific);
  } else {
    os.setf(std::ios::fixed);
  }
  os.precision(prec);
  os << v;
  return os.str();
}
}  // namespace

lti::StateSpace force_plant_model(const ForcePlantParams& p) {
  const double sigma = p.spindle_pole == SpindlePole::kPrinted ? -1.0 : 1.0;
  lti::StateSpace g;
  g.a = Mat::Zero(3, 3);
  g.b = Mat::Zero(3, 2);
  g.c = Mat::Zero(2, 3);
  g.d = Mat::Zero(2, 2);
  g.a(0, 0) = -1.0 / p.tau_f_s;
  g.a(1, 1) = -1.0 / (sigma * p.tau_s_s);
  g.b(0, 0) = p.k_f_N / p.tau_f_s;
  g.b(1, 1) = p.k_s_N / (sigma * p.tau_s_s);
  g.b(2, 0) = p.k_v_mm_s;
  g.c(0, 0) = 1.0;
  g.c(0, 1) = 1.0;
  g.c(1, 2) = 1.0;
  return g;
}

ForceDesign design_force_2dof(const ForceDesignParams& params) {
  check_params(params);
  ForceDesign d;
  d.params = params;
  const double t = params.period_s;
  d.period_s = t;
  const lti::StateSpace pd = lti::c2d_zoh(force_plant_model(params.plant), t);
  d.plant_a = pd.a;
  d.plant_b = pd.b;
  d.plant_c = pd.c;

  // ---- Feed-forward filter: exact discrete model matching P_d u_ff = G_M,d r. ----
  const lti::StateSpace gm = lti::c2d_zoh(reference_model(params.tau_m_s, params.position_model), t);
  const Mat cb = pd.c * pd.b;  // relative degree one in both outputs
  require(std::abs(cb.determinant()) > 1e-300, "C B is singular (K_s or K_v zero?)");
  const Mat g_inv = cb.inverse();
  // E maps w = [q (4); x_f] to the model plant state [x_f; x_s = y_M1 - x_f; p = y_M2].
  Mat e = Mat::Zero(3, 5);
  e(0, 4) = 1.0;
  e.block(1, 0, 1, 4) = gm.c.row(0);
  e(1, 4) = -1.0;
  e.block(2, 0, 1, 4) = gm.c.row(1);
  Mat phi = Mat::Zero(2, 5);
  phi.leftCols(4) = gm.c * gm.a;
  const Mat cu = g_inv * (phi - pd.c * pd.a * e);
  const Mat du = g_inv * gm.c * gm.b;
  Mat fa = Mat::Zero(5, 5);
  fa.topLeftCorner(4, 4) = gm.a;
  fa.row(4) = (pd.a * e + pd.b * cu).row(0);
  Mat fb = Mat::Zero(5, 2);
  fb.topRows(4) = gm.b;
  fb.row(4) = (pd.b * du).row(0);
  d.ff_a = fa;
  d.ff_b = fb;
  d.ff_cu = cu;
  d.ff_du = du;
  d.ff_cy.setZero();
  d.ff_cy.leftCols(4) = gm.c;
  if (lti::max_pole_radius(fa) >= 1.0) {
    throw std::runtime_error("force 2-DOF design: feed-forward filter is not stable");
  }

  // ---- Feedback C2: observer-based controller of the integrator-augmented plant. ----
  const double fs = std::abs(params.plant.k_f_N);
  const double ps = params.plant.k_v_mm_s;
  Mat sy = Mat::Zero(2, 2);
  sy(0, 0) = 1.0 / fs;
  sy(1, 1) = 1.0 / ps;
  Mat an = Mat::Zero(5, 5), bn = Mat::Zero(5, 2), cn = Mat::Zero(2, 5);
  an.topLeftCorner(3, 3) = pd.a;
  an.bottomLeftCorner(2, 3) = t * sy * pd.c;
  an.bottomRightCorner(2, 2) = Mat::Identity(2, 2);
  bn.topRows(3) = pd.b;
  cn.leftCols(3) = t * sy * pd.c;
  cn.rightCols(2) = Mat::Identity(2, 2);
  const auto& w = params.weights;
  Mat wy = Mat::Zero(2, 2);
  wy(0, 0) = w.q_force;
  wy(1, 1) = w.q_position;
  Mat q = Mat::Zero(5, 5);
  q.topLeftCorner(3, 3) = (sy * pd.c).transpose() * wy * (sy * pd.c);
  q(3, 3) = w.q_force_integral;
  q(4, 4) = w.q_position_integral;
  // Scale state weights by T so the discrete cost approximates the continuous integral and the
  // weights keep their meaning when the loop period changes.
  q *= t;
  q.topLeftCorner(3, 3) += 1e-12 * Mat::Identity(3, 3);
  Mat r = Mat::Zero(2, 2);
  r(0, 0) = w.r_feed * t;
  r(1, 1) = w.r_spindle * t;
  const lti::RiccatiResult lqr = lti::dlqr(an, bn, q, r);
  const Mat fn = -lqr.gain;
  Mat wn = w.observer_input_noise * t * bn * bn.transpose();
  wn += w.observer_state_noise * t * Mat::Identity(5, 5);
  const Mat vn = w.observer_measurement_noise * Mat::Identity(2, 2);
  const lti::RiccatiResult kal = lti::dkalman(an, cn, wn, vn);
  const Mat hn = -kal.gain;
  // Back to physical coordinates: x_a,n = Ts x_a, Ts = diag(I3, S_y); m_n = S_y m.
  Mat ts = Mat::Identity(5, 5);
  ts.bottomRightCorner(2, 2) = sy;
  const Mat ts_inv = ts.inverse();
  d.aug_a = ts_inv * an * ts;
  d.aug_b = ts_inv * bn;
  d.aug_c = sy.inverse() * cn * ts;
  d.f = fn * ts;
  d.h = ts_inv * hn * sy;
  d.quality = analyse_force_design(d, pd);
  d.quality.bezout_residual = bezout_residual(d);
  if (!(d.quality.max_pole_radius < 1.0)) {
    throw std::runtime_error("force 2-DOF design: closed loop not stable (max pole radius " +
                             fmt(d.quality.max_pole_radius, 6) + ")");
  }
  return d;
}

lti::StateSpace force_feedback_controller(const ForceDesign& d) {
  const double t = d.period_s;
  lti::StateSpace k;
  k.period_s = t;
  k.a = Mat::Zero(7, 7);
  k.b = Mat::Zero(7, 2);
  k.c = Mat::Zero(2, 7);
  k.d = Mat::Zero(2, 2);
  // zeta+ = zeta + T y ;  x^+ = (A_a + B_a F + H C_a) x^ - H (zeta + T y) ;  u = F x^
  k.a.topLeftCorner(2, 2) = Mat::Identity(2, 2);
  k.a.bottomLeftCorner(5, 2) = -d.h;
  k.a.bottomRightCorner(5, 5) = d.aug_a + d.aug_b * d.f + d.h * d.aug_c;
  k.b.topRows(2) = t * Mat::Identity(2, 2);
  k.b.bottomRows(5) = -t * d.h;
  k.c.rightCols(5) = d.f;
  return k;
}

lti::StateSpace force_feedforward_filter(const ForceDesign& d) {
  lti::StateSpace f;
  f.period_s = d.period_s;
  f.a = d.ff_a;
  f.b = d.ff_b;
  f.c = Mat::Zero(4, 5);
  f.c.topRows(2) = d.ff_cu;
  f.c.bottomRows(2) = d.ff_cy;
  f.d = Mat::Zero(4, 2);
  f.d.topRows(2) = d.ff_du;
  return f;
}

ForceDesignQuality analyse_force_design(const ForceDesign& d, const lti::StateSpace& plant_d) {
  ForceDesignQuality qy;
  const lti::StateSpace k = force_feedback_controller(d);
  qy.max_pole_radius = lti::max_pole_radius(lti::closed_loop_a(plant_d, k));
  const auto im = lti::input_margins(plant_d, k);
  const auto om = lti::output_margins(plant_d, k);
  qy.delay_margin_s = 1e9;
  for (std::size_t i = 0; i < 2; ++i) {
    qy.input_phase_margin_deg[i] = im[i].phase_margin_deg;
    qy.input_delay_margin_s[i] = im[i].delay_margin_s;
    qy.input_crossover_rad_s[i] = im[i].crossover_rad_s;
    qy.output_phase_margin_deg[i] = om[i].phase_margin_deg;
    qy.output_delay_margin_s[i] = om[i].delay_margin_s;
    qy.delay_margin_s = std::min(qy.delay_margin_s, im[i].delay_margin_s);
  }
  const auto sp = lti::sensitivity_peaks(plant_d, k);
  qy.peak_input_sensitivity = sp.input_s;
  qy.peak_output_sensitivity = sp.output_s;
  qy.peak_output_complementary = sp.output_t;
  qy.bezout_residual = d.quality.bezout_residual;
  return qy;
}

CoprimeFactors force_coprime_factors(const ForceDesign& d) {
  CoprimeFactors cf;
  const Mat a = d.aug_a, b = d.aug_b, c = d.aug_c, f = d.f, h = d.h;
  const double t = d.period_s;
  // Right: [[M, U], [N, V]] = [A+BF | B, -H ; F | I, 0 ; C | 0, I]
  cf.right.period_s = t;
  cf.right.a = a + b * f;
  cf.right.b = Mat::Zero(5, 4);
  cf.right.b.leftCols(2) = b;
  cf.right.b.rightCols(2) = -h;
  cf.right.c = Mat::Zero(4, 5);
  cf.right.c.topRows(2) = f;
  cf.right.c.bottomRows(2) = c;
  cf.right.d = Mat::Identity(4, 4);
  // Left: [[V~, -U~], [-N~, M~]] = [A+HC | -B, H ; F | I, 0 ; C | 0, I]
  cf.left.period_s = t;
  cf.left.a = a + h * c;
  cf.left.b = Mat::Zero(5, 4);
  cf.left.b.leftCols(2) = -b;
  cf.left.b.rightCols(2) = h;
  cf.left.c = cf.right.c;
  cf.left.d = Mat::Identity(4, 4);
  cf.plant_aug.period_s = t;
  cf.plant_aug.a = a;
  cf.plant_aug.b = b;
  cf.plant_aug.c = c;
  cf.plant_aug.d = Mat::Zero(2, 2);
  cf.ctrl_aug.period_s = t;
  cf.ctrl_aug.a = a + b * f + h * c;
  cf.ctrl_aug.b = -h;
  cf.ctrl_aug.c = f;
  cf.ctrl_aug.d = Mat::Zero(2, 2);
  return cf;
}

double bezout_residual(const ForceDesign& d, int points) {
  const CoprimeFactors cf = force_coprime_factors(d);
  const auto grid = lti::frequency_grid(d.period_s, points);
  double worst = 0.0;
  for (double w : grid) {
    const lti::CMat prod = lti::freq_response(cf.left, w) * lti::freq_response(cf.right, w);
    worst = std::max(worst, (prod - lti::CMat::Identity(4, 4)).cwiseAbs().maxCoeff());
  }
  return worst;
}

std::string describe_quality(const ForceDesignQuality& q) {
  return "closed-loop max pole radius " + fmt(q.max_pole_radius, 6) +
         "; input phase margins " + fmt(q.input_phase_margin_deg[0], 1) + "/" +
         fmt(q.input_phase_margin_deg[1], 1) + " deg (feed/spindle), output phase margins " +
         fmt(q.output_phase_margin_deg[0], 1) + "/" + fmt(q.output_phase_margin_deg[1], 1) +
         " deg (force/position); delay margin " + fmt(q.delay_margin_s * 1e3, 1) +
         " ms; peak |S_i| " + fmt(q.peak_input_sensitivity, 3) + ", |S_o| " +
         fmt(q.peak_output_sensitivity, 3) + ", |T_o| " + fmt(q.peak_output_complementary, 3) +
         "; Bezout residual " + fmt(q.bezout_residual, 2, true);
}

void ForcePlantSim::configure(const ForcePlantParams& p, double period_s) {
  if (!(period_s > 0.0)) throw std::invalid_argument("ForcePlantSim: period must be > 0");
  if (!(p.tau_f_s > 0.0 && p.tau_s_s > 0.0)) {
    throw std::invalid_argument("ForcePlantSim: time constants must be > 0");
  }
  p_ = p;
  const lti::StateSpace pd = lti::c2d_zoh(force_plant_model(p), period_s);
  a_ = pd.a;
  b_ = pd.b;
  x_.setZero();
}

void ForcePlantSim::reset(double u1, double u2, double progress_mm) noexcept {
  x_(0) = p_.k_f_N * u1;
  x_(1) = p_.k_s_N * u2;
  x_(2) = progress_mm;
}

void ForcePlantSim::step(double u1, double u2) noexcept {
  const Eigen::Vector2d u(u1, u2);
  x_ = (a_ * x_ + b_ * u).eval();
}

}  // namespace contour::control
