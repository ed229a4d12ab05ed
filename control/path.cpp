#include "control/path.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace contour::control {

namespace {
constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Angle of point q around the arc centre, in the plane.
double angle_of(const Eigen::Vector3d& q, const PathSegment& s, const PlaneAxes& ax) noexcept {
  return std::atan2(q[ax.b] - s.center[ax.b], q[ax.a] - s.center[ax.a]);
}
}  // namespace

PlaneAxes plane_axes(Plane p) noexcept {
  switch (p) {
    case Plane::kXY:
      return {0, 1, 2};
    case Plane::kZX:
      return {2, 0, 1};
    case Plane::kYZ:
      return {1, 2, 0};
  }
  return {0, 1, 2};
}

double arc_radius_mm(const PathSegment& s) noexcept {
  const PlaneAxes ax = plane_axes(s.plane);
  return std::hypot(s.start[ax.a] - s.center[ax.a], s.start[ax.b] - s.center[ax.b]);
}

double arc_sweep_rad(const PathSegment& s) noexcept {
  const PlaneAxes ax = plane_axes(s.plane);
  const double a0 = angle_of(s.start, s, ax);
  const double a1 = angle_of(s.end, s, ax);
  double d = s.ccw ? a1 - a0 : a0 - a1;
  while (d < 0.0) d += kTwoPi;
  while (d >= kTwoPi) d -= kTwoPi;
  // Same in-plane point: a full circle (RS274 reading of start == end).
  if (d < 1e-12) d = kTwoPi;
  return d + kTwoPi * s.turns;
}

double segment_length_mm(const PathSegment& s) noexcept {
  if (s.kind == PathSegment::Kind::kLine) return (s.end - s.start).norm();
  const PlaneAxes ax = plane_axes(s.plane);
  const double r = arc_radius_mm(s);
  const double h = s.end[ax.n] - s.start[ax.n];
  return std::hypot(r * arc_sweep_rad(s), h);
}

Eigen::Vector3d point_at(const PathSegment& s, double u) noexcept {
  if (s.kind == PathSegment::Kind::kLine) return s.start + u * (s.end - s.start);
  if (u >= 1.0) return s.end;
  const PlaneAxes ax = plane_axes(s.plane);
  const double r = arc_radius_mm(s);
  const double a0 = angle_of(s.start, s, ax);
  const double a = a0 + (s.ccw ? 1.0 : -1.0) * u * arc_sweep_rad(s);
  Eigen::Vector3d q;
  q[ax.a] = s.center[ax.a] + r * std::cos(a);
  q[ax.b] = s.center[ax.b] + r * std::sin(a);
  q[ax.n] = s.start[ax.n] + u * (s.end[ax.n] - s.start[ax.n]);
  return q;
}

double distance_point_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b) noexcept {
  const Eigen::Vector3d d = b - a;
  const double l2 = d.squaredNorm();
  if (l2 <= 0.0) return (p - a).norm();
  const double t = std::clamp((p - a).dot(d) / l2, 0.0, 1.0);
  return (p - (a + t * d)).norm();
}

double distance_point_polyline(const Eigen::Vector3d& p,
                               std::span<const Eigen::Vector3d> pts) noexcept {
  if (pts.empty()) return std::numeric_limits<double>::infinity();
  double best = (p - pts[0]).norm();
  for (std::size_t i = 1; i < pts.size(); ++i)
    best = std::min(best, distance_point_segment(p, pts[i - 1], pts[i]));
  return best;
}

double distance_to_segment(const Eigen::Vector3d& p, const PathSegment& s) noexcept {
  double u = 0.0;
  return closest_on_segment(p, s, u);
}

