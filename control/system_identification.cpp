#include "control/system_identification.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "control/feed_drive.hpp"

namespace contour::control {

namespace {

void append(std::vector<double>& v, double value, double seconds, double period_s) {
  const auto n = static_cast<std::size_t>(std::llround(seconds / period_s));
  v.insert(v.end(), n, value);
}

// Unit-gain ZOH response to u(k) = v_cmd(k) / K_cmd with delay d, sampled like FeedDrive: s(k) is
// the position before the k-th step.
void unit_response(const std::vector<double>& u, double tau_s, int d, double period_s,
                   std::vector<double>& s) {
  FeedDriveParams p;
  p.gain_per_s = 1.0;
  p.tau_s = tau_s;
  p.period_s = period_s;
  p.delay_cycles = d;
  FeedDrive m(p);
  s.resize(u.size());
  for (std::size_t k = 0; k < u.size(); ++k) {
    s[k] = m.position_mm();
    m.step(u[k]);
  }
}

struct Fit {
  double cost = std::numeric_limits<double>::infinity();  // sum of squared residuals
  double k = 0.0, x0 = 0.0, tau = 0.0;
};

Fit fit_at(const std::vector<double>& u, const std::vector<double>& x, double tau, int d,
           double period_s, std::vector<double>& s) {
  unit_response(u, tau, d, period_s, s);
  // Least squares on x = x0 + K s.
  const double n = static_cast<double>(x.size());
  double ss = 0.0, sx = 0.0, sss = 0.0, ssx = 0.0, sxx = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    ss += s[i];
    sx += x[i];
    sss += s[i] * s[i];
    ssx += s[i] * x[i];
    sxx += x[i] * x[i];
  }
  const double det = n * sss - ss * ss;
  Fit f;
  f.tau = tau;
  if (!(det > 0.0)) return f;
  f.k = (n * ssx - ss * sx) / det;
  f.x0 = (sx - f.k * ss) / n;
  double cost = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double r = x[i] - f.x0 - f.k * s[i];
    cost += r * r;
  }
  f.cost = cost;
  return f;
}

}  // namespace

std::vector<double> make_excitation(const ExcitationParams& p) {
  if (!(p.period_s > 0.0) || !(p.amplitude_mm_s > 0.0)) {
    throw std::invalid_argument("excitation: period and amplitude must be > 0");
  }
  for (double t : {p.long_pulse_s, p.short_pulse_s, p.rest_s}) {
    if (!(t >= p.period_s)) {
      throw std::invalid_argument("excitation: pulse and rest durations must be >= one period");
    }
  }
  if (p.short_pulses < 0 || p.short_pulses > 100) {
    throw std::invalid_argument("excitation: short_pulses must be 0..100");
  }
  std::vector<double> v;
  const double a = p.amplitude_mm_s;
  append(v, 0.0, 0.02, p.period_s);  // a short quiet lead-in: the fit sees the start at rest
  append(v, a, p.long_pulse_s, p.period_s);
  append(v, 0.0, p.rest_s, p.period_s);
  append(v, -a, p.long_pulse_s, p.period_s);
  append(v, 0.0, p.rest_s, p.period_s);
  for (int i = 0; i < p.short_pulses; ++i) {
    append(v, a, p.short_pulse_s, p.period_s);
    append(v, 0.0, p.rest_s / 2.0, p.period_s);
    append(v, -a, p.short_pulse_s, p.period_s);
    append(v, 0.0, p.rest_s / 2.0, p.period_s);
  }
  return v;
}

double excitation_excursion_mm(const std::vector<double>& v_cmd_mm_s, double period_s) {
  double x = 0.0, worst = 0.0;
  for (double v : v_cmd_mm_s) {
    x += v * period_s;
    worst = std::max(worst, std::abs(x));
  }
  return worst;
}

