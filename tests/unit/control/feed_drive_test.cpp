#include "control/feed_drive.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/support/alloc_counter.hpp"

using contour::control::FeedDrive;
using contour::control::FeedDriveParams;

// A constant command u settles to velocity K*u; the exact ZOH step matches the continuous
// solution x(t) = K u (t - tau (1 - e^{-t/tau})) at every sample (not just approximately).
TEST(FeedDrive, ExactZohMatchesContinuousStepResponse) {
  FeedDriveParams p;
  p.gain_per_s = 120.0;
  p.tau_s = 0.03;
  p.period_s = 0.001;
  FeedDrive d(p);
  const double u = 0.5;
  for (int k = 1; k <= 500; ++k) {
    const double x = d.step(u);
    const double t = k * p.period_s;
    const double expect = p.gain_per_s * u * (t - p.tau_s * (1.0 - std::exp(-t / p.tau_s)));
    ASSERT_NEAR(x, expect, 1e-12 * (1.0 + std::abs(expect))) << "k=" << k;
  }
  EXPECT_NEAR(d.velocity_mm_s(), 60.0, 60.0 * 1e-6);
}

TEST(FeedDrive, DelayShiftsResponseByWholeCycles) {
  FeedDriveParams p;
  FeedDrive plain(p);
  p.delay_cycles = 3;
  FeedDrive delayed(p);
  double plain_x[50];
  for (double& x : plain_x) x = plain.step(1.0);
  for (int k = 0; k < 50; ++k) {
    const double x = delayed.step(1.0);
    if (k < 3) {
      EXPECT_EQ(x, 0.0);
    } else {
      EXPECT_DOUBLE_EQ(x, plain_x[k - 3]);
    }
  }
}

TEST(FeedDrive, QuantisedMeasurement) {
  FeedDriveParams p;
  p.blu_mm = 0.0005;
  FeedDrive d(p);
  for (int k = 0; k < 37; ++k) d.step(0.01);
  const double m = d.measured_mm();
  EXPECT_NEAR(std::round(m / 0.0005) * 0.0005, m, 1e-15);
  EXPECT_LE(std::abs(m - d.position_mm()), 0.00025 + 1e-15);
}

TEST(FeedDrive, StepDoesNotAllocate) {
  FeedDriveParams p;
  p.delay_cycles = 1;
  FeedDrive d(p);
  contour::test::AllocGuard guard;
  for (int k = 0; k < 10000; ++k) d.step(std::sin(k * 1e-3));
  EXPECT_EQ(guard.counts().total(), 0u);
}
