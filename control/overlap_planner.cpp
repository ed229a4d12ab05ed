#include "control/overlap_planner.hpp"

#include <stdexcept>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace contour::control {

namespace {
double line_distance(const Eigen::Vector3d& x, const Eigen::Vector3d& p, const Eigen::Vector3d& u) {
  const Eigen::Vector3d r = x - p;
  return (r - r.dot(u) * u).norm();
}
}  // namespace

OverlapPlanner::OverlapPlanner(const PlannerParams& p, const Eigen::Vector3d& start_mm)
    : p_(p), pos_(start_mm) {
  if (!(p.period_s > 0.0)) throw std::invalid_argument("planner period must be > 0");
  if (!(p.arc_chord_fraction > 0.0 && p.arc_chord_fraction < 1.0))
    throw std::invalid_argument("arc_chord_fraction must be in (0, 1)");
  fir_.configure(p.fir_taps, p.fir2_taps);
  tail_ = fir_.length() - 1;
}

bool OverlapPlanner::pop(PlannedSegment& out) {
  if (out_.empty()) return false;
  out = out_.front();
  out_.pop_front();
  return true;
}

void OverlapPlanner::push(const Block& b) {
  if (ended_) return;
  switch (b.kind) {
    case BlockKind::kMotion: {
      // A feed move after a spindle start or speed change waits, at an exact stop, until the
      // spindle is at speed (rapids do not cut: they run while the spindle accelerates).
      if (!b.rapid && b.spindle != SpindleDir::kOff &&
          (b.spindle != synced_spindle_ || b.spindle_rpm != synced_rpm_)) {
        barrier(SegmentKind::kSpindleSync, "", b, 0.0);
        synced_spindle_ = b.spindle;
        synced_rpm_ = b.spindle_rpm;
      }
      if (b.spindle == SpindleDir::kOff) synced_spindle_ = SpindleDir::kOff;
      const BlendMode mode = p_.force_mode.value_or(b.blend);
      double tol = p_.force_tolerance_mm.value_or(mode == BlendMode::kLimited ? b.tolerance_mm : p_.default_tolerance_mm);
      if (mode == BlendMode::kLimited && b.tolerance_mm <= 0.0 && !p_.force_tolerance_mm) tol = p_.default_tolerance_mm;
      if (b.seg.kind == PathSegment::Kind::kLine) {
        add_move(b, pos_, b.seg.end, 0.0);
      } else {
        const double chord_err = p_.arc_chord_fraction * tol;
        chord_buf_.clear();
        chord_points(b.seg, chord_err, chord_buf_);
        Eigen::Vector3d a = pos_;
        for (const auto& e : chord_buf_) {
          add_move(b, a, e, chord_err);
          a = e;
        }
      }
      pos_ = b.seg.end;
      break;
    }
    case BlockKind::kDwell:
      if (b.user_m != 0) {
        // M100..M199: a hold marker the loop hands to the machine logic (or passes at once).
        barrier(SegmentKind::kUserMcode, "", b, b.dwell_s);
      } else {
        barrier(SegmentKind::kMotion, "", b, b.dwell_s);
      }
      break;
    case BlockKind::kProgramStop:
      barrier(SegmentKind::kHold, b.message, b, 0.0);
      break;
    case BlockKind::kToolChange:
      barrier(SegmentKind::kToolChange, b.message, b, 0.0);
      break;
    case BlockKind::kOptionalStop:
      barrier(SegmentKind::kOptionalHold, b.message, b, 0.0);
      break;
    case BlockKind::kEnd:
      barrier(SegmentKind::kEnd, "", b, 0.0);
      ended_ = true;
      break;
    default:  // a kind this planner does not know: exact stop, nothing else
      barrier(SegmentKind::kMotion, "", b, 0.0);
      break;
  }
}

