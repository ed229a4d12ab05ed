// Command chatter figure and the run-time limit-cycle / chatter detector (issue 16).
#include "control/chatter_monitor.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/support/alloc_counter.hpp"

namespace contour::control {
namespace {

using V3 = std::array<double, kChatterMaxAxes>;
constexpr std::array<bool, 3> kNoClamp{false, false, false};

TEST(CommandChatter, RmsAndMaxOfTheCycleToCycleChange) {
  // X alternates +-1 (steps of 2), Y ramps by 0.5 per cycle, Z constant.
  std::vector<V3> v;
  for (int k = 0; k < 101; ++k) v.push_back({k % 2 == 0 ? 1.0 : -1.0, 0.5 * k, 7.0});
  const ChatterFigure f = command_chatter(v, 3);
  EXPECT_EQ(f.steps, 100);
  EXPECT_DOUBLE_EQ(f.rms_mm_s[0], 2.0);
  EXPECT_DOUBLE_EQ(f.max_mm_s[0], 2.0);
  EXPECT_DOUBLE_EQ(f.rms_mm_s[1], 0.5);
  EXPECT_DOUBLE_EQ(f.rms_mm_s[2], 0.0);
  // One big step among small ones: RMS and max tell them apart.
  v.assign(100, V3{0.0, 0.0, 0.0});
  v[50][0] = 96.0;
  const ChatterFigure g = command_chatter(v, 1);
  EXPECT_EQ(g.axes, 1);
  EXPECT_DOUBLE_EQ(g.max_mm_s[0], 96.0);
  EXPECT_NEAR(g.rms_mm_s[0], std::sqrt(2.0 * 96.0 * 96.0 / 99.0), 1e-12);
  EXPECT_EQ(command_chatter({}, 3).steps, 0);
  EXPECT_EQ(command_chatter({V3{1, 2, 3}}, 3).steps, 0);
}

TEST(CommandChatter, NonFiniteSamplesBreakTheSeries) {
  std::vector<V3> v{{0, 0, 0}, {1, 0, 0}, {NAN, 0, 0}, {50, 0, 0}, {51, 0, 0}};
  const ChatterFigure f = command_chatter(v, 3);
  EXPECT_EQ(f.steps, 2);  // 0->1 and 50->51; nothing across the NaN
  EXPECT_DOUBLE_EQ(f.max_mm_s[0], 1.0);
}

TEST(ChatterMonitor, QuietAxisStaysOk) {
  ChatterMonitor m;
  for (int k = 0; k < 5000; ++k) {
    const double t = k * 0.001;
    const ChatterReport r = m.update({60.0 * std::sin(3 * t), 0.0, 1.0}, kNoClamp);
    ASSERT_EQ(r.level, ChatterLevel::kOk) << k;
  }
  EXPECT_LT(m.window_chatter_mm_s(0), 0.5);
}

TEST(ChatterMonitor, LimitCycleWarnsThenFaultsNamingTheAxisAndFigure) {
  // Issue 16, kp = 50 at standstill: Y swings about +-60 mm/s with clamps most cycles.
  ChatterMonitor m;
  int warn_at = -1, fault_at = -1;
  ChatterReport warn, fault;
  for (int k = 0; k < 2000; ++k) {
    const double vy = (k / 3) % 2 == 0 ? 60.0 : -55.0;  // ~167 Hz square wave
    const ChatterReport r = m.update({0.0, vy, 0.0}, {false, k % 3 == 0, false});
    if (r.raised && r.level == ChatterLevel::kWarning && warn_at < 0) {
      warn_at = k;
      warn = r;
    }
    if (r.raised && r.level == ChatterLevel::kFault) {
      fault_at = k;
      fault = r;
      break;
    }
  }
  ASSERT_GE(warn_at, 0);
  ASSERT_GE(fault_at, 0);
  EXPECT_EQ(warn.axis, 1);
  EXPECT_EQ(fault.axis, 1);
  EXPECT_EQ(fault.figure, ChatterFigureKind::kChatter);
  EXPECT_GT(fault.value, 40.0);
  EXPECT_EQ(fault.limit, 40.0);
  // Judged from the first full window (90-100 cycles), then the warning and fault times.
  EXPECT_NEAR(warn_at, 90 + 250, 15);
  EXPECT_NEAR(fault_at, 90 + 500, 15);
  EXPECT_EQ(m.level(1), ChatterLevel::kFault);
  EXPECT_EQ(m.level(0), ChatterLevel::kOk);
  // Fault latched until reset, even when the axis is quiet again.
  for (int k = 0; k < 500; ++k) m.update({0, 0, 0}, kNoClamp);
  EXPECT_EQ(m.level(1), ChatterLevel::kFault);
  m.reset();
  EXPECT_EQ(m.level(1), ChatterLevel::kOk);
}

TEST(ChatterMonitor, ClampRateAloneRaisesIt) {
  ChatterMonitorParams p;
  p.fault_time_s = 0.2;
  ChatterMonitor m;
  m.configure(p, 3);
  ChatterReport last;
  for (int k = 0; k < 1000 && last.level != ChatterLevel::kFault; ++k) {
    // A smooth command, but the acceleration clamp engages on every second cycle (500 / s).
    last = m.update({0.0, 0.0, 10.0 * std::sin(k * 0.001)}, {false, false, k % 2 == 0});
  }
  EXPECT_EQ(last.level, ChatterLevel::kFault);
  EXPECT_EQ(last.axis, 2);
  EXPECT_EQ(last.figure, ChatterFigureKind::kClampRate);
  EXPECT_NEAR(last.value, 500.0, 20.0);
}

// The loop publishes the raw window sums every cycle and the status reader derives the figures
// from them: the derived figures are the monitor's own, axis by axis, mid-block included.
TEST(ChatterMonitor, FiguresDerivedFromThePublishedSumsAreTheMonitorsOwn) {
  ChatterMonitor m;
  m.configure(ChatterMonitorParams{}, 2);
  std::array<double, kChatterMaxAxes> chatter{}, rate{};
  window_figures(m.window_sums(), chatter, rate);
  EXPECT_EQ(chatter, (V3{0.0, 0.0, 0.0}));  // empty window
  for (int k = 0; k < 137; ++k) {
    m.update({k % 2 == 0 ? 3.0 : -3.0, 0.5 * k, 99.0}, {k % 3 == 0, false, true});
  }
  window_figures(m.window_sums(), chatter, rate);
  for (int i = 0; i < 2; ++i) {
    EXPECT_DOUBLE_EQ(chatter[static_cast<std::size_t>(i)], m.window_chatter_mm_s(i)) << i;
    EXPECT_DOUBLE_EQ(rate[static_cast<std::size_t>(i)], m.window_clamps_per_s(i)) << i;
  }
  EXPECT_NEAR(chatter[0], 6.0, 1e-12);  // |dv| = 6 every cycle
  EXPECT_GT(rate[0], 0.0);
  EXPECT_EQ(chatter[2], 0.0);  // past the configured axes
  EXPECT_EQ(rate[2], 0.0);
}

TEST(ChatterMonitor, ShortBurstBelowTheTimesIsIgnoredAndWarningClears) {
  // A corner transient: 60 ms of heavy chatter, then quiet: neither warning (0.25 s) nor fault.
  ChatterMonitor m;
  for (int k = 0; k < 3000; ++k) {
    const bool burst = k >= 1000 && k < 1060;
    const ChatterReport r =
        m.update({burst ? ((k % 2) != 0 ? 40.0 : -40.0) : 0.0, 0.0, 0.0}, {burst, false, false});
    ASSERT_EQ(r.level, ChatterLevel::kOk) << k;
  }
  // Sustained moderate chatter: warning, which clears when the window is quiet again.
  bool warned = false;
  for (int k = 0; k < 600; ++k) {
    warned = warned || m.update({(k % 2) != 0 ? 5.0 : -5.0, 0, 0}, kNoClamp).level ==
                           ChatterLevel::kWarning;
  }
  EXPECT_TRUE(warned);
  EXPECT_EQ(m.level(0), ChatterLevel::kWarning);
  for (int k = 0; k < 200; ++k) m.update({0, 0, 0}, kNoClamp);
  EXPECT_EQ(m.level(0), ChatterLevel::kOk);
}

TEST(ChatterMonitor, RejectsBadParameters) {
  ChatterMonitor m;
  ChatterMonitorParams p;
  p.window_s = 0.005;  // fewer than 10 periods
  EXPECT_THROW(m.configure(p, 3), std::invalid_argument);
  p = ChatterMonitorParams{};
  p.warn_chatter_mm_s = 50.0;  // above the fault threshold
  EXPECT_THROW(m.configure(p, 3), std::invalid_argument);
  p = ChatterMonitorParams{};
  EXPECT_THROW(m.configure(p, 4), std::invalid_argument);
  p.fault_clamps_per_s = 0.0;
  EXPECT_THROW(m.configure(p, 3), std::invalid_argument);
}

TEST(ChatterMonitor, UpdateDoesNotAllocate) {
  ChatterMonitor m;
  ChatterMeter meter;
  std::size_t total = 0;
  {
    contour::test::AllocGuard guard;
    for (int k = 0; k < 10000; ++k) {
      const V3 v{std::sin(k * 0.01), (k % 2) != 0 ? 1.0 : -1.0, 0.0};
      m.update(v, {false, k % 7 == 0, false});
      meter.add(v);
    }
    total = guard.counts().total();
  }
  EXPECT_EQ(total, 0u);
  EXPECT_EQ(meter.figure().steps, 9999);
}

}  // namespace
}  // namespace contour::control
