#include "control/true_contour_error.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace contour::control;

TEST(CurveDistance, HelixAgainstAnalyticDistanceInPlane) {
  // Planar circle radius 5: distance = |r - 5| for points in the plane.
  FunctionCurve c([](double u) { return Vec3(5 * std::cos(u), 5 * std::sin(u), 0); },
                  [](double u) { return Vec3(-5 * std::sin(u), 5 * std::cos(u), 0); },
                  [](double u) { return Vec3(-5 * std::cos(u), -5 * std::sin(u), 0); }, 0.0, 3.0);
  CurveDistance d(c, 500);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> a(0.2, 2.8), r(4.0, 6.0);
  for (int i = 0; i < 2000; ++i) {
    const double ang = a(rng), rad = r(rng);
    const TrueError e = d.query(Vec3(rad * std::cos(ang), rad * std::sin(ang), 0));
    ASSERT_NEAR(e.distance_mm, std::abs(rad - 5.0), 1e-12);
    ASSERT_NEAR(e.u, ang, 1e-9);
    ASSERT_FALSE(e.beyond_end);
  }
  // Past the end along the tangent: beyond_end, distance to the end point.
  const Vec3 end = c.point(3.0);
  const TrueError e = d.query(end + 0.5 * c.d1(3.0).normalized());
  EXPECT_TRUE(e.beyond_end);
  EXPECT_NEAR(e.distance_mm, 0.5, 1e-12);
}

TEST(CurveDistance, NumericDerivativesParabola) {
  // No explicit derivatives: central differences. Distance of (0, 1) to y = x^2: min over x of
  // x^2 + (x^2 - 1)^2 at x^2 = 1/2 -> sqrt(3)/2.
  FunctionCurve c([](double u) { return Vec3(u, u * u, 0); }, {}, {}, -2.0, 2.0);
  CurveDistance d(c);
  EXPECT_NEAR(d.query(Vec3(0, 1, 0)).distance_mm, std::sqrt(3.0) / 2.0, 1e-10);
}

TEST(SegmentPathDistance, PolylineExact) {
  std::vector<Vec3> v{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)};
  SegmentPathDistance d(polyline_segments(v));
  EXPECT_NEAR(d.query(Vec3(0.5, 0.2, 0)).distance_mm, 0.2, 1e-15);
  EXPECT_NEAR(d.query(Vec3(1.3, 0.5, 0)).distance_mm, 0.3, 1e-15);
  EXPECT_NEAR(d.query(Vec3(1.2, -0.2, 0.1)).distance_mm, std::sqrt(0.04 + 0.04 + 0.01), 1e-15);
  const TrueError e = d.query(Vec3(1, 1.5, 0));
  EXPECT_TRUE(e.beyond_end);
  EXPECT_FALSE(d.query(Vec3(0.9, 0.9, 0)).beyond_end);
}
