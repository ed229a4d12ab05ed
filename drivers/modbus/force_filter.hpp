#pragma once
// Force signal conditioning (seed 001 Fig 2.2 -> 2.3): the raw milling force carries tooth-passing
// harmonics at k * z * n / 60 Hz (z teeth, n rpm); the controller uses the averaged force.
// Chain, each stage optional: (1) moving average over one tooth period, window recomputed from the
// spindle speed (an exact period average nulls the fundamental and every harmonic when the period
// is an integer number of samples); (2) Butterworth low-pass of order 2 or 4 (cascaded biquads,
// bilinear transform with pre-warping), unity DC gain.
// The sample rate must exceed twice the highest harmonic of interest: at a 200 Hz poll, tooth
// frequencies above 100 Hz alias (then the dynamometer amplifier's own low-pass must remove them).
//
// Pure maths (no OS headers). configure() may throw std::invalid_argument; step() and
// set_spindle_rpm() are noexcept and allocation-free (ring buffer sized at configure), < 1 us.
#include <array>
#include <cstddef>
#include <vector>

namespace contour::drivers::modbus {

struct ForceFilterSettings {
  double sample_rate_hz = 200.0;
  bool moving_average = true;
  int teeth = 4;
  double min_spindle_rpm = 100.0;  // sizes the moving-average buffer (longest tooth period)
  int butterworth_order = 2;       // 0 (off), 2 or 4
  double cutoff_hz = 10.0;
};

class ForceFilter {
 public:
  static constexpr std::size_t kChannels = 3;
  using Vec = std::array<double, kChannels>;

  ForceFilter() = default;
  explicit ForceFilter(const ForceFilterSettings& s) { configure(s); }
  void configure(const ForceFilterSettings& s);

  // Tooth period from the spindle speed; below min_spindle_rpm the window is clamped to capacity.
  // rpm <= 0: the moving average passes the signal through (window 1).
  void set_spindle_rpm(double rpm) noexcept;
  [[nodiscard]] std::size_t window_samples() const noexcept { return window_; }

  Vec step(const Vec& x) noexcept;
  void reset() noexcept;

 private:
  struct Biquad {
    double b0 = 1, b1 = 0, b2 = 0, a1 = 0, a2 = 0;
    std::array<double, kChannels> z1{}, z2{};
  };
  ForceFilterSettings s_{};
  std::vector<Vec> ring_;  // capacity fixed at configure
  std::size_t head_ = 0;
  std::size_t filled_ = 0;
  std::size_t window_ = 1;
  std::array<Biquad, 2> bq_{};
  int n_bq_ = 0;
};

}  // namespace contour::drivers::modbus
