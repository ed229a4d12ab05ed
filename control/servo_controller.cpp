#include "control/servo_controller.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace contour::control {

void ServoController::validate(const ServoParams& p) {
  if (p.axes < 1 || p.axes > kMaxServoAxes) throw std::invalid_argument("servo: axes must be 1..3");
  if (!(p.period_s > 0.0)) throw std::invalid_argument("servo: period must be > 0");
  if (p.delay_cycles < 0 || p.delay_cycles > FeedDrive::kMaxDelay) {
    throw std::invalid_argument("servo: delay_cycles out of range");
  }
  for (int i = 0; i < p.axes; ++i) {
    const auto& a = p.axis[static_cast<std::size_t>(i)];
    if (a.kp < 0.0 || a.ki_per_s < 0.0 || a.kd_s < 0.0 || a.ff < 0.0 || a.ff > 1.0 ||
        !(a.u_max_mm > 0.0)) {
      throw std::invalid_argument("servo: axis gains must be >= 0, ff in [0,1], u_max > 0");
    }
    if (!(p.drive[static_cast<std::size_t>(i)].gain_per_s > 0.0)) {
      throw std::invalid_argument("servo: drive gain must be > 0");
    }
  }
  if (p.coupling.cp < 0.0 || p.coupling.ci_per_s < 0.0 || p.coupling.cd_s < 0.0) {
    throw std::invalid_argument("servo: coupling gains must be >= 0");
  }
  if (!(p.derivative.model_blend_s >= 0.0) || !(p.derivative.lowpass_s >= 0.0) ||
      !std::isfinite(p.derivative.model_blend_s) || !std::isfinite(p.derivative.lowpass_s)) {
    throw std::invalid_argument("servo: derivative filter time constants must be >= 0");
  }
}

namespace {
double pole_of(double tau_s, double period_s) {
  return tau_s > 0.0 ? std::exp(-period_s / tau_s) : 0.0;
}
}  // namespace

void ServoController::configure(const ServoParams& p) {
  validate(p);
  p_ = p;
  a_blend_ = pole_of(p_.derivative.model_blend_s, p_.period_s);
  a_lowpass_ = pole_of(p_.derivative.lowpass_s, p_.period_s);
  for (std::size_t i = 0; i < kMaxServoAxes; ++i) {
    FeedDriveParams m = p_.drive[i];
    m.period_s = p_.period_s;
    m.blu_mm = 0.0;
    m.delay_cycles = 0;
    model_nd_[i].configure(m);
    m.delay_cycles = p_.delay_compensation ? p_.delay_cycles : 0;
    model_d_[i].configure(m);
  }
  reset();
}

void ServoController::reset() noexcept {
  ia_.setZero();
  e_prev_.setZero();
  ic_.setZero();
  eps_prev_.setZero();
  resid_f_.setZero();
  resid_f1_.setZero();
  u_last_.setZero();
  applied_pending_ = false;
  d_axis_.setZero();
  d_coup_.setZero();
  first_ = true;
  for (std::size_t i = 0; i < kMaxServoAxes; ++i) {
    model_nd_[i].reset(0.0);
    model_d_[i].reset(0.0);
  }
}

void ServoController::check_live_compatible(const ServoParams& p) const {
  validate(p);
  if (p.axes != p_.axes) throw std::invalid_argument("servo: the number of axes cannot change live");
  if (p.period_s != p_.period_s) throw std::invalid_argument("servo: the period cannot change live");
  if (p.delay_cycles != p_.delay_cycles || p.delay_compensation != p_.delay_compensation) {
    throw std::invalid_argument("servo: delay compensation cannot change live");
  }
  for (std::size_t i = 0; i < kMaxServoAxes; ++i) {
    const FeedDriveParams& a = p.drive[i];
    const FeedDriveParams& b = p_.drive[i];
    if (a.gain_per_s != b.gain_per_s || a.tau_s != b.tau_s) {
      throw std::invalid_argument("servo: drive model (gain, tau) of axis " + std::to_string(i) +
                                  " cannot change live");
    }
  }
}