IdentificationResult identify_axis(const IdentificationInput& in) {
  IdentificationResult r;
  const std::size_t n = in.v_cmd_mm_s.size();
  if (n != in.position_mm.size()) {
    r.message = "command and position records differ in length";
    return r;
  }
  if (!(in.period_s > 0.0) || !(in.command_gain_per_s > 0.0)) {
    r.message = "period and command gain must be > 0";
    return r;
  }
  if (in.max_delay_cycles < 0 || in.max_delay_cycles > FeedDrive::kMaxDelay) {
    r.message = "max_delay_cycles must be 0.." + std::to_string(FeedDrive::kMaxDelay);
    return r;
  }
  if (!(in.min_tau_s > 0.0) || !(in.max_tau_s > in.min_tau_s)) {
    r.message = "tau search range must be 0 < min < max";
    return r;
  }
  if (n < 50) {
    r.message = "record too short (" + std::to_string(n) + " samples, need >= 50)";
    return r;
  }
  std::vector<double> u(n);
  double umax = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    if (!std::isfinite(in.v_cmd_mm_s[k]) || !std::isfinite(in.position_mm[k])) {
      r.message = "non-finite sample at index " + std::to_string(k);
      return r;
    }
    u[k] = in.v_cmd_mm_s[k] / in.command_gain_per_s;
    umax = std::max(umax, std::abs(u[k]));
  }
  if (!(umax > 0.0)) {
    r.message = "no excitation: the velocity command is zero throughout";
    return r;
  }
  const double x_first = in.position_mm.front();
  for (double x : in.position_mm) r.excursion_mm = std::max(r.excursion_mm, std::abs(x - x_first));

  std::vector<double> s;
  const int nd = in.max_delay_cycles + 1;
  r.residual_by_delay_mm.assign(static_cast<std::size_t>(nd),
                                std::numeric_limits<double>::quiet_NaN());
  Fit best;
  int best_d = 0;
  const double lo = std::log(in.min_tau_s), hi = std::log(in.max_tau_s);
  constexpr int kGrid = 48;
  for (int d = 0; d < nd; ++d) {
    // Coarse grid in log tau, then golden section in the bracket around the grid minimum.
    Fit grid_best;
    int gi = 0;
    for (int i = 0; i <= kGrid; ++i) {
      const double t = std::exp(lo + (hi - lo) * i / kGrid);
      const Fit f = fit_at(u, in.position_mm, t, d, in.period_s, s);
      if (f.cost < grid_best.cost) {
        grid_best = f;
        gi = i;
      }
    }
    double a = lo + (hi - lo) * std::max(0, gi - 1) / kGrid;
    double b = lo + (hi - lo) * std::min(kGrid, gi + 1) / kGrid;
    const double g = (std::sqrt(5.0) - 1.0) / 2.0;
    double c1 = b - g * (b - a), c2 = a + g * (b - a);
    Fit f1 = fit_at(u, in.position_mm, std::exp(c1), d, in.period_s, s);
    Fit f2 = fit_at(u, in.position_mm, std::exp(c2), d, in.period_s, s);
    for (int it = 0; it < 40; ++it) {
      if (f1.cost < f2.cost) {
        b = c2;
        c2 = c1;
        f2 = f1;
        c1 = b - g * (b - a);
        f1 = fit_at(u, in.position_mm, std::exp(c1), d, in.period_s, s);
      } else {
        a = c1;
        c1 = c2;
        f1 = f2;
        c2 = a + g * (b - a);
        f2 = fit_at(u, in.position_mm, std::exp(c2), d, in.period_s, s);
      }
    }
    Fit fd = f1.cost < f2.cost ? f1 : f2;
    if (grid_best.cost < fd.cost) fd = grid_best;
    r.residual_by_delay_mm[static_cast<std::size_t>(d)] =
        std::sqrt(fd.cost / static_cast<double>(n));
    if (fd.cost < best.cost) {
      best = fd;
      best_d = d;
    }
  }
  if (!std::isfinite(best.cost)) {
    r.message = "no fit: the record does not determine the model";
    return r;
  }
  r.gain_per_s = best.k;
  r.velocity_gain = best.k / in.command_gain_per_s;
  r.tau_s = best.tau;
  r.delay_cycles = best_d;
  r.offset_mm = best.x0;
  r.rms_residual_mm = std::sqrt(best.cost / static_cast<double>(n));
  double next = std::numeric_limits<double>::infinity();
  for (int d = 0; d < nd; ++d) {
    if (d != best_d) next = std::min(next, r.residual_by_delay_mm[static_cast<std::size_t>(d)]);
  }
  r.delay_confidence = r.rms_residual_mm > 0.0 ? next / r.rms_residual_mm
                                               : std::numeric_limits<double>::infinity();
  double mean = 0.0;
  for (double x : in.position_mm) mean += x;
  mean /= static_cast<double>(n);
  double var = 0.0;
  for (double x : in.position_mm) var += (x - mean) * (x - mean);
  if (!(var > 0.0) || best.cost > 0.1 * var) {
    r.message = "the axis did not follow its command (the model explains " +
                std::to_string(var > 0.0 ? 100.0 * (1.0 - best.cost / var) : 0.0) +
                " % of the motion): is the drive enabled?";
    return r;
  }
  if (!(best.k > 0.0)) {
    r.message = "the axis moved against its command (gain " + std::to_string(best.k) +
                " 1/s): check the drive's direction and scaling";
    return r;
  }
  if (best.tau <= in.min_tau_s * 1.01 || best.tau >= in.max_tau_s * 0.99) {
    r.message = "time constant at the search bound (" + std::to_string(best.tau) +
                " s): the record does not determine it";
    return r;
  }
  r.ok = true;
  r.message = "K " + std::to_string(r.gain_per_s) + " 1/s, tau " + std::to_string(r.tau_s * 1e3) +
              " ms, delay " + std::to_string(r.delay_cycles) + " cycle(s)";
  return r;
}

}  // namespace contour::control
