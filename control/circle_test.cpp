#include "control/circle_test.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include "control/levenberg_marquardt.hpp"

namespace contour::control::circle {

namespace {
constexpr double kPi = std::numbers::pi;

void check_circle(const Circle& c) {
  if (!(c.radius_mm > 0.0) || !(c.feed_mm_min > 0.0)) {
    throw std::invalid_argument("circle test: radius and feed must be positive");
  }
}

void check_trace(const BallbarTrace& t, const char* what) {
  if (t.t_s.size() != t.deviation_um.size() || t.t_s.size() != t.angle_rad.size()) {
    throw std::invalid_argument(std::string("circle test: ") + what +
                                ": t, angle and deviation must have the same length");
  }
  if (t.t_s.size() < 16) {
    throw std::invalid_argument(std::string("circle test: ") + what + ": fewer than 16 samples");
  }
}

// Servo-only position of eq 2 at t.
Eigen::Vector2d servo_position(const Circle& c, const AxisResponse& x, const AxisResponse& y,
                               double t) {
  const double w = c.omega_rad_s();
  return {c.center_mm.x() + x.m_mm * std::cos(w * t + x.phi_rad),
          c.center_mm.y() + c.sign() * y.m_mm * std::sin(w * t + y.phi_rad)};
}

// Radial deviation (um) seen by a ballbar whose pivot is at the nominal centre + offset.
double radial_um(const Circle& c, const GeometricErrorModel* g, const Eigen::Vector2d& q,
                 const Eigen::Vector2d& offset_mm) {
  if (g == nullptr) {
    return ((q - c.center_mm - offset_mm).norm() - c.radius_mm) * 1000.0;
  }
  const Eigen::Vector3d tip = g->tool_tip_mm(Eigen::Vector3d(q.x(), q.y(), c.z_mm));
  const Eigen::Vector3d pivot =
      Eigen::Vector3d(c.center_mm.x() + offset_mm.x(), c.center_mm.y() + offset_mm.y(), c.z_mm) +
      g->params().tool_offset_mm;
  return ((tip - pivot).norm() - c.radius_mm) * 1000.0;
}

// Least-squares a0 + sum_k (a_k cos(k th) + b_k sin(k th)), k = 1..h. Returns [a0, a1, b1, ...].
Eigen::VectorXd fourier_fit(const std::vector<double>& th, const std::vector<double>& v, int h) {
  const auto n = static_cast<Eigen::Index>(th.size());
  Eigen::MatrixXd a(n, 1 + 2 * h);
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = th[static_cast<std::size_t>(i)];
    a(i, 0) = 1.0;
    for (int k = 1; k <= h; ++k) {
      a(i, 2 * k - 1) = std::cos(k * t);
      a(i, 2 * k) = std::sin(k * t);
    }
    b(i) = v[static_cast<std::size_t>(i)];
  }
  return a.colPivHouseholderQr().solve(b);
}
}  // namespace

Eigen::Vector2d Circle::command_mm(double t_s) const {
  const double th = sign() * omega_rad_s() * t_s;
  return center_mm + radius_mm * Eigen::Vector2d(std::cos(th), std::sin(th));
}

AxisDynamics dynamics_from_response(const AxisResponse& r, double radius_mm, double w) {
  const double s = std::abs(std::sin(r.phi_rad));
  AxisDynamics d;
  d.kp_per_s = r.m_mm * w / (radius_mm * s);
  d.tau_s = (r.m_mm / (radius_mm * s) + 1.0 / std::tan(r.phi_rad)) / w;
  return d;
}

AxisResponse response_of(const AxisDynamics& d, double radius_mm, double w) {
  // G(jw) = kp / (kp - tau w^2 + j w)
  const double re = d.kp_per_s - d.tau_s * w * w;
  AxisResponse r;
  r.m_mm = radius_mm * d.kp_per_s / std::hypot(re, w);
  r.phi_rad = -std::atan2(w, re);
  return r;
}

double matched_gain_eq4(const AxisResponse& x, const AxisResponse& y, const AxisDynamics& dx,
                        double radius_mm, double w) {
  const double r = radius_mm;
  return dx.kp_per_s + w / r *
                           (-(y.m_mm - r * std::cos(y.phi_rad)) / std::sin(y.phi_rad) +
                            (x.m_mm - r * std::cos(x.phi_rad)) / std::sin(x.phi_rad));
}

