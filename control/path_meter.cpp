#include "control/path_meter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace contour::control {

namespace {
using Eigen::Vector3d;

// Unit tangent at the start (u = 0) or end (u = 1) of a segment.
Vector3d tangent(const PathSegment& s, double u) {
  if (s.kind == PathSegment::Kind::kLine) return (s.end - s.start).normalized();
  const double du = 1e-6;
  const double a = std::clamp(u - du, 0.0, 1.0), b = std::clamp(u + du, 0.0, 1.0);
  return (point_at(s, b) - point_at(s, a)).normalized();
}
// Upper bound of the distance to a planar arc over the output chord [x0, x1] (length l), given
// the distances d0, d1 at its ends: when every point of the chord lies in the arc's swept range
// the distance is hypot(|rho - r|, dn) with rho (distance to the arc's axis) convex along the
// chord and dn linear; otherwise (or for helices) only the 1-Lipschitz bound holds.
double arc_bound(const PathSegment& s, const Vector3d& x0, const Vector3d& x1, double d0, double d1,
                 double l) {
  const double lip = 0.5 * (d0 + d1 + l);
  const PlaneAxes ax = plane_axes(s.plane);
  if (std::abs(s.end[ax.n] - s.start[ax.n]) > 1e-12) return lip;
  const double r = arc_radius_mm(s);
  const double sweep = arc_sweep_rad(s);
  const double cx = s.center[ax.a], cy = s.center[ax.b];
  const double ax0 = x0[ax.a] - cx, ay0 = x0[ax.b] - cy, ax1 = x1[ax.a] - cx, ay1 = x1[ax.b] - cy;
  if (sweep < 2.0 * std::numbers::pi - 1e-12) {
    const double a0 = std::atan2(s.start[ax.b] - cy, s.start[ax.a] - cx);
    const double sign = s.ccw ? 1.0 : -1.0;
    auto rel = [&](double x, double y) {
      double t = sign * (std::atan2(y, x) - a0);
      t = std::fmod(t, 2.0 * std::numbers::pi);
      if (t < 0.0) t += 2.0 * std::numbers::pi;
      return t;
    };
    const double r0 = rel(ax0, ay0), r1 = rel(ax1, ay1);
    if (r0 > sweep || r1 > sweep || std::abs(r0 - r1) >= std::numbers::pi) return lip;
  }
  const double rho0 = std::hypot(ax0, ay0), rho1 = std::hypot(ax1, ay1);
  // Distance from the axis to the chord in the plane (the smallest rho on it).
  const double ex = ax1 - ax0, ey = ay1 - ay0;
  const double e2 = ex * ex + ey * ey;
  double rho_min = std::min(rho0, rho1);
  if (e2 > 0.0) {
    const double t = std::clamp(-(ax0 * ex + ay0 * ey) / e2, 0.0, 1.0);
    rho_min = std::hypot(ax0 + t * ex, ay0 + t * ey);
  }
  const double dr = std::max(r - rho_min, std::max(rho0, rho1) - r);
  const double dn = std::max(std::abs(x0[ax.n] - s.start[ax.n]), std::abs(x1[ax.n] - s.start[ax.n]));
  return std::min(lip, std::hypot(std::max(dr, 0.0), dn));
}
}  // namespace

PathMeter::PathMeter(double period_s, double reach_mm, int accel_avg_periods, double cursor_slack_mm)
    : T_(period_s), reach_(reach_mm), slack_(cursor_slack_mm), avg_(accel_avg_periods) {
  if (!(period_s > 0.0) || !(reach_mm > 0.0) || accel_avg_periods < 1 || !(cursor_slack_mm >= 0.0))
    throw std::invalid_argument("PathMeter: period, reach and averaging must be > 0");
}

void PathMeter::add_segment(const PathSegment& s, int line) {
  const double len = segment_length_mm(s);
  if (!(len > 1e-9)) return;
  if (!segs_.empty()) {
    // The previous segment's end is a vertex when the path turns there.
    Seg& pr = segs_.back();
    const double c = tangent(pr.seg, 1.0).dot(tangent(s, 0.0));
    pr.vertex = c < 1.0 - 1e-12;
  }
  segs_.push_back({s, line, s_total_, s_total_ + len, false});
  s_total_ += len;
  r_.length_mm = s_total_;
  window();
}

double PathMeter::dist(const Vector3d& x, std::size_t* arg) const {
  double best = 1e300;
  for (std::size_t i = w0_; i < w1_; ++i) {
    const double d = distance_to_segment(x, segs_[i].seg);
    if (d < best) {
      best = d;
      if (arg != nullptr) *arg = i;
    }
  }
  return best;
}

void PathMeter::window() {
  if (segs_.empty()) return;
  const double sc = segs_[cursor_].s0;
  const double se = segs_[cursor_].s1;
  w0_ = cursor_;
  while (w0_ > 0 && segs_[w0_ - 1].s1 >= sc - reach_) --w0_;
  w1_ = cursor_ + 1;
  while (w1_ < segs_.size() && segs_[w1_].s0 <= se + reach_) ++w1_;
  // At least two segments on each side whatever their lengths: a long segment next to the
  // cursor (a Z plunge or retract before a rapid) must not hide the one after it.
  w0_ = std::min(w0_, cursor_ >= 2 ? cursor_ - 2 : std::size_t{0});
  w1_ = std::max(w1_, std::min(segs_.size(), cursor_ + 3));
}

