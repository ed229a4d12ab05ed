#include "control/loop_stability.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <charconv>
#include <string_view>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "control/contour_error.hpp"
#include "control/feed_drive.hpp"

namespace contour::control {

namespace {

struct Zoh {
  double a = 0.0, b_v = 0.0, c_x = 0.0, d_x = 0.0;
};

// FeedDrive's exact ZOH coefficients (feed_drive.hpp).
Zoh zoh(double gain_per_s, double tau_s, double period_s) {
  const double tau = tau_s > 1e-12 ? tau_s : 1e-12;
  Zoh z;
  z.a = std::exp(-period_s / tau);
  z.b_v = (1.0 - z.a) * gain_per_s;
  z.c_x = tau * (1.0 - z.a);
  z.d_x = gain_per_s * (period_s - tau * (1.0 - z.a));
  return z;
}

// One axis in one direction as a linear state map (reference 0). The model's absolute position
// and the residual's absolute value never appear: only increments do (the offset between model
// and plant is a neutral mode nothing acts on, which would otherwise show as an eigenvalue 1).
// State: x, v, pi (= x(k) - x(k-1)), pb[dp] (commands in flight to the plant), vm,
// mh[dm + 1] (model position increments, newest last), g1, g2 (blend-filter errors), D
// (low-passed derivative), I (only when an integral gain acts).
struct LinearAxis {
  Zoh plant, model;
  int dp = 0, dm = 0;
  bool predictor = false, blend = false, integral = false;
  double a_blend = 0.0, a_lp = 0.0, t_s = 0.001;
  double kp = 0.0, ki = 0.0, kd = 0.0;

  [[nodiscard]] int n_mh() const { return dm + 1; }
  [[nodiscard]] int size() const { return 3 + dp + 1 + n_mh() + 3 + (integral ? 1 : 0); }