void OverlapPlanner::barrier(SegmentKind kind, const std::string& msg, const Block& b, double extra_s) {
  std::int64_t t_stop = earliest_start_;
  if (!win_.empty()) t_stop = std::max(t_stop, win_.back().finish(tail_));
  if (kind != SegmentKind::kMotion) {
    PlannedSegment s;
    s.kind = kind;
    s.start_cycle = t_stop;
    s.start_mm = s.end_mm = pos_;
    s.line = b.line;
    s.path_start_mm = path_mm_;
    s.spindle = b.spindle;
    s.spindle_rpm = b.spindle_rpm;
    s.mist = b.mist;
    s.flood = b.flood;
    s.tool = b.tool;
    s.user_m = b.user_m;
    s.user_p = b.user_p;
    s.user_q = b.user_q;
    if (!msg.empty()) {
      messages_.push_back(msg);
      s.message_id = static_cast<int>(messages_.size()) - 1;
    }
    out_.push_back(s);
  }
  earliest_start_ = t_stop + static_cast<std::int64_t>(std::ceil(extra_s / p_.period_s - 1e-9));
  stop_before_next_ = true;
  // The path stops exactly on the last vertex: nothing before it can change any more.
  vtx_.clear();
  win_.clear();
}

void OverlapPlanner::add_move(const Block& b, const Eigen::Vector3d& a, const Eigen::Vector3d& e,
                            double chord_err) {
  const Eigen::Vector3d d = e - a;
  const double len = d.norm();
  if (len < 1e-9) {
    ++stats_.dropped_zero_length;
    return;
  }
  Move m;
  m.id = next_id_++;
  m.a = a;
  m.b = e;
  m.len = len;
  m.line = b.line;
  m.mode = p_.force_mode.value_or(b.blend);
  m.tol = p_.force_tolerance_mm.value_or(b.tolerance_mm > 0.0 ? b.tolerance_mm : p_.default_tolerance_mm);
  m.eps = m.tol - chord_err;
  m.spindle = b.spindle;
  m.rpm = b.spindle_rpm;
  m.mist = b.mist;
  m.flood = b.flood;
  m.tool = b.tool;
  m.rapid = b.rapid;
  // Axis limits: velocity, and acceleration through the FIR ramp (see header).
  double f = b.feed_mm_min;
  const Eigen::Vector3d u = d / len;
  const double t_a = static_cast<double>(std::max<std::int64_t>(tail_, 1)) * p_.period_s;
  for (int i = 0; i < 3; ++i) {
    const double ui = std::abs(u[i]);
    if (ui < 1e-12) continue;
    f = std::min(f, p_.max_velocity_mm_min[i] / ui);
    f = std::min(f, p_.max_accel_mm_s2[i] * t_a / 2.0 * 60.0 / ui);
  }
  if (!(f > 0.0)) f = 1e-6;
  m.feed_mm_min = f;
  const double x = len / (f / 60.0 * p_.period_s);
  // A move of more than ~31 years at its feed is not a real program (e.g. Y1e65 or a vanishing
  // feed); refuse it before the sample count overflows int64 (fuzz regression-1).
  if (!(x < 1e12)) {
    throw std::invalid_argument("line " + std::to_string(b.line) + ": move of " + std::to_string(len) +
                                " mm at " + std::to_string(f) + " mm/min is too long to interpolate");
  }
  m.n = p_.floor_rounding ? std::max<std::int64_t>(1, static_cast<std::int64_t>(std::floor(x + 1e-9)))
                          : std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(x - 1e-9)));
  m.path_start = path_mm_;
  path_mm_ += len;
  ++stats_.moves;
  decide(m);
}

void OverlapPlanner::refresh_window_cache() {
  WinCache& c = win_cache_;
  const std::size_t w = win_.size();
  c.sum.resize(w + 1);
  c.fin.resize(w + 1);
  c.mid.resize(w);
  c.half.resize(w);
  if (w == 0) return;
  Eigen::Vector3d x = win_.front().a;
  std::int64_t fin = std::numeric_limits<std::int64_t>::min();
  c.sum[0] = x;
  c.fin[0] = fin;
  for (std::size_t i = 0; i < w; ++i) {
    const Move& m = win_[i];
    x += m.b - m.a;
    fin = std::max(fin, m.finish(tail_));
    c.sum[i + 1] = x;
    c.fin[i + 1] = fin;
    c.mid[i] = 0.5 * (m.a + m.b);
    c.half[i] = 0.5 * (m.b - m.a).norm();
  }
}

Eigen::Vector3d OverlapPlanner::q(std::int64_t t) const {
  // Moves 0..k0-1 have all finished by t (t >= each finish(tail_) = s + n + L - 1, where
  // progress returns n): their sum is cached, added in the same order as below.
  const auto& fin = win_cache_.fin;
  const auto k0 =
      static_cast<std::size_t>(std::upper_bound(fin.begin() + 1, fin.end(), t) - (fin.begin() + 1));
  Eigen::Vector3d x = win_cache_.sum[k0];
  for (auto it = win_.begin() + static_cast<std::ptrdiff_t>(k0); it != win_.end(); ++it) {
    const Move& m = *it;
    if (m.s >= t) break;
    x += (m.b - m.a) * (fir_.progress(t - m.s, m.n) / static_cast<double>(m.n));
  }
  return x;
}