double closest_on_segment(const Eigen::Vector3d& p, const PathSegment& s, double& u) noexcept {
  if (s.kind == PathSegment::Kind::kLine) {
    const Eigen::Vector3d d = s.end - s.start;
    const double l2 = d.squaredNorm();
    u = l2 > 0.0 ? std::clamp((p - s.start).dot(d) / l2, 0.0, 1.0) : 0.0;
    return (p - (s.start + u * d)).norm();
  }
  const PlaneAxes ax = plane_axes(s.plane);
  const double r = arc_radius_mm(s);
  const double sweep = arc_sweep_rad(s);
  const double h = s.end[ax.n] - s.start[ax.n];
  const double sign = s.ccw ? 1.0 : -1.0;
  const double a0 = angle_of(s.start, s, ax);
  const double d_start = (p - s.start).norm(), d_end = (p - s.end).norm();
  double best = std::min(d_start, d_end);
  u = d_start <= d_end ? 0.0 : 1.0;
  if (std::abs(h) < 1e-12) {
    // Planar: the closest point is the radial projection if its angle lies in the swept range.
    const double dx = p[ax.a] - s.center[ax.a];
    const double dy = p[ax.b] - s.center[ax.b];
    const double rho = std::hypot(dx, dy);
    const double dn = p[ax.n] - s.start[ax.n];
    double rel = rho < 1e-15 ? 0.0 : sign * (std::atan2(dy, dx) - a0);
    rel = std::fmod(rel, kTwoPi);
    if (rel < 0.0) rel += kTwoPi;
    if (sweep >= kTwoPi - 1e-12 || rho < 1e-15) {
      // One turn or more: the radial projection on the first turn.
      u = rel / sweep;
      return std::hypot(rho - r, dn);
    }
    if (rel <= sweep) {
      const double dr = std::hypot(rho - r, dn);
      if (dr < best) {
        best = dr;
        u = rel / sweep;
      }
    }
    return best;
  }
  // Helix: g(phi) = |p - h(phi)|^2 / 2 over the swept angle. Near the helix (rho >= r / 2) every
  // local minimum lies within half a turn of a point with p's own in-plane angle (the radial term
  // dominates): Newton from each such candidate (one per turn) and the two ends. Near the axis
  // the radial term is flat: a scan of the whole sweep first (64 samples per turn).
  auto pos = [&](double phi) {
    Eigen::Vector3d q;
    const double a = a0 + sign * phi;
    q[ax.a] = s.center[ax.a] + r * std::cos(a);
    q[ax.b] = s.center[ax.b] + r * std::sin(a);
    q[ax.n] = s.start[ax.n] + h * phi / sweep;
    return q;
  };
  const double kz = h / sweep;
  double best_phi = u * sweep;
  auto newton = [&](double phi) {
    for (int it = 0; it < 30; ++it) {
      const double a = a0 + sign * phi;
      Eigen::Vector3d d1, d2;
      d1[ax.a] = -sign * r * std::sin(a);
      d1[ax.b] = sign * r * std::cos(a);
      d1[ax.n] = kz;
      d2[ax.a] = -r * std::cos(a);
      d2[ax.b] = -r * std::sin(a);
      d2[ax.n] = 0.0;
      const Eigen::Vector3d e = p - pos(phi);
      const double g1 = -e.dot(d1);
      const double g2 = d1.squaredNorm() - e.dot(d2);
      if (g2 <= 0.0) break;
      const double next = std::clamp(phi - g1 / g2, 0.0, sweep);
      if (std::abs(next - phi) < 1e-14) break;
      phi = next;
    }
    const double d = (p - pos(phi)).norm();
    if (d < best) {
      best = d;
      best_phi = phi;
    }
    return d;
  };
  const double rho = std::hypot(p[ax.a] - s.center[ax.a], p[ax.b] - s.center[ax.b]);
  if (rho >= 0.5 * r) {
    double rel = sign * (std::atan2(p[ax.b] - s.center[ax.b], p[ax.a] - s.center[ax.a]) - a0);
    rel = std::fmod(rel, kTwoPi);
    if (rel < 0.0) rel += kTwoPi;
    for (double phi = rel - kTwoPi; phi <= sweep + kTwoPi; phi += kTwoPi) {
      if (phi < -0.5 * kTwoPi || phi > sweep + 0.5 * kTwoPi) continue;
      newton(std::clamp(phi, 0.0, sweep));
    }
    newton(0.0);
    newton(sweep);
    u = best_phi / sweep;
    return best;
  }
  const int n = std::max(16, static_cast<int>(std::ceil(sweep / kTwoPi * 64.0)));
  double scan_phi = best_phi;
  double scan_d = best;
  for (int i = 0; i <= n; ++i) {
    const double phi = sweep * i / n;
    const double d = (p - pos(phi)).norm();
    if (d < scan_d) {
      scan_d = d;
      scan_phi = phi;
    }
  }
  if (scan_d < best) {
    best = scan_d;
    best_phi = scan_phi;
  }
  newton(scan_phi);
  u = best_phi / sweep;
  return best;
}

double distance_to_path(const Eigen::Vector3d& p, std::span<const PathSegment> path) noexcept {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& s : path) best = std::min(best, distance_to_segment(p, s));
  return best;
}

void chord_points(const PathSegment& s, double max_error_mm, std::vector<Eigen::Vector3d>& out) {
  if (s.kind == PathSegment::Kind::kLine) {
    out.push_back(s.end);
    return;
  }
  const double r = arc_radius_mm(s);
  const double sweep = arc_sweep_rad(s);
  // Sagitta r(1 - cos(dphi/2)) <= e  =>  dphi <= 2 acos(1 - e/r).
  double dphi = kTwoPi;
  if (max_error_mm < r) dphi = 2.0 * std::acos(1.0 - max_error_mm / r);
  const int n = std::max(2, static_cast<int>(std::ceil(sweep / std::max(dphi, 1e-9))));
  for (int i = 1; i < n; ++i) out.push_back(point_at(s, static_cast<double>(i) / n));
  out.push_back(s.end);
}

}  // namespace contour::control