double matched_gain(const AxisDynamics& x, const AxisDynamics& y, double w) {
  return x.kp_per_s + w * w * (y.tau_s - x.tau_s);
}

GainMatch match_y_to_x(const FitResult& f, double w) {
  GainMatch g;
  g.kp_target_y_per_s = matched_gain(f.dynamics[0], f.dynamics[1], w);
  g.ratio_y = g.kp_target_y_per_s / f.dynamics[1].kp_per_s;
  return g;
}

FitResult fit_machine_record(const Circle& c, const MachineRecord& rec) {
  check_circle(c);
  const std::size_t n = rec.t_s.size();
  for (int a = 0; a < 2; ++a) {
    if (rec.command_mm[static_cast<std::size_t>(a)].size() != n ||
        rec.encoder_mm[static_cast<std::size_t>(a)].size() != n) {
      throw std::invalid_argument("circle test: record columns differ in length");
    }
  }
  if (n < 16) throw std::invalid_argument("circle test: record has fewer than 16 samples");
  const double w = c.omega_rad_s();
  const auto rows = static_cast<Eigen::Index>(n);
  Eigen::MatrixXd a(rows, 3);
  for (Eigen::Index i = 0; i < rows; ++i) {
    const double t = rec.t_s[static_cast<std::size_t>(i)];
    a(i, 0) = std::cos(w * t);
    a(i, 1) = std::sin(w * t);
    a(i, 2) = 1.0;
  }
  const auto qr = a.colPivHouseholderQr();
  FitResult f;
  double ss = 0.0;
  for (std::size_t ax = 0; ax < 2; ++ax) {
    // Command and encoder are fitted alike; their phase difference is the axis' phase, so a
    // time-origin offset in the record cancels.
    const Eigen::Map<const Eigen::VectorXd> cmd(rec.command_mm[ax].data(), rows);
    const Eigen::Map<const Eigen::VectorXd> enc(rec.encoder_mm[ax].data(), rows);
    const Eigen::Vector3d pc = qr.solve(cmd);
    const Eigen::Vector3d pe = qr.solve(enc);
    // x: m cos(wt + phi) = m cos(phi) cos(wt) - m sin(phi) sin(wt)
    // y: s m sin(wt + phi) = s m sin(phi) cos(wt) + s m cos(phi) sin(wt)
    auto phase = [&](const Eigen::Vector3d& p) {
      return ax == 0 ? std::atan2(-p(1), p(0)) : std::atan2(c.sign() * p(0), c.sign() * p(1));
    };
    const double amp_c = std::hypot(pc(0), pc(1));
    const double amp_e = std::hypot(pe(0), pe(1));
    double dphi = phase(pe) - phase(pc);
    dphi = std::remainder(dphi, 2.0 * kPi);
    f.response[ax].m_mm = c.radius_mm * amp_e / amp_c;
    f.response[ax].phi_rad = dphi;
    f.dynamics[ax] = dynamics_from_response(f.response[ax], c.radius_mm, w);
    ss += (a * pe - enc).squaredNorm();
  }
  f.rms_residual_um = std::sqrt(ss / (2.0 * static_cast<double>(n))) * 1000.0;
  f.converged = true;
  f.iterations = 1;
  return f;
}

FitResult fit_ballbar(const Circle& c, const BallbarTrace& tr, const BallbarFitOptions& o) {
  check_circle(c);
  check_trace(tr, "ballbar trace");
  if (!(o.kp_ref_x_per_s > 0.0)) {
    throw std::invalid_argument("circle test: a positive reference gain for X is required");
  }
  const double w = c.omega_rad_s();
  const double r0 = c.radius_mm;
  const auto n = static_cast<Eigen::Index>(tr.t_s.size());
  // p = [phi_x, m_y - R, phi_y, offset_x, offset_y]; m_x from eq 3 with k_p,x = reference.
  auto unpack = [&](const Eigen::VectorXd& p, AxisResponse& x, AxisResponse& y) {
    x.phi_rad = p(0);
    x.m_mm = o.kp_ref_x_per_s * r0 * std::abs(std::sin(p(0))) / w;
    y.m_mm = r0 + p(1);
    y.phi_rad = p(2);
  };
  auto f = [&](const Eigen::VectorXd& p, Eigen::VectorXd& r) {
    AxisResponse x, y;
    unpack(p, x, y);
    const Eigen::Vector2d off(p(3), p(4));
    for (Eigen::Index i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      const Eigen::Vector2d q = servo_position(c, x, y, tr.t_s[k]);
      r(i) = radial_um(c, o.geometry, q, off) - tr.deviation_um[k];
    }
  };
  const AxisResponse g0 = response_of({o.kp_ref_x_per_s, o.tau_guess_s}, r0, w);
  Eigen::VectorXd p0(5);
  p0 << g0.phi_rad, g0.m_mm - r0, g0.phi_rad, 0.0, 0.0;
  Eigen::VectorXd typ(5);
  typ << 1e-2, 1e-3 * r0, 1e-2, 1e-2, 1e-2;
  const LmResult lm = levenberg_marquardt(f, n, p0, typ);
  FitResult res;
  unpack(lm.params, res.response[0], res.response[1]);
  res.center_offset_mm = Eigen::Vector2d(lm.params(3), lm.params(4));
  for (std::size_t a = 0; a < 2; ++a) {
    res.dynamics[a] = dynamics_from_response(res.response[a], r0, w);
  }
  res.kp_x_is_reference = true;
  res.rms_residual_um = std::sqrt(2.0 * lm.cost / static_cast<double>(n));
  res.iterations = lm.iterations;
  res.converged = lm.status == LmStatus::kConverged;
  return res;
}

