#include "control/force_controller.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace contour::control {

const char* to_string(ForceStatus s) noexcept {
  switch (s) {
    case ForceStatus::kNotConfigured: return "not_configured";
    case ForceStatus::kDisabled: return "disabled";
    case ForceStatus::kActive: return "active";
    case ForceStatus::kSaturated: return "saturated";
    case ForceStatus::kCeilingHold: return "ceiling_hold";
    case ForceStatus::kStaleHold: return "stale_hold";
    case ForceStatus::kStaleProgrammed: return "stale_programmed_feed";
  }
  return "unknown";
}

void ForceController::configure(const ForceDesign& d, const ForceLimits& l) {
  auto req = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("force controller limits: ") + what);
  };
  req(l.override_min >= 0.0 && l.override_max > l.override_min, "need 0 <= override_min < override_max");
  req(l.override_rate_per_s > 0.0, "override rate must be > 0");
  req(l.spindle_min_rpm >= 0.0 && l.spindle_max_rpm > l.spindle_min_rpm,
      "need 0 <= spindle_min_rpm < spindle_max_rpm");
  req(l.spindle_nominal_rpm >= l.spindle_min_rpm && l.spindle_nominal_rpm <= l.spindle_max_rpm,
      "spindle nominal speed outside [min, max]");
  req(l.spindle_rpm_per_unit > 0.0, "spindle_rpm_per_unit must be > 0");
  req(l.spindle_rate_rpm_s > 0.0, "spindle rate must be > 0");
  req(l.force_ceiling_N > 0.0, "force ceiling must be > 0");
  req(l.stale_age_s > 0.0, "stale age must be > 0");
  req(l.bumpless_tau_s > 0.0, "bumpless time constant must be > 0");
  req(d.period_s > 0.0, "design has no period");
  const Eigen::Matrix2d fz = d.f.rightCols<2>();
  req(std::abs(fz.determinant()) > 1e-12 * (1.0 + fz.cwiseAbs().maxCoeff()),
      "design's integrator gain F_z is singular (anti-windup impossible)");
  lim_ = l;
  t_ = d.period_s;
  bias_decay_ = std::exp(-t_ / l.bumpless_tau_s);
  tau_m_s_ = d.params.tau_m_s;
  position_model_ = d.params.position_model;
  k_f_N_ = d.params.plant.k_f_N;
  k_v_mm_s_ = d.params.plant.k_v_mm_s;
  ff_a_ = d.ff_a;
  ff_b_ = d.ff_b;
  ff_cu_ = d.ff_cu;
  ff_du_ = d.ff_du;
  ff_cy_ = d.ff_cy;
  aug_a_ = d.aug_a;
  aug_b_ = d.aug_b;
  aug_c_ = d.aug_c;
  f_ = d.f;
  h_ = d.h;
  fz_inv_ = fz.inverse();
  configured_ = true;
  active_ = false;
  latch_ = Latch::kNone;
  override_ = 1.0;
  rpm_ = l.spindle_nominal_rpm;
}

void ForceController::enable(const ForceEnableState& s) noexcept {
  if (!configured_) return;
  latch_ = Latch::kNone;
  active_ = true;
  need_bias_ = true;
  override_ = s.feed_override;
  rpm_ = s.spindle_rpm;
  // Reference model at rest at the measured force; position model on the current ramp (state of
  // the cascade 1/(tau s+1), 1/(tau s+1) driven by a ramp of slope v: q1 = r - tau v,
  // q2 = r - 2 tau v), placed so that the model output equals the measured progress.
  const double v = k_v_mm_s_ * s.feed_override;
  const double tau = tau_m_s_;
  const double r_eff = position_model_ == PositionModel::kPaper ? s.progress_mm + 2.0 * tau * v
                                                                 : s.progress_mm;
  w_ << s.force_N, s.force_N, r_eff - tau * v, r_eff - 2.0 * tau * v, k_f_N_ * s.feed_override;
  xh_.setZero();
  zeta_.setZero();
  bias_.setZero();
  y_model_ = ff_cy_ * w_;
}

void ForceController::disable() noexcept {
  active_ = false;
  if (latch_ == Latch::kStaleProgrammed) latch_ = Latch::kNone;
}

void ForceController::apply_limits(double want_override, double want_rpm, double& got_override,
                                   double& got_rpm) const noexcept {
  const double dov = lim_.override_rate_per_s * t_;
  const double drpm = lim_.spindle_rate_rpm_s * t_;
  double o = std::clamp(want_override, override_ - dov, override_ + dov);
  got_override = std::clamp(o, lim_.override_min, lim_.override_max);
  double n = std::clamp(want_rpm, rpm_ - drpm, rpm_ + drpm);
  got_rpm = std::clamp(n, lim_.spindle_min_rpm, lim_.spindle_max_rpm);
}

