#include "control/geometric_error.hpp"

#include <gtest/gtest.h>

#include "tests/support/alloc_counter.hpp"

using contour::control::GeometricErrorModel;
using contour::control::GeometricErrorParams;

TEST(GeometricError, ZeroModelIsIdentity) {
  GeometricErrorParams p;
  p.tool_offset_mm = Eigen::Vector3d(0, 0, 50);
  const GeometricErrorModel g(p);
  const Eigen::Vector3d q(12.5, -40.0, 3.0);
  EXPECT_LT(g.error_mm(q).norm(), 1e-15);
  EXPECT_LT((g.tool_tip_mm(q) - Eigen::Vector3d(12.5, -40.0, 53.0)).norm(), 1e-12);
}

TEST(GeometricError, PositioningAndStraightnessArePolynomialsOfTheirAxis) {
  GeometricErrorParams p;
  p.axes[0].translation_mm[0].c = {0.001, 2e-5, 3e-7};  // X positioning: 1 um + 0.02 um/mm ...
  p.axes[1].translation_mm[0].c = {0.0, 0.0, -1e-7};    // Y straightness in X
  const GeometricErrorModel g(p);
  const Eigen::Vector3d e = g.error_mm({50.0, -20.0, 0.0});
  EXPECT_NEAR(e.x(), 0.001 + 2e-5 * 50 + 3e-7 * 2500 - 1e-7 * 400, 1e-12);
  EXPECT_NEAR(e.y(), 0.0, 1e-15);
}

TEST(GeometricError, SquarenessAndAbbeSigns) {
  GeometricErrorParams p;
  p.squareness_xy_rad = 100e-6;
  p.axes[0].rotation_rad[1].c[0] = 20e-6;  // pitch of X (about machine Y)
  p.tool_offset_mm = Eigen::Vector3d(0, 0, 100);
  const GeometricErrorModel g(p);
  const Eigen::Vector3d e = g.error_mm({0.0, 80.0, 0.0});
  // s_xy * y = 8 um, plus the Abbe error of the 100 mm arm: 100 mm * 20 urad = 2 um.
  EXPECT_NEAR(e.x(), 8e-3 + 2e-3, 1e-7);
  EXPECT_NEAR(e.z(), 0.0, 1e-6);  // second order only (0.18 nm)
}

TEST(GeometricError, ScaledModelScalesTheError) {
  GeometricErrorParams p;
  p.axes[1].translation_mm[1].c = {0.0, 5e-5, 2e-7};
  p.squareness_xy_rad = 50e-6;
  const GeometricErrorModel g(p);
  const Eigen::Vector3d q(30.0, 70.0, 0.0);
  EXPECT_LT((g.scaled(1.1).error_mm(q) - 1.1 * g.error_mm(q)).norm(), 1e-9);
  EXPECT_GT(g.error_mm(q).norm(), 1e-3);
}

TEST(GeometricError, ToolTipDoesNotAllocate) {
  GeometricErrorParams p;
  p.axes[2].rotation_rad[0].c = {1e-6, 1e-8};
  p.tool_offset_mm = Eigen::Vector3d(0, 0, 80);
  const GeometricErrorModel g(p);
  double sum = 0.0;
  contour::test::AllocGuard guard;
  for (int i = 0; i < 10000; ++i) sum += g.tool_tip_mm({0.01 * i, -0.02 * i, 1.0}).x();
  EXPECT_EQ(guard.counts().total(), 0u);
  EXPECT_TRUE(std::isfinite(sum));
}