FitResult fit_reversal(const Circle& cw, const BallbarTrace& tcw, const Circle& ccw,
                       const BallbarTrace& tccw, const ReversalFitOptions& o) {
  check_circle(cw);
  check_circle(ccw);
  check_trace(tcw, "CW trace");
  check_trace(tccw, "CCW trace");
  if (cw.direction == ccw.direction) {
    throw std::invalid_argument("circle test: reversal needs one CW and one CCW circle");
  }
  if (!(o.kp_ref_x_per_s > 0.0) || o.harmonics < 2 || o.harmonics > 32) {
    throw std::invalid_argument("circle test: reversal needs kp_ref > 0 and 2..32 harmonics");
  }
  const int h = o.harmonics;
  const auto n1 = static_cast<Eigen::Index>(tcw.t_s.size());
  const auto n2 = static_cast<Eigen::Index>(tccw.t_s.size());
  const AxisDynamics dx{o.kp_ref_x_per_s, o.tau_assumed_s[0]};
  // p = [k_p,y, a0, a1, b1, ..., ah, bh] (Fourier coefficients in um, in the position angle).
  auto model = [&](const Circle& c, const BallbarTrace& tr, const Eigen::VectorXd& p,
                   Eigen::VectorXd& r, Eigen::Index base) {
    const double w = c.omega_rad_s();
    const AxisResponse x = response_of(dx, c.radius_mm, w);
    const AxisResponse y = response_of({p(0), o.tau_assumed_s[1]}, c.radius_mm, w);
    const auto n = static_cast<Eigen::Index>(tr.t_s.size());
    for (Eigen::Index i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      const Eigen::Vector2d q = servo_position(c, x, y, tr.t_s[k]);
      const Eigen::Vector2d d = q - c.center_mm;
      const double th = std::atan2(d.y(), d.x());
      double g = p(1);
      for (int j = 1; j <= h; ++j) {
        g += p(2 * j) * std::cos(j * th) + p(2 * j + 1) * std::sin(j * th);
      }
      r(base + i) = (d.norm() - c.radius_mm) * 1000.0 + g - tr.deviation_um[k];
    }
  };
  auto f = [&](const Eigen::VectorXd& p, Eigen::VectorXd& r) {
    model(cw, tcw, p, r, 0);
    model(ccw, tccw, p, r, n1);
  };
  Eigen::VectorXd p0 = Eigen::VectorXd::Zero(2 + 2 * h);
  p0(0) = o.kp_ref_x_per_s;
  Eigen::VectorXd typ = Eigen::VectorXd::Ones(2 + 2 * h);
  typ(0) = o.kp_ref_x_per_s;
  const LmResult lm = levenberg_marquardt(f, n1 + n2, p0, typ);
  FitResult res;
  const double w = cw.omega_rad_s();
  res.dynamics[0] = dx;
  res.dynamics[1] = {lm.params(0), o.tau_assumed_s[1]};
  res.response[0] = response_of(res.dynamics[0], cw.radius_mm, w);
  res.response[1] = response_of(res.dynamics[1], cw.radius_mm, w);
  res.kp_x_is_reference = true;
  res.tau_estimated = false;
  res.center_offset_mm = Eigen::Vector2d(lm.params(2), lm.params(3)) / 1000.0;
  res.rms_residual_um = std::sqrt(2.0 * lm.cost / static_cast<double>(n1 + n2));
  res.iterations = lm.iterations;
  res.converged = lm.status == LmStatus::kConverged;
  return res;
}

