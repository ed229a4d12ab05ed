// HoldSource (daemon/reference_sources.hpp): standstill, servoing or following the axes.
#include <gtest/gtest.h>

#include <cmath>

#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::daemon {
namespace {

TEST(HoldSource, ServoingItHoldsTheStartPositionWhateverTheAxesDo) {
  HoldSource h;
  h.start(Eigen::Vector3d(1, 2, 3));
  Feedback fb;
  fb.act_mm = Eigen::Vector3d(1.01, 2.0, 2.99);
  for (int n = 0; n < 10; ++n) {
    const RefPoint r = h.step(fb, true);
    EXPECT_EQ(r.source, SourceKind::kHold);
    EXPECT_TRUE(r.track);
    EXPECT_TRUE(r.drives_on);
    EXPECT_EQ(r.position_mm, Eigen::Vector3d(1, 2, 3));
    fb.act_mm.x() += 0.01;
  }
  EXPECT_FALSE(h.done());
}

TEST(HoldSource, NotServoingItFollowsTheMeasuredPositionAndHoldsTheLastOne) {
  HoldSource h;
  h.start(Eigen::Vector3d::Zero());
  Feedback fb;
  fb.act_mm = Eigen::Vector3d(5, 6, 7);
  RefPoint r = h.step(fb, false);
  EXPECT_FALSE(r.track);
  EXPECT_FALSE(r.drives_on);
  EXPECT_EQ(r.position_mm, Eigen::Vector3d(5, 6, 7));
  fb.act_mm = Eigen::Vector3d(8, 6, 7);
  r = h.step(fb, true);  // the drives come back: it holds where the axes were last seen
  EXPECT_EQ(r.position_mm, Eigen::Vector3d(5, 6, 7));
}

TEST(HoldSource, NoAllocationInStep) {
  HoldSource h;
  Feedback fb;
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 100; ++n) (void)h.step(fb, n % 2 == 0);
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