double OverlapPlanner::dist_seg(const Eigen::Vector3d& x, std::size_t i) const {
  return distance_point_segment(x, win_[i].a, win_[i].b);
}

double OverlapPlanner::dist_path(const Eigen::Vector3d& x, int* arg) const {
  double best = std::numeric_limits<double>::infinity();
  const std::size_t w = win_.size();
  // The result is the smallest distance and the first move that has it. A move whose bounding
  // sphere (midpoint, half length) is farther from x than ub, the distance to the move found
  // nearest last time (>= the minimum), is strictly farther than the minimum: it is neither, and
  // is skipped. The margin (1 pm, plus 1 pm per metre of coordinates) covers the rounding of the
  // sphere test and of the distances. (A NaN sample gives +inf either way, as before: the check fails.)
  const std::size_t h = dist_hint_ < w ? dist_hint_ : w - 1;
  const double dh = dist_seg(x, h);
  const double margin = 1e-9 + 1e-12 * x.cwiseAbs().maxCoeff();
  std::size_t best_i = h;
  for (std::size_t i = 0; i < w; ++i) {
    double d;
    if (i == h) {
      d = dh;
    } else {
      const double r = dh + win_cache_.half[i] + margin;
      if ((x - win_cache_.mid[i]).squaredNorm() > r * r) continue;
      d = dist_seg(x, i);
    }
    if (d < best) {
      best = d;
      best_i = i;
    }
  }
  dist_hint_ = best_i;
  if (arg != nullptr) *arg = static_cast<int>(best_i);
  return best;
}

double OverlapPlanner::chord_max(const Eigen::Vector3d& A, double da, int ia, const Eigen::Vector3d& B,
                                 double db, int ib) const {
  double worst = std::max(da, db);
  if (ia == ib) return worst;  // one convex distance function bounds the whole chord
  // min(d_ia, d_ib) >= true distance; its maximum on the chord is at an end or where they cross.
  const auto sa = static_cast<std::size_t>(ia), sb = static_cast<std::size_t>(ib);
  double lo = 0.0, hi = 1.0;
  for (int it = 0; it < 40; ++it) {
    const double mid = 0.5 * (lo + hi);
    const Eigen::Vector3d x = A + mid * (B - A);
    if (dist_seg(x, sa) <= dist_seg(x, sb)) lo = mid; else hi = mid;
  }
  const Eigen::Vector3d x = A + 0.5 * (lo + hi) * (B - A);
  worst = std::max(worst, std::min(dist_seg(x, sa), dist_seg(x, sb)));
  return worst;
}

void OverlapPlanner::extend_fixed(std::int64_t until) {
  if (vtx_.empty()) return;
  refresh_window_cache();
  // Only the newest move can be in motion alone after every older one stopped: straight run.
  std::int64_t t_single = win_.back().s;
  for (std::size_t i = 0; i + 1 < win_.size(); ++i) t_single = std::max(t_single, win_[i].finish(tail_));
  for (auto& v : vtx_) {
    if (v.fixed_from >= until) continue;
    const std::int64_t stop = std::min(until, std::max(t_single, v.fixed_from));
    Eigen::Vector3d prev = q(v.fixed_from);
    for (std::int64_t t = v.fixed_from + 1; t <= stop && v.fixed_best > v.eps; ++t) {
      const Eigen::Vector3d cur = q(t);
      v.fixed_best = std::min(v.fixed_best, distance_point_segment(v.p, prev, cur));
      prev = cur;
    }
    if (stop < until) v.fixed_best = std::min(v.fixed_best, distance_point_segment(v.p, q(stop), q(until)));
    v.fixed_from = until;
  }
  std::erase_if(vtx_, [](const Vertex& v) { return v.fixed_best <= v.eps; });
}

