#include "control/contour_error.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

namespace contour::control {

namespace {

ThreePointFoot line_foot(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& p) noexcept {
  ThreePointFoot f;
  Vec3 dir = c - a;
  // a == c happens at a reversal (b is the turning point): the line through a and b.
  if (dir.norm() < ContourErrorModel::kMinSpacing_mm) dir = b - a;
  const double n = dir.norm();
  if (!(n >= ContourErrorModel::kMinSpacing_mm)) {
    f.k = b;
    f.branch = ContourBranch::kPoint;
    return f;
  }
  const Vec3 t = dir / n;
  f.k = b + t * (p - b).dot(t);
  f.tangent = t;
  f.branch = ContourBranch::kLine;
  return f;
}

}  // namespace

ThreePointFoot three_point_foot(const Vec3& a, const Vec3& b, const Vec3& c,
                                const Vec3& p) noexcept {
  // Circumcentre from the vectors to the third point (numerically better than solving eqs 1-2
  // as a linear system): centre = c + ((|u|^2 w - |w|^2 u) x n) / (2|n|^2), u = a-c, w = b-c.
  const Vec3 u = a - c;
  const Vec3 w = b - c;
  const Vec3 n = u.cross(w);
  const double chord = u.norm();
  const double n2 = n.squaredNorm();
  // Sagitta of b over the chord a-c: below 1e-9 mm the circle radius exceeds ~1e6 mm and the
  // centre loses digits; the line branch is then exact to < 1e-12 mm over a 1-mm window.
  if (chord < ContourErrorModel::kMinSpacing_mm ||
      std::sqrt(n2) / chord < ContourErrorModel::kCollinearSagitta_mm) {
    return line_foot(a, b, c, p);
  }
  const Vec3 centre = c + (u.squaredNorm() * w - w.squaredNorm() * u).cross(n) / (2.0 * n2);
  const double rho = (a - centre).norm();
  const Vec3 nhat = n / std::sqrt(n2);
  const Vec3 h = p - nhat * (p - centre).dot(nhat);  // eq 3: projection of P on the plane
  const Vec3 hc = h - centre;
  const double dist = hc.norm();
  ThreePointFoot f;
  f.radius_mm = rho;
  f.centre = centre;
  f.plane_normal = nhat;
  f.branch = ContourBranch::kCircle;
  Vec3 radial;
  if (dist < 1e-12 * (1.0 + rho)) {
    // P on the circle's axis: every circle point is equally near; take the window centre.
    f.k = b;
    radial = (b - centre) / rho;
  } else {
    // eqs 5-6 with the root nearer to P: t = 1 - rho/|HC| -> K = C + rho (H - C)/|H - C|.
    radial = hc / dist;
    f.k = centre + rho * radial;
  }
  Vec3 t = nhat.cross(radial);
  if (t.dot(c - a) < 0.0) t = -t;
  f.tangent = t;
  return f;
}

Vec3 eps_on(const ContourErrorResult& g, const Vec3& q) noexcept {
  switch (g.branch) {
    case ContourBranch::kCircle: {
      const Vec3 h = q - g.plane_normal * (q - g.centre).dot(g.plane_normal);
      const Vec3 hc = h - g.centre;
      const double dist = hc.norm();
      if (!(dist > 1e-12 * (1.0 + g.radius_mm))) return g.k_point - q;
      return g.centre + g.radius_mm * hc / dist - q;
    }
    case ContourBranch::kLine:
      return g.k_point + g.tangent * (q - g.k_point).dot(g.tangent) - q;
    case ContourBranch::kPoint:
      break;
  }
  return g.k_point - q;
}

void ContourErrorModel::configure(const ContourErrorParams& p) {
  if (p.window_capacity < 4) {
    throw std::invalid_argument("contour error model: window_capacity must be >= 4");
  }
  p_ = p;
  std::size_t slots = 4;
  while (slots < static_cast<std::size_t>(p.window_capacity)) slots *= 2;
  ring_.assign(slots, Vec3::Zero());
  mask_ = slots - 1;
  reset();
}

void ContourErrorModel::reset() noexcept {
  oldest_ = 0;
  newest_ = -1;
  centre_ = 0;
  overflow_ = false;
}

void ContourErrorModel::push_reference(const Vec3& r_mm) noexcept {
  if (!r_mm.allFinite()) return;
  if (newest_ >= oldest_ && (r_mm - at(newest_)).norm() < kMinSpacing_mm) return;
  ++newest_;
  ring_[static_cast<std::size_t>(newest_) & mask_] = r_mm;
  if (newest_ - oldest_ + 1 > static_cast<std::int64_t>(p_.window_capacity)) {
    ++oldest_;
    // The window lost its first point: the lag exceeds the capacity. Force it forward.
    if (centre_ - 1 < oldest_) {
      overflow_ = true;
      centre_ = oldest_ + 1;
    }
  }
}

ContourErrorResult ContourErrorModel::update(const Vec3& p_mm) noexcept {
  ContourErrorResult r;
  if (newest_ < oldest_ || !p_mm.allFinite()) {
    r.status = ContourStatus::kNoReference;
    return r;
  }
  switch (p_.kind) {
    case ModelKind::kNearestPoint:
      r = nearest_model(p_mm);
      break;
    case ModelKind::kLinear:
      r = linear_model(p_mm);
      break;
    case ModelKind::kCircle:
      r = circle_model(p_mm);
      break;
  }
  r.status = overflow_ ? ContourStatus::kLagOverflow : ContourStatus::kOk;
  overflow_ = false;
  return r;
}

ContourErrorResult ContourErrorModel::circle_model(const Vec3& p) noexcept {
  ContourErrorResult r;
  const std::int64_t n = newest_ - oldest_ + 1;
  if (n == 1) {
    r.k_point = at(newest_);
    r.eps = r.k_point - p;
    r.branch = ContourBranch::kPoint;
    return r;
  }
  if (n == 2) {
    const ThreePointFoot f = three_point_foot(at(oldest_), at(oldest_), at(newest_), p);
    r.k_point = f.k;
    r.tangent = f.tangent;
    r.branch = f.branch;
    r.eps = f.k - p;
    r.lag_points = 1;
    return r;
  }
  // Valid centres: oldest+1 .. newest-1.
  if (centre_ < oldest_ + 1) centre_ = oldest_ + 1;
  if (centre_ > newest_ - 1) centre_ = newest_ - 1;
  // eq 8, tested with the current P. Multi-step: repeat until the next point is no nearer.
  while (centre_ + 1 <= newest_ - 1 && (p - at(centre_ + 1)).squaredNorm() <
                                           (p - at(centre_)).squaredNorm()) {
    ++centre_;
    if (p_.rule == WindowRule::kLiteral) break;
  }
  if (p_.rule == WindowRule::kMultiStep) {
    // Bounded look-ahead over the lag region (up to the newest point): eq 8 stops at the first local minimum of |P - R|
    // along the points, which at a sharp corner (tool cutting it) or a reversal is not the nearest
    // point ahead. On smooth paths this never moves the window (the distance is unimodal there).
    double best = (p - at(centre_)).squaredNorm();
    std::int64_t best_i = centre_;
    for (std::int64_t i = centre_ + 1; i <= newest_; ++i) {
      const double d2 = (p - at(i)).squaredNorm();
      if (d2 < best) {
        best = d2;
        best_i = i;
      }
    }
    centre_ = best_i < newest_ ? best_i : newest_ - 1;  // the newest point: last full window
  }
  const ThreePointFoot f = three_point_foot(at(centre_ - 1), at(centre_), at(centre_ + 1), p);
  r.k_point = f.k;
  r.tangent = f.tangent;
  r.radius_mm = f.radius_mm;
  r.centre = f.centre;
  r.plane_normal = f.plane_normal;
  r.branch = f.branch;
  r.eps = f.k - p;
  r.lag_points = static_cast<int>(newest_ - centre_);
  return r;
}

ContourErrorResult ContourErrorModel::nearest_model(const Vec3& p) const noexcept {
  ContourErrorResult r;
  std::int64_t best = newest_;
  double best_d2 = (p - at(newest_)).squaredNorm();
  for (std::int64_t i = newest_ - 1; i >= oldest_; --i) {
    const double d2 = (p - at(i)).squaredNorm();
    if (d2 < best_d2) {
      best_d2 = d2;
      best = i;
    }
  }
  r.k_point = at(best);
  r.eps = r.k_point - p;
  r.branch = ContourBranch::kPoint;
  r.lag_points = static_cast<int>(newest_ - best);
  if (best > oldest_) {
    const Vec3 d = at(best) - at(best - 1);
    r.tangent = d / d.norm();  // stored neighbours are >= kMinSpacing_mm apart
  }
  return r;
}

ContourErrorResult ContourErrorModel::linear_model(const Vec3& p) const noexcept {
  ContourErrorResult r;
  const Vec3& rk = at(newest_);
  const Vec3 e = rk - p;
  r.branch = ContourBranch::kPoint;
  r.eps = e;
  r.k_point = rk;
  if (newest_ > oldest_) {
    const Vec3 d = rk - at(newest_ - 1);
    const Vec3 t = d / d.norm();
    r.tangent = t;
    r.eps = e - t * e.dot(t);
    r.k_point = p + r.eps;
    r.branch = ContourBranch::kLine;
  }
  return r;
}

}  // namespace contour::control
