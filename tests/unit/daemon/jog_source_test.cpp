// JogSource (daemon/reference_sources.hpp): trapezoidal single-axis jog at the live limits.
#include <gtest/gtest.h>

#include <cmath>

#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::daemon {
namespace {

constexpr double kT = 0.001;

LiveLimits limits() {
  LiveLimits l;
  l.max_velocity_mm_s = {100.0, 100.0, 50.0};
  l.max_accel_mm_s2 = {1000.0, 1000.0, 500.0};
  return l;
}

TEST(JogSource, ReachesTheTargetExactlyWithinSpeedAndAccelerationLimits) {
  JogSource j;
  j.start(0, 50.0, 12.5);
  Eigen::Vector3d ref = Eigen::Vector3d::Zero();
  double v_prev = 0.0;
  int n = 0;
  for (; n < 10000 && j.active(); ++n) {
    const RefPoint r = j.step(ref, limits(), kT);
    EXPECT_EQ(r.source, SourceKind::kJog);
    const double v = (r.position_mm.x() - ref.x()) / kT;
    EXPECT_LE(v, 50.0 + 1e-9);
    // Braking follows v = sqrt(2 a d) sampled once per cycle: it overshoots a_max while the
    // distance left shrinks (up to ~38 % in the last cycle). Round-1 behaviour kept unchanged by
    // the stage refactor (issue 15); the stop rework (issue 16) owns the fix. Bounded here so that
    // a change for the worse fails.
    const double rem = 12.5 - r.position_mm.x();
    EXPECT_LE(std::abs(v - v_prev) / kT, rem > 0.5 ? 1000.0 * 1.02 : 1000.0 * 1.4) << "cycle " << n;
    EXPECT_EQ(r.position_mm.y(), 0.0);
    ref = r.position_mm;
    v_prev = v;
  }
  EXPECT_TRUE(j.done());
  EXPECT_EQ(ref.x(), 12.5);
  // 12.5 mm: 0.05 s ramp up, 0.2 s at 50 mm/s, 0.05 s down: ~0.3 s.
  EXPECT_NEAR(n * kT, 0.3, 0.01);
}

TEST(JogSource, TheAxisVelocityLimitCapsTheRequestedSpeed) {
  JogSource j;
  j.start(2, 500.0, -20.0);  // Z: 50 mm/s limit
  Eigen::Vector3d ref = Eigen::Vector3d::Zero();
  double vmax = 0.0;
  while (j.active()) {
    const RefPoint r = j.step(ref, limits(), kT);
    vmax = std::max(vmax, std::abs(r.position_mm.z() - ref.z()) / kT);
    ref = r.position_mm;
  }
  EXPECT_NEAR(vmax, 50.0, 1e-9);
  EXPECT_EQ(ref.z(), -20.0);
}

TEST(JogSource, BrakeStopsWithinTheBrakingDistanceWithoutReversing) {
  JogSource j;
  j.start(1, 80.0, 100.0);
  Eigen::Vector3d ref = Eigen::Vector3d::Zero();
  for (int n = 0; n < 300; ++n) ref = j.step(ref, limits(), kT).position_mm;
  const double at_brake = ref.y();
  const double v = 80.0;  // at speed after 0.3 s
  j.brake(ref.y(), 1000.0);
  EXPECT_NEAR(j.target_mm(), at_brake + v * v / 2000.0, 1e-9);
  double prev = ref.y();
  while (j.active()) {
    ref = j.step(ref, limits(), kT).position_mm;
    EXPECT_GE(ref.y(), prev);
    prev = ref.y();
  }
  EXPECT_NEAR(ref.y(), at_brake + 3.2, 1e-9);
}

TEST(JogSource, NoAllocationInStep) {
  JogSource j;
  j.start(0, 50.0, 5.0);
  Eigen::Vector3d ref = Eigen::Vector3d::Zero();
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 1000; ++n) ref = j.step(ref, limits(), kT).position_mm;
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