void ServoController::set_gains(const ServoParams& p) noexcept {
  const bool pid_old = p_.law == AxisLaw::kPid;
  const bool pid_new = p.law == AxisLaw::kPid;
  for (int i = 0; i < p_.axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    // Axis integrator: keep Ki * ia.
    const double ki_old = pid_old ? p_.axis[s].ki_per_s : 0.0;
    const double ki_new = pid_new ? p.axis[s].ki_per_s : 0.0;
    ia_[i] = (ki_old > 0.0 && ki_new > 0.0) ? ia_[i] * ki_old / ki_new : 0.0;
    // Coupling integrator: keep Ci * ic.
    const double ci_old = p_.coupling.enable ? p_.coupling.ci_per_s : 0.0;
    const double ci_new = p.coupling.enable ? p.coupling.ci_per_s : 0.0;
    ic_[i] = (ci_old > 0.0 && ci_new > 0.0) ? ic_[i] * ci_old / ci_new : 0.0;
  }
  // Everything structural stays (checked off-RT); only the gain fields are copied, so the Smith
  // predictor models keep their parameters and history.
  if (!pid_new) d_axis_.setZero();
  if (!p.coupling.enable) d_coup_.setZero();
  p_.law = p.law;
  p_.axis = p.axis;
  p_.coupling = p.coupling;
  // The blend filter state and the model run whatever the setting, so switching it is bumpless.
  p_.derivative = p.derivative;
  a_blend_ = pole_of(p_.derivative.model_blend_s, p_.period_s);
  a_lowpass_ = pole_of(p_.derivative.lowpass_s, p_.period_s);
}

Vec3 ServoController::predict(const Vec3& p_meas_mm) const noexcept {
  Vec3 out = p_meas_mm;
  if (!p_.delay_compensation || p_.delay_cycles == 0) return out;
  for (int i = 0; i < p_.axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    out[i] += model_nd_[s].position_mm() - model_d_[s].position_mm();
  }
  return out;
}