ForceOutput ForceController::passive_step() noexcept {
  ForceOutput out;
  switch (latch_) {
    case Latch::kCeiling:
    case Latch::kStaleHold:
      // Feed hold: the interpolator decelerates the path on its own ramp; the spindle keeps
      // turning at the last command (stopping it in the cut would break the tool).
      override_ = 0.0;
      out.feed_override = 0.0;
      out.spindle_rpm = rpm_;
      out.feed_hold_request = true;
      out.status = latch_ == Latch::kCeiling ? ForceStatus::kCeilingHold : ForceStatus::kStaleHold;
      return out;
    case Latch::kStaleProgrammed:
    case Latch::kNone:
      break;
  }
  double o = 0.0, n = 0.0;
  apply_limits(1.0, lim_.spindle_nominal_rpm, o, n);
  override_ = o;
  rpm_ = n;
  out.feed_override = o;
  out.spindle_rpm = n;
  out.status = latch_ == Latch::kStaleProgrammed ? ForceStatus::kStaleProgrammed
                                                 : ForceStatus::kDisabled;
  return out;
}

ForceOutput ForceController::step(const ForceInput& in) noexcept {
  if (!configured_) return ForceOutput{};
  const bool fresh = in.force_valid && std::isfinite(in.force_N) && in.force_age_s <= lim_.stale_age_s;
  if (fresh && in.force_N >= lim_.force_ceiling_N) {
    latch_ = Latch::kCeiling;
    active_ = false;
  }
  if (active_ && !fresh) {
    latch_ = lim_.fallback == ForceFallback::kHold ? Latch::kStaleHold : Latch::kStaleProgrammed;
    active_ = false;
  }
  if (!active_ || !std::isfinite(in.progress_mm) || !std::isfinite(in.force_ref_N) ||
      !std::isfinite(in.planned_progress_mm)) {
    if (active_) {  // non-finite progress/reference: a programming error upstream; fail safe
      latch_ = Latch::kStaleHold;
      active_ = false;
    }
    return passive_step();
  }

  const Eigen::Vector2d r(in.force_ref_N, in.planned_progress_mm);
  const Eigen::Vector2d y(in.force_N, in.progress_mm);
  const Eigen::Vector2d u_ff = ff_cu_ * w_ + ff_du_ * r;
  y_model_ = ff_cy_ * w_;
  const Eigen::Vector2d u_fb = f_ * xh_;
  const Eigen::Vector2d u_lin = u_ff + u_fb;
  if (need_bias_) {
    // Bumpless: whatever the linear law asks for differs from what is applied now; start from
    // the applied values and let the difference decay.
    bias_(0) = override_ - u_lin(0);
    bias_(1) = (rpm_ - lim_.spindle_nominal_rpm) / lim_.spindle_rpm_per_unit - u_lin(1);
    need_bias_ = false;
  } else {
    bias_ *= bias_decay_;
  }
  const Eigen::Vector2d u_want = u_lin + bias_;
  double o = 0.0, n = 0.0;
  apply_limits(u_want(0), lim_.spindle_nominal_rpm + u_want(1) * lim_.spindle_rpm_per_unit, o, n);
  const Eigen::Vector2d u_app(o, (n - lim_.spindle_nominal_rpm) / lim_.spindle_rpm_per_unit);
  const Eigen::Vector2d du = u_app - u_want;
  const bool saturated = du.cwiseAbs().maxCoeff() > 1e-12;

  // Observer and integrator, driven by what was applied (observer-form anti-windup).
  const Eigen::Vector2d m = zeta_ + t_ * (y - y_model_);
  const Eigen::Vector2d u_fb_app = u_app - u_ff - bias_;
  xh_ = (aug_a_ * xh_ + aug_b_ * u_fb_app + h_ * (aug_c_ * xh_ - m)).eval();
  zeta_ = m;
  if (saturated && lim_.anti_windup) {
    // Move the integrators (and their estimates, so the observer error is untouched) so that the
    // next feedback command differs by exactly the amount the actuator could not give.
    const Eigen::Vector2d dz = fz_inv_ * du;
    zeta_ += dz;
    xh_.tail<2>() += dz;
  }
  w_ = (ff_a_ * w_ + ff_b_ * r).eval();
  override_ = o;
  rpm_ = n;
  ForceOutput out;
  out.feed_override = o;
  out.spindle_rpm = n;
  out.status = saturated ? ForceStatus::kSaturated : ForceStatus::kActive;
  return out;
}

}  // namespace contour::control

