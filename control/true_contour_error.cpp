#include "control/true_contour_error.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace contour::control {

CurveDistance::CurveDistance(const ParametricCurve& curve, int table_points) : c_(curve) {
  if (table_points < 16) throw std::invalid_argument("curve distance: table_points < 16");
  const double u0 = c_.u_begin();
  const double u1 = c_.u_end();
  u_.resize(static_cast<std::size_t>(table_points));
  x_.resize(u_.size());
  for (std::size_t i = 0; i < u_.size(); ++i) {
    u_[i] = u0 + (u1 - u0) * static_cast<double>(i) / static_cast<double>(u_.size() - 1);
    x_[i] = c_.point(u_[i]);
  }
}

TrueError CurveDistance::query(const Vec3& p) const noexcept {
  return query(p, std::numeric_limits<double>::quiet_NaN());
}

TrueError CurveDistance::query(const Vec3& p, double hint_u) const noexcept {
  const auto n = static_cast<std::ptrdiff_t>(u_.size());
  std::ptrdiff_t lo_i = 0, hi_i = n - 1;
  const double span = u_.back() - u_.front();
  if (std::isfinite(hint_u)) {
    const auto h = static_cast<std::ptrdiff_t>((hint_u - u_.front()) / span * static_cast<double>(n - 1));
    lo_i = std::max<std::ptrdiff_t>(0, h - 300);
    hi_i = std::min<std::ptrdiff_t>(n - 1, h + 300);
  }
  auto best_in = [&](std::ptrdiff_t a, std::ptrdiff_t b) {
    std::ptrdiff_t best = a;
    double bd = (x_[static_cast<std::size_t>(a)] - p).squaredNorm();
    for (std::ptrdiff_t i = a + 1; i <= b; ++i) {
      const double d = (x_[static_cast<std::size_t>(i)] - p).squaredNorm();
      if (d < bd) {
        bd = d;
        best = i;
      }
    }
    return best;
  };
  std::ptrdiff_t best = best_in(lo_i, hi_i);
  // A hint window whose best point is on its own border may be hiding a nearer part: go global.
  if ((best == lo_i && lo_i > 0) || (best == hi_i && hi_i < n - 1)) best = best_in(0, n - 1);

  auto gprime = [&](double u) { return (c_.point(u) - p).dot(c_.d1(u)); };
  double lo = u_[static_cast<std::size_t>(std::max<std::ptrdiff_t>(best - 1, 0))];
  double hi = u_[static_cast<std::size_t>(std::min<std::ptrdiff_t>(best + 1, n - 1))];
  double glo = gprime(lo);
  double ghi = gprime(hi);
  double u;
  if (glo >= 0.0 && ghi >= 0.0) {
    u = lo;  // increasing distance over the bracket: minimum at its start (path start)
  } else if (glo <= 0.0 && ghi <= 0.0) {
    u = hi;
  } else if (glo > 0.0) {
    // g' goes + to -: a local maximum of the distance in the bracket; take the better end.
    u = (c_.point(lo) - p).squaredNorm() < (c_.point(hi) - p).squaredNorm() ? lo : hi;
  } else {
    u = u_[static_cast<std::size_t>(best)];
    for (int it = 0; it < 60; ++it) {
      const Vec3 x = c_.point(u);
      const Vec3 x1 = c_.d1(u);
      const Vec3 x2 = c_.d2(u);
      const double g1 = (x - p).dot(x1);
      const double g2 = x1.squaredNorm() + (x - p).dot(x2);
      if (g1 < 0.0) {
        lo = u;
      } else {
        hi = u;
      }
      double next = (g2 > 0.0) ? u - g1 / g2 : 0.5 * (lo + hi);
      if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
      const bool done = std::abs(next - u) <= 1e-15 * span || hi - lo <= 1e-15 * span;
      u = next;
      if (done) break;
    }
  }
  TrueError r;
  r.u = u;
  r.foot = c_.point(u);
  r.distance_mm = (r.foot - p).norm();
  if (u >= u_.back()) r.beyond_end = (p - r.foot).dot(c_.d1(u)) > 0.0;
  return r;
}

SegmentPathDistance::SegmentPathDistance(std::vector<PathSegment> segments)
    : segs_(std::move(segments)) {
  if (segs_.empty()) throw std::invalid_argument("segment path distance: no segments");
}

TrueError SegmentPathDistance::query(const Vec3& p) const noexcept {
  TrueError r;
  double best = std::numeric_limits<double>::infinity();
  std::size_t best_i = 0;
  for (std::size_t i = 0; i < segs_.size(); ++i) {
    const double d = distance_to_segment(p, segs_[i]);
    if (d < best) {
      best = d;
      best_i = i;
    }
  }
  r.distance_mm = best;
  r.u = static_cast<double>(best_i);
  const PathSegment& last = segs_.back();
  if (best_i == segs_.size() - 1) {
    // Beyond the end: P past the end point along the end tangent (numeric tangent: lines exact,
    // arcs from the last 1e-6 of the sweep).
    const Vec3 t = last.end - point_at(last, 1.0 - 1e-6);
    r.beyond_end = (p - last.end).dot(t) > 0.0 && std::abs((p - last.end).norm() - best) < 1e-12;
  }
  return r;
}

std::vector<PathSegment> polyline_segments(std::span<const Vec3> vertices) {
  std::vector<PathSegment> out;
  for (std::size_t i = 1; i < vertices.size(); ++i) {
    if ((vertices[i] - vertices[i - 1]).norm() < 1e-12) continue;
    out.push_back(PathSegment::line(vertices[i - 1], vertices[i]));
  }
  return out;
}

}  // namespace contour::control