ServoStatus ServoController::update(const Vec3& r_mm, const Vec3& p_hat_mm,
                                    const ContourErrorResult& ce, const Vec3& v_ref_mm_s,
                                    Vec3& u_out) noexcept {
  const double t_s = p_.period_s;
  const Vec3 e = r_mm - p_hat_mm;
  Vec3 eps = ce.eps;
  if (!eps.allFinite()) eps.setZero();
  // Model-blend residual r = P_hat - m(k) (= P_meas(k) - m(k-d) with the predictor) through
  // F(z) = ((1-a)/(1-a z^-1))^2. Second order: the derivative of a first-order F's output still
  // carries (1-a)/(1+a) of each encoder count at the Nyquist frequency; through the daemon on
  // Table 2 the Z command chatter was 3.2 mm/s RMS with a first-order F at 5 ms, 1.1 with this.
  Vec3 m_pos;
  for (int i = 0; i < kMaxServoAxes; ++i) {
    m_pos[i] = model_nd_[static_cast<std::size_t>(i)].position_mm();
  }
  Vec3 resid = p_hat_mm - m_pos;
  if (!resid.allFinite()) resid.setZero();
  if (first_) {
    resid_f1_ = resid;
    resid_f_ = resid;
  } else {
    resid_f1_ = a_blend_ * resid_f1_ + (1.0 - a_blend_) * resid;
    resid_f_ = a_blend_ * resid_f_ + (1.0 - a_blend_) * resid_f1_;
  }
  // What the derivative terms act on: e and eps of P_tilde instead of P_hat.
  const Vec3 p_tilde = p_.derivative.model_blend_s > 0.0 ? Vec3(m_pos + resid_f_) : p_hat_mm;
  const Vec3 e_d = r_mm - p_tilde;
  // eps of P_tilde, as eps plus the difference on the model's geometry (robust to a result whose
  // geometry fields are not filled in, e.g. hand-made in tests: then eps_d = eps - shift).
  Vec3 eps_d = eps;
  Vec3 eps_tilde;  // eps_on(ce, p_tilde), computed at most once per cycle
  bool have_eps_tilde = false;
  if (p_.derivative.model_blend_s > 0.0) {
    eps_tilde = eps_on(ce, p_tilde);
    have_eps_tilde = true;
    eps_d += eps_tilde - eps_on(ce, p_hat_mm);
    if (!eps_d.allFinite()) eps_d = eps;
  }
  if (first_) {
    e_prev_ = e_d;
    eps_prev_ = eps_d;
    p_tilde_prev_ = p_tilde;
    first_ = false;
  }
  // Same geometry: the previous position's error on this cycle's circle/line, so that a new
  // window (a new circle) is not differentiated as tool motion. kAhead: only while the window is
  // on the newest points (lag <= 1: the tool at or ahead of the reference, the model
  // extrapolating); elsewhere the paper's eps(k) - eps(k-1).
  Vec3 eps_d_prev = eps_prev_;
  const SameGeometry sg = p_.derivative.same_geometry;
  if (sg == SameGeometry::kAlways || (sg == SameGeometry::kAhead && ce.lag_points <= 1)) {
    if (!have_eps_tilde) eps_tilde = eps_on(ce, p_tilde);
    eps_d_prev = eps_d + eps_on(ce, p_tilde_prev_) - eps_tilde;
    if (!eps_d_prev.allFinite()) eps_d_prev = eps_prev_;
  }
  p_tilde_prev_ = p_tilde;
  const Vec3 ia_old = ia_;
  const Vec3 ic_old = ic_;
  const bool pid = p_.law == AxisLaw::kPid;
  if (pid) ia_ += t_s * e;
  const bool couple = p_.coupling.enable;
  if (couple) {
    ic_ += t_s * eps;
    if (p_.coupling.remove_tangential_integral && ce.tangent.squaredNorm() > 0.5) {
      ic_ -= ce.tangent * ce.tangent.dot(ic_);
    }
  }
  ServoStatus status = ServoStatus::kOk;
  u_out.setZero();
  terms_ = ServoTerms{};
  for (int i = 0; i < p_.axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    const AxisGains& g = p_.axis[s];
    terms_.axis_p[i] = g.kp * e[i];
    if (pid) {
      terms_.axis_i[i] = g.ki_per_s * ia_[i];
      const double raw = g.kd_s * (e_d[i] - e_prev_[i]) / t_s;
      d_axis_[i] = a_lowpass_ * d_axis_[i] + (1.0 - a_lowpass_) * raw;
      terms_.axis_d[i] = d_axis_[i];
    }
    if (g.ff > 0.0) terms_.ff[i] = g.ff * v_ref_mm_s[i] / p_.drive[s].gain_per_s;
    if (couple) {
      const CouplingGains& c = p_.coupling;
      const double raw = c.cd_s * (eps_d[i] - eps_d_prev[i]) / t_s;
      d_coup_[i] = a_lowpass_ * d_coup_[i] + (1.0 - a_lowpass_) * raw;
      terms_.coupling_p[i] = c.cp * eps[i];
      terms_.coupling_i[i] = c.ci_per_s * ic_[i];
      terms_.coupling_d[i] = d_coup_[i];
    }
    double u = terms_.axis_p[i] + terms_.axis_i[i] + terms_.axis_d[i] + terms_.ff[i] +
               terms_.coupling_p[i] + terms_.coupling_i[i] + terms_.coupling_d[i];
    if (!std::isfinite(u)) u = 0.0;
    if (std::abs(u) > g.u_max_mm) {
      status = ServoStatus::kSaturated;
      const double sign = u > 0.0 ? 1.0 : -1.0;
      // Conditional integration: undo this cycle's integration on this axis when it pushed the
      // command further into the limit.
      const double d_int =
          (pid ? g.ki_per_s * (ia_[i] - ia_old[i]) : 0.0) +
          (couple ? p_.coupling.ci_per_s * (ic_[i] - ic_old[i]) : 0.0);
      if (d_int * sign > 0.0) {
        ia_[i] = ia_old[i];
        if (couple) ic_[i] = ic_old[i];
      }
      u = sign * g.u_max_mm;
    }
    u_out[i] = u;
  }
  e_prev_ = e_d;
  eps_prev_ = eps_d;
  const bool predictor = p_.delay_compensation && p_.delay_cycles > 0;
  for (int i = 0; i < p_.axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    model_nd_[s].step(u_out[i]);
    if (predictor) model_d_[s].step(u_out[i]);
  }
  u_last_ = u_out;
  applied_pending_ = true;
  return status;
}

void ServoController::command_applied(const Vec3& u_applied_mm) noexcept {
  // Only the command of the update() just made can be corrected (not twice, not after reset()).
  if (!applied_pending_) return;
  applied_pending_ = false;
  const bool predictor = p_.delay_compensation && p_.delay_cycles > 0;
  for (int i = 0; i < p_.axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    const double du = u_applied_mm[i] - u_last_[i];
    if (du == 0.0 || !std::isfinite(du)) continue;
    model_nd_[s].correct_last_command(du);
    if (predictor) model_d_[s].correct_last_command(du);
    u_last_[i] = u_applied_mm[i];
  }
}