namespace contour::control {

namespace {
// Fig 4.1-like desired force profile for kTrack/kNoise: up, higher, lower.
double force_reference(const ForceScenario& sc, double t) {
  if (sc.kind == ForceScenarioKind::kTrack || sc.kind == ForceScenarioKind::kNoise ||
      sc.kind == ForceScenarioKind::kModelError) {
    if (t >= 7.0) return 0.8 * sc.force_ref_N;
    if (t >= 3.5) return 1.5 * sc.force_ref_N;
  }
  return sc.force_ref_N;
}

// Small deterministic Gaussian source (xorshift + Box-Muller): no <random> state to size.
struct Noise {
  std::uint64_t s;
  double uniform() {
    s ^= s << 13;
    s ^= s >> 7;
    s ^= s << 17;
    return (static_cast<double>(s >> 11) + 0.5) / 9007199254740992.0;
  }
  double gauss() {
    const double u1 = uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
};
// See ForceMetrics::disturbance_recovery_bound_s. Starts from the steady state at the reference
// with the applied inputs (u1, n) and drives both inputs towards less (d > 0) or more force.
double recovery_bound_s(const ForcePlantParams& p, const ForceLimits& l, double period_s,
                        double u1, double n_rpm, double xf, double xs, double d, double ref) {
  const double band = 0.02 * std::abs(ref);
  const double err0 = xf + xs + d - ref;
  if (std::abs(err0) <= band) return 0.0;
  const double sgn = err0 > 0.0 ? -1.0 : 1.0;  // direction of the wanted force change
  const double af = std::exp(-period_s / p.tau_f_s), as = std::exp(-period_s / p.tau_s_s);
  const double sig = p.spindle_pole == SpindlePole::kPrinted ? -1.0 : 1.0;
  // Printed reading: the spindle term is unstable; its impulse response keeps the sign of
  // -K_s (= K_s / sigma) for all t, so extreme inputs in that direction still give the bound.
  const double as_eff = sig > 0.0 ? as : std::exp(period_s / p.tau_s_s);
  const double u1_goal = sgn * p.k_f_N > 0.0 ? l.override_max : l.override_min;
  const double n_goal = sgn * p.k_s_N * sig > 0.0 ? l.spindle_max_rpm : l.spindle_min_rpm;
  const long kmax = std::lround(20.0 / period_s);
  for (long k = 0; k < kmax; ++k) {
    // Any admissible input leaves the force on the far side of this extreme trajectory, so
    // reaching the near edge of the band is necessary (overshooting past it is allowed here).
    const double err = xf + xs + d - ref;
    if (sgn < 0.0 ? err <= band : err >= -band) return static_cast<double>(k) * period_s;
    const double du1 = l.override_rate_per_s * period_s, dn = l.spindle_rate_rpm_s * period_s;
    u1 = u1_goal > u1 ? std::min(u1_goal, u1 + du1) : std::max(u1_goal, u1 - du1);
    n_rpm = n_goal > n_rpm ? std::min(n_goal, n_rpm + dn) : std::max(n_goal, n_rpm - dn);
    const double u2 = (n_rpm - l.spindle_nominal_rpm) / l.spindle_rpm_per_unit;
    xf = af * xf + (1.0 - af) * p.k_f_N * u1;
    xs = as_eff * xs + (1.0 - as_eff) * p.k_s_N * u2;
  }
  return 1e9;
}
}  // namespace

ForceMetrics run_force_scenario(const ForceDesign& d, const ForceScenario& sc, ForceTrace* trace) {
  ForceController c;
  c.configure(d, sc.limits);
  ForcePlantSim plant;
  plant.configure(sc.true_plant, d.period_s);
  plant.reset(0.0, 0.0, 0.0);
  const auto& lim = sc.limits;
  c.enable(ForceEnableState{0.0, lim.spindle_nominal_rpm, 0.0, 0.0});
  const double t_step = d.period_s;
  const auto n = static_cast<long>(std::llround(sc.duration_s / t_step));
  Noise noise{0x9E3779B97F4A7C15ull ^ sc.seed};
  const bool noisy = sc.kind == ForceScenarioKind::kNoise || sc.add_noise;
  const bool has_dist = sc.kind == ForceScenarioKind::kStep || sc.kind == ForceScenarioKind::kImpulse;
  const double first_change = (sc.kind == ForceScenarioKind::kTrack ||
                               sc.kind == ForceScenarioKind::kNoise ||
                               sc.kind == ForceScenarioKind::kModelError)
                                  ? 3.5
                                  : (has_dist ? sc.disturbance_at_s : sc.duration_s);
  const double lag_end = first_change;
  ForceMetrics m;
  double se_f = 0.0, se_fm = 0.0, se_p = 0.0, lag_sum = 0.0;
  long lag_n = 0;
  double last_out = 0.0, last_rec = 0.0;
  const double f0 = sc.force_ref_N;
  bool finite = true;
  const long dist_k = std::lround(sc.disturbance_at_s / t_step);
  double prev_override = 0.0, prev_rpm = lim.spindle_nominal_rpm;
  if (trace) *trace = ForceTrace{};
  for (long k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * t_step;
    double dist = 0.0;
    if (sc.kind == ForceScenarioKind::kStep && t >= sc.disturbance_at_s) dist = sc.disturbance_N;
    if (sc.kind == ForceScenarioKind::kImpulse && t >= sc.disturbance_at_s &&
        t < sc.disturbance_at_s + sc.pulse_s) {
      dist = sc.disturbance_N;
    }
    if (sc.kind == ForceScenarioKind::kStep && k == dist_k) {
      // Bound from the state the controller has at the disturbance (steady at the reference).
      m.disturbance_recovery_bound_s =
          recovery_bound_s(sc.true_plant, lim, t_step, prev_override, prev_rpm,
                           sc.true_plant.k_f_N * prev_override,
                           plant.force_N() - sc.true_plant.k_f_N * prev_override, sc.disturbance_N,
                           force_reference(sc, t));
    }
    const double f_true = plant.force_N(dist);
    const double f_meas = f_true + (noisy ? sc.noise_sigma_N * noise.gauss() : 0.0);
    const double ref = force_reference(sc, t);
    const double plan = sc.feed_mm_s * t;
    const double prog = plant.progress_mm();
    ForceInput in;
    in.force_ref_N = ref;
    in.planned_progress_mm = plan;
    in.force_N = f_meas;
    in.progress_mm = prog;
    const ForceOutput out = c.step(in);
    const double fm = c.model_output()(0);
    prev_override = out.feed_override;
    prev_rpm = out.spindle_rpm;
    plant.step(out.feed_override, (out.spindle_rpm - lim.spindle_nominal_rpm) / lim.spindle_rpm_per_unit);
    if (!std::isfinite(f_true) || !std::isfinite(prog)) finite = false;
    se_f += (f_true - ref) * (f_true - ref);
    se_fm += (f_true - fm) * (f_true - fm);
    se_p += (plan - prog) * (plan - prog);
    if (t < first_change) {
      m.force_overshoot_pct = std::max(m.force_overshoot_pct, (f_true - f0) / std::abs(f0) * 100.0);
      if (std::abs(f_true - f0) > 0.02 * std::abs(f0)) last_out = t + t_step;
    }
    if (t >= lag_end - 1.0 && t < lag_end) {
      lag_sum += plan - prog;
      ++lag_n;
      m.steady_force_error = std::max(m.steady_force_error, std::abs(f_true - ref));
    }
    if (has_dist && t >= sc.disturbance_at_s && std::abs(f_true - ref) > 0.02 * std::abs(ref)) {
      last_rec = t + t_step - sc.disturbance_at_s;
    }
    if (trace) {
      trace->t_s.push_back(t);
      trace->force_N.push_back(f_true);
      trace->force_ref_N.push_back(ref);
      trace->force_model_N.push_back(fm);
      trace->progress_mm.push_back(prog);
      trace->plan_mm.push_back(plan);
      trace->feed_override.push_back(out.feed_override);
      trace->spindle_rpm.push_back(out.spindle_rpm);
    }
  }
  const double nn = static_cast<double>(std::max(n, 1L));
  m.force_settling_s = last_out;
  m.force_rms_error = std::sqrt(se_f / nn);
  m.force_rms_error_vs_model = std::sqrt(se_fm / nn);
  m.position_rms_error_mm = std::sqrt(se_p / nn);
  m.position_ramp_lag_mm = lag_n > 0 ? lag_sum / static_cast<double>(lag_n) : 0.0;
  m.disturbance_recovery_s = last_rec;
  const lti::StateSpace pd = lti::c2d_zoh(force_plant_model(sc.true_plant), d.period_s);
  const double rad = lti::max_pole_radius(lti::closed_loop_a(pd, force_feedback_controller(d)));
  m.stable = finite && rad < 1.0;
  return m;
}

}  // namespace contour::control