  void step(const Eigen::VectorXd& s, Eigen::VectorXd& o) const {
    const int ipb = 3, ivm = 3 + dp, imh = ivm + 1, ig1 = imh + n_mh(), ig2 = ig1 + 1,
              id = ig2 + 1, ii = id + 1;
    const int last = imh + n_mh() - 1;
    const double x = s[0], v = s[1], pi = s[2];
    double smith = 0.0;
    if (predictor) {
      for (int j = 0; j < dm; ++j) smith += s[last - j];
    }
    const double p_hat = x + smith;
    // Residual increment: plant increment minus the model increment it is compared with.
    const double dr = pi - (predictor ? s[last - dm] : s[last]);
    const double df1 = (1.0 - a_blend) * (s[ig1] + dr);
    const double df2 = (1.0 - a_blend) * (s[ig2] + df1);
    const double dp_tilde =
        blend ? s[last] + df2 : pi + (predictor ? s[last] - s[last - dm] : 0.0);
    const double e = -p_hat;
    const double integ = integral ? s[ii] + t_s * e : 0.0;
    const double d_new = a_lp * s[id] + (1.0 - a_lp) * kd * (-dp_tilde) / t_s;
    const double u = kp * e + ki * integ + d_new;
    const double applied = dp > 0 ? s[ipb] : u;
    o.setZero(s.size());
    o[0] = x + plant.c_x * v + plant.d_x * applied;
    o[1] = plant.a * v + plant.b_v * applied;
    o[2] = o[0] - x;
    for (int j = 0; j + 1 < dp; ++j) o[ipb + j] = s[ipb + j + 1];
    if (dp > 0) o[ipb + dp - 1] = u;
    const double vm = s[ivm];
    o[ivm] = model.a * vm + model.b_v * u;
    for (int j = 0; j + 1 < n_mh(); ++j) o[imh + j] = s[imh + j + 1];
    o[last] = model.c_x * vm + model.d_x * u;
    o[ig1] = s[ig1] + dr - df1;
    o[ig2] = s[ig2] + df1 - df2;
    o[id] = d_new;
    if (integral) o[ii] = integ;
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

double pole(double tau_s, double period_s) { return tau_s > 0.0 ? std::exp(-period_s / tau_s) : 0.0; }

void check_plant(const LoopPlant& plant) {
  if (plant.axes < 1 || plant.axes > kMaxServoAxes) {
    throw std::invalid_argument("stability check: plant axes must be 1..3");
  }
  for (int i = 0; i < plant.axes; ++i) {
    const AxisPlant& a = plant.axis[static_cast<std::size_t>(i)];
    if (!(a.gain_per_s > 0.0) || !(a.tau_s >= 0.0) || a.delay_cycles < 0 ||
        a.delay_cycles > FeedDrive::kMaxDelay || !(a.blu_mm >= 0.0) ||
        !(a.max_velocity_mm_s > 0.0) || !(a.max_accel_mm_s2 > 0.0) || !(a.clamp_tau_s >= 0.0)) {
      throw std::invalid_argument("stability check: plant axis " + std::to_string(i) +
                                  " has a non-positive gain/limit or a delay outside 0..16");
    }
  }
}

// One number in a text, printf-like: "prefix %.Nf suffix" or "%g" (control/ has no stdio).
std::string fmt(const char* f, double a) {
  const std::string_view s(f);
  const std::size_t pct = s.find('%');
  if (pct == std::string_view::npos) return std::string(s);
  std::size_t i = pct + 1;
  std::chars_format form = std::chars_format::general;
  int precision = 6;
  if (i < s.size() && s[i] == '.') {
    precision = 0;
    for (++i; i < s.size() && s[i] >= '0' && s[i] <= '9'; ++i) precision = precision * 10 + (s[i] - '0');
  }
  if (i < s.size() && s[i] == 'f') form = std::chars_format::fixed;
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, a, form, precision);
  std::string out(s.substr(0, pct));
  out.append(buf, r.ec == std::errc() ? r.ptr : buf);
  out += s.substr(i + 1);
  return out;
}

std::string corner_name(double gs, double ts) {
  if (gs == 1.0 && ts == 1.0) return "nominal plant";
  if (gs != 1.0) return "plant gain x" + fmt("%.2f", gs);
  return "plant time constant x" + fmt("%.2f", ts);
}

// Gains of one axis in one direction.
void direction_gains(const ServoParams& p, int axis, bool along, double& kp, double& ki,
                     double& kd) {
  const AxisGains& g = p.axis[static_cast<std::size_t>(axis)];
  const bool pid = p.law == AxisLaw::kPid;
  kp = g.kp;
  ki = pid ? g.ki_per_s : 0.0;
  kd = pid ? g.kd_s : 0.0;
  if (p.coupling.enable && !along) {
    kp += p.coupling.cp;
    ki += p.coupling.ci_per_s;
    kd += p.coupling.cd_s;
  }
}

struct SimFigures {
  std::array<double, kMaxServoAxes> pk_pk_mm{};
  std::array<double, kMaxServoAxes> chatter_mm_s{};
  std::array<double, kMaxServoAxes> clamps_per_s{};
  std::array<double, kMaxServoAxes> v_min{}, v_max{};
  bool finite = true;
};

// At rest an axis whose position spans more than this many counts, that clamps at all, or whose
// command changes by more than this RMS is oscillating. Why 30 mm/s: with the derivative filter
// off, an axis dithering by one count at rest already changes its command by ~20 mm/s RMS (the
// unfiltered Cd K BLU / T steps), which is chatter but not a limit cycle; kp = 50 clamps 557-667
// times per second.
constexpr double kRestPeakToPeakBlu = 4.0;
constexpr double kRestChatter_mm_s = 30.0;
constexpr int kMoveCycles = 60;
constexpr int kSettleCycles = 540;
constexpr int kJudgeCycles = 300;
constexpr double kMove_mm = 0.2;

// dir: zero = hold an off-grid point after a small disturbance; else a kMove_mm move along dir.
SimFigures simulate(const ServoParams& p, const LoopPlant& plant, const Vec3& dir, double gs,
                    double ts) {
  const int axes = plant.axes;
  ServoController ctrl(p);
  ContourErrorModel model;
  std::array<FeedDrive, kMaxServoAxes> drive{};
  const Vec3 start(10.000123, -5.000371, 2.000217);  // off the encoder grid
  const bool hold = dir.squaredNorm() == 0.0;
  for (int i = 0; i < axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    const AxisPlant& a = plant.axis[s];
    FeedDriveParams fp;
    fp.gain_per_s = a.gain_per_s * gs;
    fp.tau_s = a.tau_s * ts;
    fp.period_s = p.period_s;
    fp.blu_mm = a.blu_mm;
    fp.delay_cycles = a.delay_cycles;
    drive[s].configure(fp);
    // Holding: start 3 counts off the reference (a disturbance to recover from).
    const double off = hold ? (i == 1 ? -3.0 : 3.0) * std::max(a.blu_mm, 1e-4) : 0.0;
    drive[s].reset(start[i] + off);
  }
  SimFigures f;
  std::array<double, kMaxServoAxes> lo{}, hi{}, sq{}, prev{};
  std::array<int, kMaxServoAxes> clamps{};
  lo.fill(1e300);
  hi.fill(-1e300);
  f.v_min.fill(1e300);
  f.v_max.fill(-1e300);
  const int total = kMoveCycles + kSettleCycles + kJudgeCycles;
  const Vec3 unit = hold ? Vec3::Zero() : Vec3(dir.normalized());
  Vec3 r_prev = start;
  for (int k = 0; k < total; ++k) {
    // Smooth move: (1 - cos) position profile over kMoveCycles, then rest.
    const double frac = k >= kMoveCycles ? 1.0 : 0.5 * (1.0 - std::cos(std::numbers::pi * k / kMoveCycles));
    const Vec3 r = start + unit * (kMove_mm * frac);
    const Vec3 v_ref = (r - r_prev) / p.period_s;
    r_prev = r;
    Vec3 p_meas = Vec3::Zero();
    for (int i = 0; i < axes; ++i) p_meas[i] = drive[static_cast<std::size_t>(i)].measured_mm();
    const Vec3 p_hat = ctrl.predict(p_meas);
    model.push_reference(r);
    const ContourErrorResult ce = model.update(p_hat);
    Vec3 u = Vec3::Zero();
    ctrl.update(r, p_hat, ce, v_ref, u);
    Vec3 u_applied = Vec3::Zero();
    const bool judged = k >= total - kJudgeCycles;
    for (int i = 0; i < axes; ++i) {
      const auto s = static_cast<std::size_t>(i);
      const AxisPlant& a = plant.axis[s];
      const double k_cmd = p.drive[s].gain_per_s;
      // daemon/servo_loop.cpp control_step: v = K u, velocity clamp, acceleration clamp.
      double v = k_cmd * u[i];
      if (!std::isfinite(v)) v = 0.0;
      bool clamped = false;
      if (std::abs(v) > a.max_velocity_mm_s) {
        v = std::copysign(a.max_velocity_mm_s, v);
        clamped = true;
      }
      if (a.clamp_tau_s > 0.0) {
        const double dv = a.max_accel_mm_s2 * a.clamp_tau_s;
        const double va = drive[s].velocity_mm_s();
        if (v > va + dv || v < va - dv) {
          v = std::clamp(v, va - dv, va + dv);
          clamped = true;
        }
      }
      u_applied[i] = v / k_cmd;
      if (judged) {
        const double x = drive[s].position_mm();
        lo[s] = std::min(lo[s], x);
        hi[s] = std::max(hi[s], x);
        if (k > total - kJudgeCycles) sq[s] += (v - prev[s]) * (v - prev[s]);
        if (clamped) ++clamps[s];
        f.v_min[s] = std::min(f.v_min[s], v);
        f.v_max[s] = std::max(f.v_max[s], v);
      }
      prev[s] = v;
    }
    if (plant.controller_sees_clamps) ctrl.command_applied(u_applied);
    for (int i = 0; i < axes; ++i) {
      drive[static_cast<std::size_t>(i)].step(u_applied[i]);
      if (!std::isfinite(drive[static_cast<std::size_t>(i)].position_mm())) f.finite = false;
    }
    if (!f.finite) break;
  }
  const double judge_s = kJudgeCycles * p.period_s;
  for (int i = 0; i < axes; ++i) {
    const auto s = static_cast<std::size_t>(i);
    f.pk_pk_mm[s] = f.finite ? hi[s] - lo[s] : 1e300;
    f.chatter_mm_s[s] = std::sqrt(sq[s] / (kJudgeCycles - 1));
    f.clamps_per_s[s] = clamps[s] / judge_s;
  }
  return f;
}

}  // namespace

double loop_spectral_radius(const ServoParams& p, int axis, const AxisPlant& plant, bool along,
                            double gain_scale, double tau_scale) {
  ServoController::validate(p);
  if (axis < 0 || axis >= p.axes) throw std::invalid_argument("stability check: axis out of range");
  const auto s = static_cast<std::size_t>(axis);
  LinearAxis l;
  // The plant's command unit is the controller's u (v = K_cmd u): its gain in u units is K_true.
  l.plant = zoh(plant.gain_per_s * gain_scale, plant.tau_s * tau_scale, p.period_s);
  l.model = zoh(p.drive[s].gain_per_s, p.drive[s].tau_s, p.period_s);
  l.dp = plant.delay_cycles;
  l.predictor = p.delay_compensation && p.delay_cycles > 0;
  l.dm = l.predictor ? p.delay_cycles : 0;
  l.blend = p.derivative.model_blend_s > 0.0;
  l.a_blend = pole(p.derivative.model_blend_s, p.period_s);
  l.a_lp = pole(p.derivative.lowpass_s, p.period_s);
  l.t_s = p.period_s;
  direction_gains(p, axis, along, l.kp, l.ki, l.kd);
  l.integral = l.ki > 0.0;
  return l.radius();
}

StabilityVerdict check_loop_stability(const ServoParams& p, const LoopPlant& plant,
                                      const StabilityOptions& opt) {
  ServoController::validate(p);
  check_plant(plant);
  if (plant.axes != p.axes) {
    throw std::invalid_argument("stability check: the plant has " + std::to_string(plant.axes) +
                                " axes, the controller " + std::to_string(p.axes));
  }
  if (!(opt.gain_margin >= 0.0 && opt.gain_margin < 1.0) ||
      !(opt.tau_margin >= 0.0 && opt.tau_margin < 1.0)) {
    throw std::invalid_argument("stability check: margins must be in [0, 1)");
  }
  StabilityVerdict out;
  auto name = [&](int i) { return std::string("axis ") + opt.axis_names[static_cast<std::size_t>(i)]; };
  auto fail = [&](int axis, std::string why) {
    if (!out.stable) return;  // keep the first reason
    out.stable = false;
    out.axis = axis;
    out.reason = name(axis) + ": " + std::move(why);
  };
  struct Corner {
    double gs, ts;
  };
  std::vector<Corner> corners{{1.0, 1.0}};
  if (opt.gain_margin > 0.0) {
    corners.push_back({1.0 + opt.gain_margin, 1.0});
    corners.push_back({1.0 - opt.gain_margin, 1.0});
  }
  if (opt.tau_margin > 0.0) {
    corners.push_back({1.0, 1.0 + opt.tau_margin});
    corners.push_back({1.0, 1.0 - opt.tau_margin});
  }
  // Part 1: linear, per axis, both directions.
  for (const Corner& c : corners) {
    for (int i = 0; i < p.axes; ++i) {
      for (bool along : {false, true}) {
        if (along && !p.coupling.enable) continue;  // same loop as across
        const double rho =
            loop_spectral_radius(p, i, plant.axis[static_cast<std::size_t>(i)], along, c.gs, c.ts);
        ++out.linear_cases;
        out.spectral_radius = std::max(out.spectral_radius, rho);
        if (!(rho < 1.0 - kRadiusMargin)) {
          double kp = 0.0, ki = 0.0, kd = 0.0;
          direction_gains(p, i, along, kp, ki, kd);
          fail(i, std::string(rho >= 1.0 ? "unstable" : "on the stability limit") + " " +
                      (p.coupling.enable ? (along ? "along the path (axis law alone)"
                                                  : "across the path (axis law + coupling)")
                                         : "(axis law)") +
                      " with the " + corner_name(c.gs, c.ts) + ": closed-loop spectral radius " +
                      fmt("%.6f", rho) + " (kp " + fmt("%g", kp) + ", ki " + fmt("%g", ki) +
                      " 1/s, kd " + fmt("%g", kd) + " s; plant delay " +
                      std::to_string(plant.axis[static_cast<std::size_t>(i)].delay_cycles) +
                      ", predictor delay " + std::to_string(p.delay_compensation ? p.delay_cycles : 0) +
                      " cycles)");
        }
      }
    }
  }
  if (!opt.simulate) return out;
  // Part 2: the real code with quantisation and the daemon's clamps.
  std::vector<std::pair<Vec3, std::string>> scenarios;
  scenarios.emplace_back(Vec3::Zero(), "holding a position");
  for (int i = 0; i < p.axes; ++i) {
    Vec3 d = Vec3::Zero();
    d[i] = 1.0;
    scenarios.emplace_back(d, fmt("after a %.1f mm move along ", kMove_mm) + std::string(1, opt.axis_names[static_cast<std::size_t>(i)]));
  }
  if (p.axes > 1) {
    Vec3 d = Vec3::Zero();
    for (int i = 0; i < p.axes; ++i) d[i] = 1.0;
    scenarios.emplace_back(d, fmt("after a %.1f mm diagonal move", kMove_mm));
  }
  for (const Corner& c : corners) {
    for (const auto& [dir, what] : scenarios) {
      const SimFigures f = simulate(p, plant, dir, c.gs, c.ts);
      ++out.simulations;
      for (int i = 0; i < p.axes; ++i) {
        const auto s = static_cast<std::size_t>(i);
        const double blu = std::max(plant.axis[s].blu_mm, 1e-4);
        out.rest_peak_to_peak_um = std::max(out.rest_peak_to_peak_um, f.pk_pk_mm[s] * 1e3);
        out.rest_chatter_mm_s = std::max(out.rest_chatter_mm_s, f.chatter_mm_s[s]);
        out.rest_clamps_per_s = std::max(out.rest_clamps_per_s, f.clamps_per_s[s]);
        const bool moving = !f.finite || f.pk_pk_mm[s] > kRestPeakToPeakBlu * blu ||
                            f.clamps_per_s[s] > 0.0 || f.chatter_mm_s[s] > kRestChatter_mm_s;
        if (moving) {
          fail(i, (f.finite ? "oscillates at rest " : "diverges ") + what + " with the " +
                      corner_name(c.gs, c.ts) + ": position " + fmt("+-%.1f um", f.pk_pk_mm[s] * 0.5e3) +
                      ", command " + fmt("%.1f", f.v_min[s]) + ".." + fmt("%.1f mm/s", f.v_max[s]) +
                      ", " + fmt("%.1f mm/s RMS change per cycle", f.chatter_mm_s[s]) + ", " +
                      fmt("%.0f clamped cycles/s", f.clamps_per_s[s]));
        }
      }
    }
  }
  return out;
}

}  // namespace contour::control
