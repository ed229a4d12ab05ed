#include "control/reference_path.hpp"

#include <cmath>
#include <stdexcept>

namespace contour::control {

namespace {
double step_h(const ParametricCurve& c) {
  return 1e-5 * std::max(1.0, std::abs(c.u_end() - c.u_begin()));
}
}  // namespace

Vec3 ParametricCurve::d1(double u) const {
  const double h = step_h(*this);
  return (point(u + h) - point(u - h)) / (2.0 * h);
}

Vec3 ParametricCurve::d2(double u) const {
  // Larger step than d1: the rounding error of the second difference grows like eps/h^2.
  const double h = 1e2 * step_h(*this);
  return (point(u + h) - 2.0 * point(u) + point(u - h)) / (h * h);
}

std::vector<ReferencePoint> sample_curve(const ParametricCurve& c, double feed_mm_s,
                                         double period_s) {
  if (!(feed_mm_s > 0.0) || !(period_s > 0.0)) {
    throw std::invalid_argument("reference path: feed and period must be > 0");
  }
  const double ds = feed_mm_s * period_s;
  const double u0 = c.u_begin();
  const double u1 = c.u_end();
  const double span = u1 - u0;
  if (!(span > 0.0)) throw std::invalid_argument("reference path: empty u range");
  std::vector<ReferencePoint> out;
  double u = u0;
  Vec3 prev = c.point(u);
  out.push_back({prev, Vec3::Zero(), u});
  for (;;) {
    const Vec3 x1 = c.d1(u);
    const Vec3 x2 = c.d2(u);
    const double sp = x1.norm();
    double du;
    if (sp > 1e-12) {
      const double spp = x1.dot(x2) / sp;
      const double du1 = ds / sp;
      du = du1 - 0.5 * spp * du1 * du1 / sp;
      // The second-order term only corrects; never let it reverse or double the step.
      if (!(du > 0.25 * du1) || du > 4.0 * du1) du = du1;
    } else {
      // Singular point (|x'| = 0): second-order start ds = |x''| du^2 / 2.
      const double n2 = x2.norm();
      if (n2 < 1e-12) throw std::invalid_argument("reference path: curve has zero speed");
      du = std::sqrt(2.0 * ds / n2);
    }
    if (u + du >= u1 - 1e-12 * span) {
      const Vec3 end = c.point(u1);
      if ((end - prev).norm() > 1e-9) out.push_back({end, (end - prev) / period_s, u1});
      break;
    }
    u += du;
    const Vec3 x = c.point(u);
    out.push_back({x, (x - prev) / period_s, u});
    prev = x;
    if (out.size() > 50'000'000) throw std::invalid_argument("reference path: too many points");
  }
  return out;
}

std::vector<ReferencePoint> sample_polyline(const std::vector<Vec3>& vertices, double feed_mm_s,
                                            double period_s) {
  if (!(feed_mm_s > 0.0) || !(period_s > 0.0)) {
    throw std::invalid_argument("reference path: feed and period must be > 0");
  }
  std::vector<ReferencePoint> out;
  if (vertices.empty()) return out;
  const double ds = feed_mm_s * period_s;
  out.push_back({vertices[0], Vec3::Zero(), 0.0});
  double s = 0.0;
  for (std::size_t i = 1; i < vertices.size(); ++i) {
    const Vec3 a = vertices[i - 1];
    const Vec3 d = vertices[i] - a;
    const double len = d.norm();
    if (len < 1e-9) continue;
    const auto n = static_cast<long>(std::ceil(len / ds - 1e-9));
    const Vec3 v = d / len * (len / static_cast<double>(n)) / period_s;
    for (long j = 1; j <= n; ++j) {
      const double f = static_cast<double>(j) / static_cast<double>(n);
      out.push_back({j == n ? vertices[i] : Vec3(a + f * d), v, s + f * len});
    }
    s += len;
  }
  return out;
}

}  // namespace contour::control
