// StopSource (daemon/reference_sources.hpp): the controlled stop of FAULT.
#include <gtest/gtest.h>

#include <cmath>

#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::daemon {
namespace {

TEST(StopSource, RampsTheVelocityDownAlongItsDirectionAtTheStopDecelerationThenDisables) {
  StopSource s;
  s.start();
  Feedback fb;
  fb.act_mm = Eigen::Vector3d(1, 1, 1);
  std::array<double, kMaxAxes> v{30.0, 40.0, 0.0};  // 50 mm/s
  const double dec = 1000.0, T = 0.001;
  int n = 0;
  double prev = 50.0;
  for (; n < 1000 && !s.done(); ++n) {
    const RefPoint r = s.step(fb, v, dec, T, 3);
    EXPECT_EQ(r.source, SourceKind::kStop);
    EXPECT_FALSE(r.track);
    EXPECT_EQ(r.position_mm, fb.act_mm);
    const double speed = std::hypot(r.velocity_mm_s[0], r.velocity_mm_s[1]);
    EXPECT_LE(speed, prev) << "never faster (cycle " << n << ")";
    EXPECT_NEAR(prev - speed, std::min(prev, dec * T), 1e-9) << "cycle " << n;
    if (speed > 0.0) {
      EXPECT_NEAR(r.velocity_mm_s[0] / r.velocity_mm_s[1], 0.75, 1e-9);
    }
    EXPECT_EQ(r.drives_on, speed > 0.0);
    prev = speed;
    v = r.velocity_mm_s;
  }
  EXPECT_TRUE(s.done());
  EXPECT_GE(n, 50);  // 50 mm/s at 1000 mm/s^2: 50 cycles (+1 for rounding)
  EXPECT_LE(n, 51);
  EXPECT_EQ(prev, 0.0);
}

TEST(StopSource, AStandingMachineIsDoneAtOnce) {
  StopSource s;
  s.start();
  const RefPoint r = s.step(Feedback{}, {0.0, 0.0, 0.0}, 1000.0, 0.001, 3);
  EXPECT_FALSE(r.drives_on);
  EXPECT_TRUE(s.done());
}

TEST(StopSource, NoAllocationInStep) {
  StopSource s;
  Feedback fb;
  std::array<double, kMaxAxes> v{10.0, 0.0, 0.0};
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 100; ++n) v = s.step(fb, v, 100.0, 0.001, 3).velocity_mm_s;
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
