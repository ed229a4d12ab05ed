// Force filter: removes the tooth-passing component (attenuation in dB asserted and printed),
// keeps the mean (unity DC gain), follows spindle-speed changes, rejects bad settings, allocates
// nothing per step.
#include "drivers/modbus/force_filter.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <stdexcept>

#include "tests/support/alloc_counter.hpp"

namespace dm = contour::drivers::modbus;

namespace {
// Raw milling force like seed 001 Fig 2.2: mean + tooth-passing fundamental and 2nd harmonic.
struct Signal {
  double mean_N = 400.0;
  double amp1_N = 160.0;  // 40 % of the mean
  double amp2_N = 60.0;
  double tooth_hz = 20.0;
  double at(double t) const {
    const double w = 2.0 * std::numbers::pi * tooth_hz * t;
    return mean_N + amp1_N * std::sin(w) + amp2_N * std::sin(2.0 * w + 0.3);
  }
};

// Peak-to-peak/2 of the output ripple after settling, and its mean.
struct Measured {
  double ripple_N = 0;
  double mean_N = 0;
};
Measured run(dm::ForceFilter& f, const Signal& sig, double fs_hz, double seconds) {
  const int n = static_cast<int>(seconds * fs_hz);
  double lo = 1e300, hi = -1e300, sum = 0;
  int m = 0;
  for (int i = 0; i < n; ++i) {
    const double x = sig.at(i / fs_hz);
    const double y = f.step({x, 0.5 * x, 0.0})[0];
    if (i > n / 2) {
      lo = std::min(lo, y);
      hi = std::max(hi, y);
      sum += y;
      ++m;
    }
  }
  return {(hi - lo) / 2.0, sum / m};
}
double db(double out, double in) { return 20.0 * std::log10(out / in); }
}  // namespace

TEST(ForceFilter, MovingAverageOverToothPeriodRemovesToothPassing) {
  // 2 teeth at 600 rpm -> 20 Hz tooth passing, 200 Hz poll: window 10 samples.
  dm::ForceFilterSettings s;
  s.sample_rate_hz = 200;
  s.teeth = 2;
  s.min_spindle_rpm = 100;
  s.butterworth_order = 0;
  dm::ForceFilter f(s);
  f.set_spindle_rpm(600);
  EXPECT_EQ(f.window_samples(), 10u);
  Signal sig;
  const Measured m = run(f, sig, 200, 5);
  const double att = db(m.ripple_N, sig.amp1_N + sig.amp2_N);
  std::printf(
      "[figure] moving average (10 samples, 20 Hz tooth, 200 Hz fs): ripple %.3g N, "
      "attenuation %.1f dB, mean %.3f N\n",
      m.ripple_N, att, m.mean_N);
  EXPECT_LT(att, -60.0);
  EXPECT_NEAR(m.mean_N, sig.mean_N, 0.01);
}

TEST(ForceFilter, ButterworthAttenuatesToothPassing) {
  Signal sig;
  for (int order : {2, 4}) {
    dm::ForceFilterSettings s;
    s.sample_rate_hz = 200;
    s.moving_average = false;
    s.butterworth_order = order;
    s.cutoff_hz = 4.0;
    dm::ForceFilter f(s);
    const Measured m = run(f, sig, 200, 10);
    const double att = db(m.ripple_N, sig.amp1_N + sig.amp2_N);
    std::printf(
        "[figure] Butterworth order %d, fc 4 Hz, 20 Hz tooth: attenuation %.1f dB, "
        "mean %.3f N\n",
        order, att, m.mean_N);
    // Analogue bound: -20*order*log10(20/4) = -28 dB (2nd), -56 dB (4th); bilinear adds more.
    EXPECT_LT(att, order == 2 ? -26.0 : -52.0);
    EXPECT_NEAR(m.mean_N, sig.mean_N, 0.5);
  }
}

TEST(ForceFilter, CombinedChainWithNoiseAndSpeedChange) {
  dm::ForceFilterSettings s;
  s.sample_rate_hz = 200;
  s.teeth = 2;
  s.min_spindle_rpm = 100;
  s.butterworth_order = 2;
  s.cutoff_hz = 5.0;
  dm::ForceFilter f(s);
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0.0, 5.0);
  // Speed change 600 -> 480 rpm: tooth period 10 -> 12.5 samples (window 12 or 13).
  f.set_spindle_rpm(480);
  EXPECT_TRUE(f.window_samples() == 12u || f.window_samples() == 13u);
  Signal sig;
  sig.tooth_hz = 16.0;
  double lo = 1e300, hi = -1e300;
  for (int i = 0; i < 2000; ++i) {
    const double y = f.step({sig.at(i / 200.0) + noise(rng), 0, 0})[0];
    if (i > 1000) {
      lo = std::min(lo, y);
      hi = std::max(hi, y);
    }
  }
  const double att = db((hi - lo) / 2.0, sig.amp1_N + sig.amp2_N);
  std::printf("[figure] MA(12/12.5 samples)+BW2 5 Hz, 16 Hz tooth + 5 N noise: %.1f dB\n", att);
  EXPECT_LT(att, -30.0);
  f.set_spindle_rpm(1);  // below min: clamped to capacity (120 samples at 100 rpm)
  EXPECT_EQ(f.window_samples(), 60u);
  f.set_spindle_rpm(0);
  EXPECT_EQ(f.window_samples(), 1u);
}

TEST(ForceFilter, BadSettingsThrow) {
  dm::ForceFilterSettings s;
  s.butterworth_order = 3;
  EXPECT_THROW(dm::ForceFilter{s}, std::invalid_argument);
  s.butterworth_order = 2;
  s.cutoff_hz = 150;  // above 0.45 fs
  EXPECT_THROW(dm::ForceFilter{s}, std::invalid_argument);
  s.cutoff_hz = 10;
  s.teeth = 0;
  EXPECT_THROW(dm::ForceFilter{s}, std::invalid_argument);
}

TEST(ForceFilter, StepAllocatesNothing) {
  dm::ForceFilterSettings s;
  s.butterworth_order = 4;
  dm::ForceFilter f(s);
  f.set_spindle_rpm(3000);
  double acc = 0;
  contour::test::AllocGuard g;
  for (int i = 0; i < 10000; ++i) {
    if (i % 1000 == 0) f.set_spindle_rpm(1000.0 + i / 10.0);
    acc += f.step({static_cast<double>(i % 7), 1.0, 2.0})[1];
  }
  EXPECT_EQ(g.counts().total(), 0u);
  EXPECT_GT(acc, 0.0);
}