double OverlapPlanner::verify(std::int64_t g, double eps) {
  ++stats_.verifications;
  Move& m = win_.back();
  const Move& k = win_[win_.size() - 2];
  const std::int64_t fixed = k.s + k.n;
  m.s = fixed + g;
  std::int64_t t1 = m.s;
  for (std::size_t i = 0; i + 1 < win_.size(); ++i) t1 = std::max(t1, win_[i].finish(tail_));
  refresh_window_cache();
  // q(t) for t in [fixed, t1], each computed once: the path check and every pending vertex's
  // check walk the same samples.
  const auto span = static_cast<std::size_t>(t1 - fixed + 1);
  q_buf_.resize(span);
  q_have_.assign(span, 0);
  auto qt = [&](std::int64_t t) -> const Eigen::Vector3d& {
    const auto i = static_cast<std::size_t>(t - fixed);
    if (q_have_[i] == 0) {
      q_buf_[i] = q(t);
      q_have_[i] = 1;
    }
    return q_buf_[i];
  };
  double emax = 0.0;
  // Path error on every chord where two or more moves are in motion.
  // (Each sample's distance to the path is found once: the end of one chord starts the next.)
  Eigen::Vector3d prev = qt(m.s);
  int i_prev = 0;
  double d_prev = dist_path(prev, &i_prev);
  for (std::int64_t t = m.s + 1; t <= t1; ++t) {
    const Eigen::Vector3d cur = qt(t);
    int i_cur = 0;
    const double d_cur = dist_path(cur, &i_cur);
    const double e = chord_max(prev, d_prev, i_prev, cur, d_cur, i_cur);
    if (e > eps) return std::numeric_limits<double>::infinity();
    emax = std::max(emax, e);
    prev = cur;
    d_prev = d_cur;
    i_prev = i_cur;
  }
  // Two-sided: every pending vertex within its eps of the sampled polyline.
  if (!vtx_.empty()) {
    const Eigen::Vector3d after = qt(t1);
    for (const auto& v : vtx_) {
      double best = v.fixed_best;
      if (best <= v.eps) continue;
      Eigen::Vector3d p0 = qt(fixed);
      for (std::int64_t t = fixed + 1; t <= t1 && best > v.eps; ++t) {
        const Eigen::Vector3d cur = qt(t);
        best = std::min(best, distance_point_segment(v.p, p0, cur));
        p0 = cur;
      }
      best = std::min(best, distance_point_segment(v.p, after, m.b));
      if (best > v.eps) return std::numeric_limits<double>::infinity();
    }
  }
  return emax;
}

OverlapPlanner::TwoBlock OverlapPlanner::paper_two_block(const Eigen::Vector3d& a0,
                                                     const Eigen::Vector3d& vertex,
                                                     const Eigen::Vector3d& b1, std::int64_t na,
                                                     std::int64_t nb, double eps,
                                                     bool incremental) const {
  const Eigen::Vector3d da = vertex - a0, db = b1 - vertex;
  const Eigen::Vector3d ua = da.normalized(), ub = db.normalized();
  auto err = [&](std::int64_t t, std::int64_t g) {
    const Eigen::Vector3d x = a0 + da * (fir_.progress(t, na) / static_cast<double>(na)) +
                              db * (fir_.progress(t - (na + g), nb) / static_cast<double>(nb));
    return std::min(line_distance(x, vertex, ua), line_distance(x, vertex, ub));
  };
  // Overlap region of gap g: t in [na + g + 1, na + tail] (eq 6: max over the overlap).
  auto full = [&](std::int64_t g, std::int64_t* arg) {
    double e = 0.0;
    for (std::int64_t t = na + g + 1; t <= na + tail_; ++t) {
      const double v = err(t, g);
      if (v > e) {
        e = v;
        *arg = t;
      }
    }
    return e;
  };
  std::int64_t j = 0;
  std::int64_t g = 0;
  double e = full(0, &j);
  while (e > eps && g < tail_) {
    ++g;
    if (!incremental) {
      e = full(g, &j);
      continue;
    }
    // Eqs 13-27: shrinking the overlap by one period moves the maximum only next to the previous
    // one (here in absolute time: the point j or j + 1, as block b starts one period later).
    e = 0.0;
    std::int64_t jn = j;
    for (std::int64_t t = j; t <= j + 1; ++t) {
      if (t < na + g + 1 || t > na + tail_) continue;
      const double v = err(t, g);
      if (v > e) {
        e = v;
        jn = t;
      }
    }
    j = jn;
  }
  return {static_cast<int>(tail_ - g), e};
}

