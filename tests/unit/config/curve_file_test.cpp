#include "config/curve_file.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace contour::config;

namespace {
std::string error_of(const std::string& yaml) {
  try {
    load_curve_string(yaml, "k.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return {};
}
}  // namespace

TEST(CurveFile, PaperCurvesLoadInMm) {
  for (const char* name : {"eq11", "helix", "ellipse", "cubic"}) {
    const CurveFile f =
        load_curve_file(std::string(CONTOUR_SOURCE_DIR "/config/programs/") + name + ".yaml");
    EXPECT_EQ(f.name, name);
    EXPECT_DOUBLE_EQ(f.scale_to_mm, 0.0005);
    ASSERT_TRUE(f.curve);
    // Explicit derivatives agree with central differences of x(u).
    for (double u : {0.1, 0.5, 0.9}) {
      // Named Eigen types, not auto: an auto expression would keep references to the temporaries
      // point(u +- 1e-6) past their lifetime (ASan: stack-use-after-scope).
      const Eigen::Vector3d a = f.curve->d1(u);
      const Eigen::Vector3d b = (f.curve->point(u + 1e-6) - f.curve->point(u - 1e-6)) / 2e-6;
      EXPECT_LT((a - b).norm(), 1e-6 * (1.0 + a.norm())) << name << " u=" << u;
    }
  }
  const CurveFile e = load_curve_file(CONTOUR_SOURCE_DIR "/config/programs/eq11.yaml");
  const auto p = e.curve->point(0.5);
  EXPECT_NEAR(p.x(), (1.5e5 * 0.25 - 1.5e5 * 0.5) * 0.0005, 1e-12);
  EXPECT_NEAR(p.y(), -2e4 * 0.5 * 0.0005, 1e-12);
}

TEST(CurveFile, NumericDerivativesWhenNoneGiven) {
  const CurveFile f = load_curve_string(
      "curve: {units: mm, u: [0, 2], x: 'cos(pi*u)', y: 'sin(pi*u)', z: 'u'}\n");
  const auto d = f.curve->d1(0.5);
  EXPECT_NEAR(d.x(), -M_PI, 1e-8);
  EXPECT_NEAR(d.z(), 1.0, 1e-8);
  EXPECT_DOUBLE_EQ(f.curve->u_end(), 2.0);
}

TEST(CurveFile, BadExpressionNamesFileLineKeyAndPosition) {
  const std::string e = error_of("curve:\n  u: [0, 1]\n  x: 'u +* 2'\n  y: 'v'\n  z: '0'\n");
  EXPECT_NE(e.find("k.yaml:3:6: curve.x: bad expression"), std::string::npos) << e;
  EXPECT_NE(e.find("k.yaml:4:6: curve.y: bad expression 'v'"), std::string::npos) << e;
}

TEST(CurveFile, StructuralErrors) {
  EXPECT_NE(error_of("curve:\n  u: [1, 0]\n  x: u\n  y: u\n  z: u\n").find("u_end > u_begin"),
            std::string::npos);
  EXPECT_NE(error_of("curve:\n  x: u\n  y: u\n").find("curve.z: required key is missing"),
            std::string::npos);
  EXPECT_NE(error_of("curve:\n  x: u\n  y: u\n  z: u\n  colour: red\n").find("unknown key"),
            std::string::npos);
  EXPECT_NE(error_of("curve:\n  x: sqrt(u-2)\n  y: u\n  z: u\n").find("not finite"),
            std::string::npos);
  EXPECT_NE(error_of("curve:\n  x: u\n  y: u\n  z: u\n  dx: '1'\n").find("dx, dy, dz"),
            std::string::npos);
}
