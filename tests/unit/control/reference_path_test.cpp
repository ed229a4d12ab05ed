#include "control/reference_path.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace contour::control;

// Seed 000 eq 11 in mm (BLU 0.5 um): steps of F*T arc length within 0.2 % (second-order Taylor).
TEST(SampleCurve, ConstantArcLengthSteps) {
  const double s = 0.0005;
  FunctionCurve c([s](double u) -> Vec3 { return Vec3(1.5e5 * u * u - 1.5e5 * u, -2e4 * u, -5e3 * u) * s; },
                  [s](double u) -> Vec3 { return Vec3(3e5 * u - 1.5e5, -2e4, -5e3) * s; },
                  [s](double) -> Vec3 { return Vec3(3e5, 0, 0) * s; });
  const double feed = 4000.0 / 60.0, t = 0.001;
  const auto ref = sample_curve(c, feed, t);
  ASSERT_GT(ref.size(), 100u);
  double worst = 0.0;
  for (std::size_t i = 1; i + 1 < ref.size(); ++i) {
    // Arc length of the step by fine chords.
    double len = 0.0;
    Vec3 prev = c.point(ref[i - 1].u);
    for (int j = 1; j <= 50; ++j) {
      const Vec3 x = c.point(ref[i - 1].u + (ref[i].u - ref[i - 1].u) * j / 50.0);
      len += (x - prev).norm();
      prev = x;
    }
    worst = std::max(worst, std::abs(len / (feed * t) - 1.0));
  }
  // Measured 1.5e-3 at the vertex (radius 0.75 mm = 11 steps), ~1e-6 elsewhere.
  EXPECT_LT(worst, 2e-3);
  EXPECT_NEAR((ref.back().r_mm - c.point(1.0)).norm(), 0.0, 1e-15);
  EXPECT_LE((ref.back().r_mm - ref[ref.size() - 2].r_mm).norm(), feed * t * 1.001);
}

TEST(SamplePolyline, EveryVertexIsAReferencePointAndNoStepIsTooLong) {
  std::vector<Vec3> v{Vec3(0, 0, 0), Vec3(4, 10, -0.45), Vec3(8, 21, -1), Vec3(8, 21, -1),
                      Vec3(12, 32, -1.54)};
  const double feed = 4000.0 / 60.0, t = 0.001;
  const auto ref = sample_polyline(v, feed, t);
  for (const auto& vert : v) {
    bool found = false;
    for (const auto& r : ref) found = found || (r.r_mm - vert).norm() < 1e-12;
    EXPECT_TRUE(found);
  }
  for (std::size_t i = 1; i < ref.size(); ++i) {
    EXPECT_LE((ref[i].r_mm - ref[i - 1].r_mm).norm(), feed * t * (1 + 1e-9));
    EXPECT_GT((ref[i].r_mm - ref[i - 1].r_mm).norm(), 0.9 * feed * t);
  }
}

TEST(SampleCurve, RejectsBadInput) {
  FunctionCurve c([](double u) { return Vec3(u, 0, 0); }, {}, {});
  EXPECT_THROW(sample_curve(c, 0.0, 0.001), std::invalid_argument);
  FunctionCurve still([](double) { return Vec3(1, 2, 3); }, {}, {});
  EXPECT_THROW(sample_curve(still, 10.0, 0.001), std::invalid_argument);
}