namespace {

// The scalar normal-direction loop as a linear state map. State layout:
// [x, v, ubuf(d), I, e_prev, v_model, inc(d)].
struct ScalarLoop {
  double a, b_v, c_x, d_x;        // true plant
  double am, bm, cm, dm;          // nominal model (Smith predictor)
  double kp, ci, cd, t_s;
  int d;
  bool smith;
  [[nodiscard]] int size() const { return 2 + d + 2 + 1 + d; }
  void step(const Eigen::VectorXd& s, Eigen::VectorXd& out) const {
    const double x = s[0], v = s[1];
    const int ib = 2, ii = 2 + d, ie = 3 + d, ivm = 4 + d, iinc = 5 + d;
    double delta = 0.0;
    if (smith) {
      for (int j = 0; j < d; ++j) delta += s[iinc + j];
    }
    const double e = -(x + delta);
    const double integ = s[ii] + t_s * e;
    const double u = kp * e + ci * integ + cd * (e - s[ie]) / t_s;
    const double applied = d > 0 ? s[ib] : u;
    out.setZero(s.size());
    out[0] = x + c_x * v + d_x * applied;
    out[1] = a * v + b_v * applied;
    for (int j = 0; j + 1 < d; ++j) out[ib + j] = s[ib + j + 1];
    if (d > 0) out[ib + d - 1] = u;
    out[ii] = integ;
    out[ie] = e;
    out[ivm] = am * s[ivm] + bm * u;
    for (int j = 0; j + 1 < d; ++j) out[iinc + j] = s[iinc + j + 1];
    if (d > 0) out[iinc + d - 1] = cm * s[ivm] + dm * u;
  }
  [[nodiscard]] double radius() const {
    const int n = size();
    Eigen::MatrixXd m(n, n);
    Eigen::VectorXd s(n), o(n);
    for (int j = 0; j < n; ++j) {
      s.setZero();
      s[j] = 1.0;
      step(s, o);
      m.col(j) = o;
    }
    Eigen::EigenSolver<Eigen::MatrixXd> es(m, false);
    return es.eigenvalues().cwiseAbs().maxCoeff();
  }
};

void discretise(const FeedDriveParams& p, double gain, double& a, double& b, double& c,
                double& d) {
  const double tau = p.tau_s > 1e-12 ? p.tau_s : 1e-12;
  a = std::exp(-p.period_s / tau);
  b = (1.0 - a) * gain;
  c = tau * (1.0 - a);
  d = gain * (p.period_s - tau * (1.0 - a));
}

}  // namespace

LoopMargin loop_margin(const FeedDriveParams& drive, const AxisGains& axis,
                       const CouplingGains& coupling, int delay_cycles, bool smith_predictor,
                       double plant_gain_scale) {
  ScalarLoop l{};
  discretise(drive, drive.gain_per_s * plant_gain_scale, l.a, l.b_v, l.c_x, l.d_x);
  discretise(drive, drive.gain_per_s, l.am, l.bm, l.cm, l.dm);
  const double c_on = coupling.enable ? 1.0 : 0.0;
  l.kp = axis.kp + c_on * coupling.cp;
  l.ci = axis.ki_per_s + c_on * coupling.ci_per_s;
  l.cd = axis.kd_s + c_on * coupling.cd_s;
  l.t_s = drive.period_s;
  l.d = delay_cycles < 0 ? 0 : delay_cycles;
  l.smith = smith_predictor;
  LoopMargin m;
  m.spectral_radius = l.radius();
  // Bisection on a common factor g on all controller gains.
  const ScalarLoop base = l;
  auto stable_at = [&](double g) {
    ScalarLoop s = base;
    s.kp *= g;
    s.ci *= g;
    s.cd *= g;
    return s.radius() < 1.0;
  };
  if (!stable_at(1.0)) {
    double lo = 0.0, hi = 1.0;
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      (stable_at(mid) ? lo : hi) = mid;
    }
    m.gain_margin = lo;
    return m;
  }
  double lo = 1.0, hi = 2.0;
  while (stable_at(hi) && hi < 1e4) {
    lo = hi;
    hi *= 2.0;
  }
  for (int it = 0; it < 40; ++it) {
    const double mid = 0.5 * (lo + hi);
    (stable_at(mid) ? lo : hi) = mid;
  }
  m.gain_margin = lo;
  return m;
}

}  // namespace contour::control