void OverlapPlanner::emit(const Move& m) {
  PlannedSegment s;
  s.kind = SegmentKind::kMotion;
  s.start_cycle = m.s;
  s.samples = m.n;
  s.start_mm = m.a;
  s.end_mm = m.b;
  s.length_mm = m.len;
  s.path_start_mm = m.path_start;
  s.feed_mm_min = m.feed_mm_min;
  s.line = m.line;
  s.spindle = m.spindle;
  s.spindle_rpm = m.rpm;
  s.mist = m.mist;
  s.flood = m.flood;
  s.tool = m.tool;
  s.rapid = m.rapid;
  s.speed_mm_min = m.feed_mm_min;
  out_.push_back(s);
}

void OverlapPlanner::decide(Move& m) {
  if (win_.empty() || stop_before_next_) {
    m.s = earliest_start_;
    if (!win_.empty()) m.s = std::max(m.s, win_.back().finish(tail_));
    stop_before_next_ = false;
    win_.push_back(m);
    emit(m);
    return;
  }
  const Move k = win_.back();
  const BlendMode mode = k.mode;
  CornerReport cr;
  cr.move_index = m.id;
  cr.line = m.line;
  cr.prev_line = k.line;
  cr.vertex_mm = k.b;
  const double c = std::clamp((k.b - k.a).normalized().dot((m.b - m.a).normalized()), -1.0, 1.0);
  cr.angle_deg = std::acos(c) * 180.0 / std::numbers::pi;
  std::int64_t g = tail_;
  const std::int64_t fixed = k.s + k.n;
  if (mode == BlendMode::kFull) {
    g = 0;
    // Report the paper's sampled two-block error (eq 6) of the full overlap.
    cr.model_error_mm = paper_two_block(k.a, k.b, m.b, k.n, m.n, std::numeric_limits<double>::infinity(), true).error_mm;
    win_.push_back(m);
  } else if (mode == BlendMode::kExactStop) {
    g = tail_;
    win_.push_back(m);
  } else {
    const double eps = std::min(k.eps, m.eps);
    cr.tolerance_mm = std::min(k.tol, m.tol);
    const TwoBlock tb = paper_two_block(k.a, k.b, m.b, k.n, m.n, eps, true);
    if (p_.method == BlendMethod::kPaper) {
      g = tail_ - tb.overlap_cycles;
      cr.model_error_mm = tb.error_mm;
      win_.push_back(m);
    } else {
      extend_fixed(fixed);
      win_.push_back(m);
      // Vertices are held with a 1 % margin: the output the interpolator produces differs from
      // this window's model of it by rounding and by the continuation after the window (measured:
      // up to 0.08 um at 50 um: short_blocks.ngc, plasmatest.ngc, issue 19; cause not found yet);
      // the path samples keep the full eps.
      vtx_.push_back(Vertex{m.id, k.b, eps * (1.0 - 1e-2), std::numeric_limits<double>::infinity(), fixed});
      double e = std::numeric_limits<double>::infinity();
      if (p_.method == BlendMethod::kExhaustive) {
        for (g = 0; g <= tail_; ++g) {
          e = verify(g, eps);
          if (std::isfinite(e)) break;
        }
      } else {
        g = tail_ - tb.overlap_cycles;
        e = verify(g, eps);
        if (std::isfinite(e)) {
          while (g > 0) {
            const double e2 = verify(g - 1, eps);
            if (!std::isfinite(e2)) break;
            --g;
            e = e2;
          }
        } else {
          while (g < tail_ && !std::isfinite(e)) e = verify(++g, eps);
        }
      }
      if (!std::isfinite(e)) {
        g = tail_;  // always holds: stop at the vertex (see header)
        e = verify(g, eps);
      }
      cr.model_error_mm = std::isfinite(e) ? e : 0.0;
    }
  }
  Move& nm = win_.back();
  nm.s = fixed + g;
  cr.overlap_cycles = static_cast<int>(tail_ - g);
  emit(nm);
  if (corner_cb_) corner_cb_(cr);
  // Bounded window: drop moves that stopped before anything still to be evaluated.
  std::int64_t need = nm.s;
  for (const auto& v : vtx_) need = std::min(need, v.fixed_from);
  while (win_.size() > 2 && win_.front().finish(tail_) <= need) win_.pop_front();
  stats_.max_window = std::max(stats_.max_window, win_.size());
}

}  // namespace contour::control