double PathMeter::progress_mm(const Vector3d& x, const PathSegment& s, double ref_mm) {
  const double len = segment_length_mm(s);
  if (s.kind == PathSegment::Kind::kLine) return (x - s.start).dot(s.end - s.start) / len;
  const PlaneAxes ax = plane_axes(s.plane);
  const double r = arc_radius_mm(s);
  const double dx = x[ax.a] - s.center[ax.a], dy = x[ax.b] - s.center[ax.b];
  if (std::hypot(dx, dy) < 0.5 * r) return std::numeric_limits<double>::quiet_NaN();
  const double sweep = arc_sweep_rad(s);
  const double a0 = std::atan2(s.start[ax.b] - s.center[ax.b], s.start[ax.a] - s.center[ax.a]);
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  double rel = (s.ccw ? 1.0 : -1.0) * (std::atan2(dy, dx) - a0);
  rel = std::fmod(rel, kTwoPi);
  if (rel < 0.0) rel += kTwoPi;
  const double ref = ref_mm / len * sweep;
  const double phi = rel + kTwoPi * std::round((ref - rel) / kTwoPi);
  return phi / sweep * len;
}

void PathMeter::add_sample(const Vector3d& p) {
  const std::int64_t n = r_.samples++;
  // Kinematics.
  hist_.push_back(p);
  if (hist_.size() > static_cast<std::size_t>(avg_) + 2) hist_.pop_front();
  if (hist_.size() >= 2) {
    const Vector3d v = (hist_[hist_.size() - 1] - hist_[hist_.size() - 2]) / T_;
    r_.peak_speed_mm_s = std::max(r_.peak_speed_mm_s, v.norm());
    if (v.norm() > 1e-9) {
      if (first_move_ < 0) first_move_ = n - 1;
      last_move_ = n;
    }
    if (hist_.size() >= 3) {
      const Vector3d v0 = (hist_[hist_.size() - 2] - hist_[hist_.size() - 3]) / T_;
      r_.peak_accel_raw_mm_s2 = r_.peak_accel_raw_mm_s2.cwiseMax(((v - v0) / T_).cwiseAbs());
    }
    if (hist_.size() == static_cast<std::size_t>(avg_) + 2) {
      const Vector3d va = (hist_[1] - hist_[0]) / T_;
      const double span = avg_ * T_;
      r_.peak_accel_mm_s2 = r_.peak_accel_mm_s2.cwiseMax(((v - va) / span).cwiseAbs());
    }
  }
  if (segs_.empty()) {
    prev_ = p;
    have_prev_ = true;
    return;
  }
  // Cursor: nearest segment of the window to this sample.
  // The cursor only moves forward: to the EARLIEST segment from the cursor on whose distance is
  // within cursor_slack_mm of the nearest one, so a later pass over the same place (stacked circles, a
  // second lap, a full circle starting where the last one ended) never takes it early, and the
  // segments behind it stay in the window for the error.
  std::size_t arg = cursor_;
  {
    // Has the tool left the cursor's segment (past its end, or back along it)?
    std::size_t from = cursor_;
    const Seg& cs = segs_[cursor_];
    const double pr = progress_mm(p, cs.seg, cursor_progress_mm_);
    if (std::isfinite(pr)) {
      if ((pr < cursor_progress_mm_ - slack_ || pr > cs.s1 - cs.s0 + slack_) && cursor_ + 1 < w1_)
        from = cursor_ + 1;
      else
        cursor_progress_mm_ = std::max(cursor_progress_mm_, std::min(pr, cs.s1 - cs.s0));
    }
    double dmin = 1e300;
    for (std::size_t i = from; i < w1_; ++i) dmin = std::min(dmin, distance_to_segment(p, segs_[i].seg));
    for (std::size_t i = from; i < w1_; ++i) {
      if (distance_to_segment(p, segs_[i].seg) <= dmin + slack_) {
        arg = i;
        break;
      }
    }
  }
  if (arg != cursor_) {
    cursor_ = arg;
    cursor_progress_mm_ = std::max(0.0, progress_mm(p, segs_[cursor_].seg, 0.0));
    if (!std::isfinite(cursor_progress_mm_)) cursor_progress_mm_ = 0.0;
    window();
  }
  const double dp = dist(p, nullptr);
  if (!have_prev_) {
    prev_ = p;
    have_prev_ = true;
    last_err_ = dp;
    if (dp > r_.max_path_error_mm) {
      r_.max_path_error_mm = dp;
      r_.worst_sample = n;
      r_.worst_point_mm = p;
      r_.worst_line = segs_[cursor_].line;
    }
    return;
  }
  // Branch and bound on the output chord [prev, p]. Bound of min_k d_k on an interval: for a
  // line segment d_k is convex along the chord (<= the larger end value); for an arc (helix
  // too), with u_a, u_b the swept fractions of the closest points at the ends, every point of the
  // interval is within max(d_a, d_b) + r dphi^2 / 8 of the arc point at the interpolated angle
  // (dphi = |u_b - u_a| sweep); it is also 1-Lipschitz ((d_a + d_b + l) / 2) and, planar, the
  // radial bound of arc_bound(). Intervals that cannot beat the maximum by more than
  // max(1 nm, 1e-4 of it) are dropped.
  const Vector3d a = prev_;
  const std::size_t nw = w1_ - w0_;
  const double len = (p - a).norm();
  pool_.clear();
  upool_.clear();
  tpar_.clear();
  double m = 0.0;
  Vector3d where = p;
  auto eval = [&](double t) {
    const Vector3d x = a + t * (p - a);
    const std::size_t idx = tpar_.size();
    tpar_.push_back(t);
    double best = 1e300;
    for (std::size_t i = w0_; i < w1_; ++i) {
      double u = 0.0;
      const double d = closest_on_segment(x, segs_[i].seg, u);
      pool_.push_back(d);
      upool_.push_back(u);
      best = std::min(best, d);
    }
    if (best > m) {
      m = best;
      where = x;
    }
    return idx;
  };
  auto bound = [&](std::size_t i0, std::size_t i1) {
    const double l = (tpar_[i1] - tpar_[i0]) * len;
    double ub = 1e300;
    for (std::size_t k = 0; k < nw; ++k) {
      const double d0 = pool_[i0 * nw + k], d1 = pool_[i1 * nw + k];
      const PathSegment& sg = segs_[w0_ + k].seg;
      if (sg.kind == PathSegment::Kind::kLine) {
        ub = std::min(ub, std::max(d0, d1));
      } else if (std::min(d0, d1) < ub) {
        // Along the chord, the arc point at the interpolated angle: the chord of the arc between
        // the two closest points deviates from the arc by at most r dphi^2 / 8 (|h''| = r).
        const double dphi = std::abs(upool_[i1 * nw + k] - upool_[i0 * nw + k]) * arc_sweep_rad(sg);
        const double r = arc_radius_mm(sg);
        ub = std::min(ub, std::max(d0, d1) + r * dphi * dphi / 8.0);
        if (std::min(d0, d1) < ub)
          ub = std::min(ub, arc_bound(sg, a + tpar_[i0] * (p - a), a + tpar_[i1] * (p - a), d0, d1, l));
      }
    }
    return ub;
  };
  const std::size_t i0 = eval(0.0), i1 = eval(1.0);
  struct Iv {
    std::size_t a, b;
  };
  Iv stack[128];
  int top = 0;
  stack[top++] = {i0, i1};
  while (top > 0) {
    const Iv iv = stack[--top];
    const double l = (tpar_[iv.b] - tpar_[iv.a]) * len;
    if (l < 1e-9 || top >= 126) continue;
    if (bound(iv.a, iv.b) <= m + std::max(1e-6, 1e-4 * m)) continue;
    const std::size_t mid = eval(0.5 * (tpar_[iv.a] + tpar_[iv.b]));
    stack[top++] = {iv.a, mid};
    stack[top++] = {mid, iv.b};
  }
  last_err_ = m;
  last_line_ = segs_[cursor_].line;
  if (m > r_.max_path_error_mm) {
    r_.max_path_error_mm = m;
    r_.worst_sample = n;
    r_.worst_point_mm = where;
    r_.worst_line = segs_[cursor_].line;
  }
  // Vertices in the window: distance to this output chord.
  for (std::size_t i = w0_; i < w1_; ++i) {
    Seg& s = segs_[i];
    if (!s.vertex || s.vdone) continue;
    s.vbest = std::min(s.vbest, distance_point_segment(s.seg.end, a, p));
  }
  // Segments far behind the cursor are done: close their vertices, drop them.
  const double s_here = segs_[cursor_].s0;
  while (!segs_.empty() && cursor_ > 0 && segs_.front().s1 < s_here - 2.0 * reach_) {
    Seg& s = segs_.front();
    if (s.vertex && !s.vdone) {
      ++r_.vertices;
      if (s.vbest > r_.max_vertex_error_mm) {
        r_.max_vertex_error_mm = s.vbest;
        r_.worst_vertex_mm = s.seg.end;
        r_.worst_vertex_line = s.line;
      }
    }
    segs_.pop_front();
    --cursor_;
    if (w0_ > 0) --w0_;
    if (w1_ > 0) --w1_;
  }
  prev_ = p;
}

void PathMeter::finish() {
  for (auto& s : segs_) {
    if (!s.vertex || s.vdone) continue;
    s.vdone = true;
    ++r_.vertices;
    if (s.vbest > r_.max_vertex_error_mm) {
      r_.max_vertex_error_mm = s.vbest;
      r_.worst_vertex_mm = s.seg.end;
      r_.worst_vertex_line = s.line;
    }
  }
  if (first_move_ >= 0) r_.duration_s = static_cast<double>(last_move_ - first_move_) * T_;
}

}  // namespace contour::control
