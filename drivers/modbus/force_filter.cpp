#include "drivers/modbus/force_filter.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace contour::drivers::modbus {

void ForceFilter::configure(const ForceFilterSettings& s) {
  if (!(s.sample_rate_hz > 0.0)) throw std::invalid_argument("force filter: sample_rate_hz <= 0");
  if (s.moving_average && (s.teeth < 1 || !(s.min_spindle_rpm > 0.0)))
    throw std::invalid_argument(
        "force filter: moving average needs teeth >= 1, min_spindle_rpm > 0");
  if (s.butterworth_order != 0 && s.butterworth_order != 2 && s.butterworth_order != 4)
    throw std::invalid_argument("force filter: butterworth_order must be 0, 2 or 4");
  if (s.butterworth_order != 0 && !(s.cutoff_hz > 0.0 && s.cutoff_hz < 0.45 * s.sample_rate_hz))
    throw std::invalid_argument("force filter: cutoff_hz must be in (0, 0.45 * sample_rate_hz)");
  s_ = s;
  std::size_t cap = 1;
  if (s.moving_average) {
    const double longest = s.sample_rate_hz * 60.0 / (s.teeth * s.min_spindle_rpm);
    cap = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(longest)));
    if (cap > 100000)
      throw std::invalid_argument("force filter: tooth period window > 100000 samples");
  }
  ring_.assign(cap, Vec{});
  window_ = 1;
  // Butterworth pole pairs: Q = 1 / (2 cos(theta_k)); order 2: 0.7071; order 4: 0.5412, 1.3066.
  n_bq_ = s.butterworth_order / 2;
  for (int k = 0; k < n_bq_; ++k) {
    const double theta = std::numbers::pi * (2.0 * k + 1.0) / (2.0 * s.butterworth_order);
    const double q = 1.0 / (2.0 * std::cos(theta));
    const double w0 = 2.0 * std::numbers::pi * s.cutoff_hz / s.sample_rate_hz;
    const double alpha = std::sin(w0) / (2.0 * q);
    const double c = std::cos(w0);
    const double a0 = 1.0 + alpha;
    Biquad& b = bq_[static_cast<std::size_t>(k)];
    b.b0 = (1.0 - c) / 2.0 / a0;
    b.b1 = (1.0 - c) / a0;
    b.b2 = b.b0;
    b.a1 = -2.0 * c / a0;
    b.a2 = (1.0 - alpha) / a0;
  }
  reset();
}

void ForceFilter::set_spindle_rpm(double rpm) noexcept {
  if (!s_.moving_average || !(rpm > 0.0)) {
    window_ = 1;
    return;
  }
  const double period = s_.sample_rate_hz * 60.0 / (s_.teeth * rpm);
  const auto n = static_cast<std::size_t>(std::max(1.0, std::round(period)));
  window_ = std::min(n, ring_.size());
}

void ForceFilter::reset() noexcept {
  for (auto& v : ring_) v = Vec{};
  head_ = 0;
  filled_ = 0;
  for (auto& b : bq_) {
    b.z1 = {};
    b.z2 = {};
  }
}

ForceFilter::Vec ForceFilter::step(const Vec& x) noexcept {
  Vec y = x;
  if (s_.moving_average && !ring_.empty()) {
    ring_[head_] = x;
    head_ = (head_ + 1) % ring_.size();
    filled_ = std::min(filled_ + 1, ring_.size());
    const std::size_t n = std::min(window_, filled_);
    // Summing the window each step (<= a few hundred samples at 200 Hz) avoids the drift of a
    // running sum when the window changes with the spindle speed.
    Vec sum{};
    std::size_t idx = head_;
    for (std::size_t i = 0; i < n; ++i) {
      idx = idx == 0 ? ring_.size() - 1 : idx - 1;
      for (std::size_t c = 0; c < kChannels; ++c) sum[c] += ring_[idx][c];
    }
    for (std::size_t c = 0; c < kChannels; ++c) y[c] = sum[c] / static_cast<double>(n);
  }
  for (int k = 0; k < n_bq_; ++k) {
    Biquad& b = bq_[static_cast<std::size_t>(k)];
    for (std::size_t c = 0; c < kChannels; ++c) {
      // Transposed direct form II.
      const double in = y[c];
      const double out = b.b0 * in + b.z1[c];
      b.z1[c] = b.b1 * in - b.a1 * out + b.z2[c];
      b.z2[c] = b.b2 * in - b.a2 * out;
      y[c] = out;
    }
  }
  return y;
}

}  // namespace contour::drivers::modbus