EllipseMetrics ellipse_metrics(const std::vector<double>& th, const std::vector<double>& dev) {
  if (th.size() != dev.size() || th.size() < 16) {
    throw std::invalid_argument("circle test: ellipse metrics need >= 16 (angle, deviation) pairs");
  }
  const Eigen::VectorXd p = fourier_fit(th, dev, 4);
  EllipseMetrics e;
  e.mean_um = p(0);
  e.ellipse_um = 2.0 * std::hypot(p(3), p(4));
  e.ellipse_45_um = 2.0 * std::abs(p(4));
  e.major_axis_deg = 0.5 * std::atan2(p(4), p(3)) * 180.0 / kPi;
  double lo = HUGE_VAL, hi = -HUGE_VAL;
  for (std::size_t i = 0; i < th.size(); ++i) {
    const double v = dev[i] - p(1) * std::cos(th[i]) - p(2) * std::sin(th[i]);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  e.circularity_um = hi - lo;
  return e;
}

CircleRun simulate_circle(const std::array<SimAxis, 2>& axes, const Circle& c,
                          const SimOptions& o) {
  check_circle(c);
  const double period = axes[0].drive.period_s;
  if (!(period > 0.0) || std::abs(axes[1].drive.period_s - period) > 1e-15) {
    throw std::invalid_argument("circle test: both axes need the same positive period");
  }
  // Slowest closed-loop decay rate of tau s^2 + s + k (the delay is ignored here; the 12/rate
  // margin leaves ~6e-6 of the start-up transient).
  double settle = o.min_settle_s;
  for (const auto& a : axes) {
    const double tau = std::max(a.tau_loop_s(), 1e-9);
    const double k = a.kp_per_s();
    const double disc = 1.0 - 4.0 * tau * k;
    const double rate = disc < 0.0 ? 1.0 / (2.0 * tau) : (1.0 - std::sqrt(disc)) / (2.0 * tau);
    settle = std::max(settle, 12.0 / rate);
  }
  const double w = c.omega_rad_s();
  const auto k0 = static_cast<long>(std::ceil(settle / period));
  const auto n =
      static_cast<long>(std::llround(o.revolutions * 2.0 * kPi / (w * period)));
  std::array<FeedDrive, 2> drives{FeedDrive(axes[0].drive), FeedDrive(axes[1].drive)};
  const Eigen::Vector2d start = c.command_mm(0.0);
  drives[0].reset(start.x());
  drives[1].reset(start.y());
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  CircleRun run;
  for (auto& v : run.record.command_mm) v.reserve(static_cast<std::size_t>(n));
  for (auto& v : run.record.encoder_mm) v.reserve(static_cast<std::size_t>(n));
  for (long k = 0; k < k0 + n; ++k) {
    const double t = static_cast<double>(k) * period;
    const Eigen::Vector2d cmd = c.command_mm(t);
    const Eigen::Vector2d enc(drives[0].measured_mm(), drives[1].measured_mm());
    const Eigen::Vector2d q(drives[0].position_mm(), drives[1].position_mm());
    if (k >= k0) {
      run.record.t_s.push_back(t);
      for (std::size_t a = 0; a < 2; ++a) {
        run.record.command_mm[a].push_back(cmd(static_cast<Eigen::Index>(a)));
        run.record.encoder_mm[a].push_back(enc(static_cast<Eigen::Index>(a)));
      }
      const Eigen::Vector2d d = q - c.center_mm;
      const double th = std::atan2(d.y(), d.x());
      run.servo_angle_rad.push_back(th);
      run.servo_deviation_um.push_back((d.norm() - c.radius_mm) * 1000.0);
      run.ballbar.t_s.push_back(t);
      run.ballbar.angle_rad.push_back(th);
      run.ballbar.deviation_um.push_back(radial_um(c, o.geometry, q, Eigen::Vector2d::Zero()) +
                                         o.noise_um * noise(rng));
    }
    for (std::size_t a = 0; a < 2; ++a) {
      const double e = cmd(static_cast<Eigen::Index>(a)) - enc(static_cast<Eigen::Index>(a));
      drives[a].step(axes[a].position_gain * e);
    }
  }
  return run;
}

}  // namespace contour::control::circle
