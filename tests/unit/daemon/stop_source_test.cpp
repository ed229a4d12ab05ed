// StopSource (daemon/reference_sources.hpp): the controlled stop of FAULT and the power-down of
// `disable`: a ramp from a velocity the axes really have, zero until standstill, then off (or the
// drives' quick stop after the standstill timeout).
#include <gtest/gtest.h>

#include <cmath>

#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::daemon {
namespace {

LiveLimits limits() {
  LiveLimits l;
  l.stop_decel_mm_s2 = 1000.0;
  l.max_velocity_mm_s = {100.0, 100.0, 100.0};
  l.max_accel_mm_s2 = {2000.0, 2000.0, 2000.0};
  l.standstill_velocity_mm_s = 1.0;
  l.standstill_time_s = 0.005;
  l.standstill_timeout_s = 0.1;
  return l;
}

// Feedback of axes moving at v (fresh).
Feedback moving(double vx, double vy, double vz) {
  Feedback fb;
  fb.act_mm = Eigen::Vector3d(1, 1, 1);
  const double v[3] = {vx, vy, vz};
  for (std::size_t i = 0; i < 3; ++i) {
    fb.bus.axis[i].fresh = true;
    fb.bus.axis[i].velocity_mm_s = v[i];
  }
  return fb;
}

TEST(StopSource, RampsEachAxisDownMonotonicallyAlongItsDirectionAtTheStopDeceleration) {
  StopSource s;
  const LiveLimits lim = limits();
  s.start({30.0, -40.0, 0.0}, 3);  // 50 mm/s
  Feedback fb = moving(30.0, -40.0, 0.0);
  const double T = 0.001;
  int n = 0;
  double prev = 50.0;
  std::array<double, kMaxAxes> vprev{30.0, -40.0, 0.0};
  for (; n < 1000 && s.phase() == StopSource::Phase::kRamp; ++n) {
    const RefPoint r = s.step(fb, lim, T);
    EXPECT_EQ(r.source, SourceKind::kStop);
    EXPECT_FALSE(r.track);
    EXPECT_EQ(r.position_mm, fb.act_mm);
    EXPECT_TRUE(r.drives_on);
    EXPECT_FALSE(r.quick_stop);
    const double speed = std::hypot(r.velocity_mm_s[0], r.velocity_mm_s[1]);
    EXPECT_NEAR(prev - speed, std::min(prev, lim.stop_decel_mm_s2 * T), 1e-9) << "cycle " << n;
    for (std::size_t a = 0; a < 3; ++a) {
      EXPECT_LE(std::abs(r.velocity_mm_s[a]), std::abs(vprev[a]) + 1e-12) << "axis " << a;
      EXPECT_GE(r.velocity_mm_s[a] * vprev[a], 0.0) << "never reverses";
    }
    if (speed > 0.0) {
      EXPECT_NEAR(r.velocity_mm_s[0] / r.velocity_mm_s[1], -0.75, 1e-9);
    }
    prev = speed;
    vprev = r.velocity_mm_s;
  }
  EXPECT_EQ(prev, 0.0);
  EXPECT_GE(n, 50);  // 50 mm/s at 1000 mm/s^2: 50 cycles
  EXPECT_LE(n, 51);
  EXPECT_EQ(s.phase(), StopSource::Phase::kSettle);
}

TEST(StopSource, DrivesStayOnWithZeroCommandUntilTheAxesStandStillThenOff) {
  StopSource s;
  const LiveLimits lim = limits();
  s.start({0.0, 0.0, 0.0}, 3);
  EXPECT_EQ(s.phase(), StopSource::Phase::kSettle);
  // Still coasting at 18 mm/s through the drive's lag: never "disable voltage" now.
  Feedback fb = moving(18.0, 0.0, 0.0);
  for (int n = 0; n < 20; ++n) {
    const RefPoint r = s.step(fb, lim, 0.001);
    EXPECT_TRUE(r.drives_on) << n;
    EXPECT_EQ(r.velocity_mm_s[0], 0.0);
  }
  EXPECT_FALSE(s.done());
  // Below the standstill speed: off after standstill_time_s (5 cycles), not before.
  fb = moving(0.5, 0.2, 0.0);
  int off_at = -1;
  for (int n = 0; n < 20 && off_at < 0; ++n) {
    const RefPoint r = s.step(fb, lim, 0.001);
    if (!r.drives_on) off_at = n;
  }
  EXPECT_EQ(off_at, 4);  // the 5th cycle below the speed completes 5 ms
  EXPECT_TRUE(s.done());
  EXPECT_EQ(s.phase(), StopSource::Phase::kOff);
  EXPECT_FALSE(s.timed_out());
}

TEST(StopSource, StaleFeedbackIsNotStandstillAndTheTimeoutGivesTheDrivesQuickStop) {
  StopSource s;
  const LiveLimits lim = limits();
  s.start({0.0, 0.0, 0.0}, 3);
  Feedback fb = moving(0.0, 0.0, 0.0);
  fb.bus.axis[1].fresh = false;  // Y's TPDOs are missing: nobody knows it stands
  int timeouts = 0;
  RefPoint r;
  for (int n = 0; n < 200; ++n) {
    r = s.step(fb, lim, 0.001);
    if (s.timed_out()) {
      ++timeouts;
      EXPECT_EQ(s.moving_axis(), 1);
      EXPECT_TRUE(std::isnan(s.moving_speed_mm_s()));
      EXPECT_NEAR(n * 0.001, lim.standstill_timeout_s, 0.0015);
    }
  }
  EXPECT_EQ(timeouts, 1);
  EXPECT_TRUE(r.quick_stop);
  EXPECT_FALSE(r.drives_on);
  EXPECT_TRUE(s.done());
  EXPECT_EQ(s.phase(), StopSource::Phase::kQuickStop);
}

TEST(StopSource, AnAxisStillMovingAtTheTimeoutIsNamed) {
  StopSource s;
  s.start({5.0, 0.0, 0.0}, 3);
  const Feedback fb = moving(0.1, 0.0, 7.5);  // Z keeps moving (a drive that does not brake)
  for (int n = 0; n < 300 && !s.done(); ++n) s.step(fb, limits(), 0.001);
  EXPECT_EQ(s.phase(), StopSource::Phase::kQuickStop);
  EXPECT_EQ(s.moving_axis(), 2);
  EXPECT_DOUBLE_EQ(s.moving_speed_mm_s(), 7.5);
}

TEST(StopSource, StartsOffAndNonFiniteStartVelocitiesCountAsZero) {
  StopSource s;
  EXPECT_TRUE(s.done());
  EXPECT_EQ(s.phase(), StopSource::Phase::kOff);
  s.start({std::nan(""), 3.0, 4.0}, 3);
  const RefPoint r = s.step(moving(0, 3, 4), limits(), 0.001);
  EXPECT_EQ(r.velocity_mm_s[0], 0.0);
  EXPECT_NEAR(std::hypot(r.velocity_mm_s[1], r.velocity_mm_s[2]), 4.0, 1e-9);
}

TEST(StopSource, NoAllocationInStep) {
  StopSource s;
  const Feedback fb = moving(10.0, 0.0, 0.0);
  const LiveLimits lim = limits();
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    s.start({10.0, 0.0, 0.0}, 3);
    for (int n = 0; n < 300; ++n) s.step(fb, lim, 0.001);
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
