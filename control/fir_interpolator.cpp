#include "control/fir_interpolator.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace contour::control {

void FirFilter::configure(int taps1, int taps2) {
  if (taps1 < 1 || taps2 < 0) throw std::invalid_argument("FIR taps must be >= 1");
  std::vector<double> a(static_cast<std::size_t>(taps1), 1.0 / taps1);
  if (taps2 > 0) {
    std::vector<double> c(static_cast<std::size_t>(taps1 + taps2 - 1), 0.0);
    for (int i = 0; i < taps1; ++i)
      for (int j = 0; j < taps2; ++j) c[static_cast<std::size_t>(i + j)] += a[static_cast<std::size_t>(i)] / taps2;
    a = std::move(c);
  }
  w_ = std::move(a);
  length_ = static_cast<int>(w_.size());
  p_.assign(w_.size() + 1, 0.0);
  pi_.assign(w_.size() + 1, 0.0);
  for (std::size_t i = 0; i < w_.size(); ++i) {
    p_[i + 1] = p_[i] + w_[i];
    pi_[i + 1] = pi_[i] + static_cast<double>(i) * w_[i];
  }
  // Make the total exactly 1 so a finished block lands exactly on its end point.
  p_.back() = 1.0;
}

double FirFilter::progress(std::int64_t k, std::int64_t n) const noexcept {
  if (k <= 0) return 0.0;
  const std::int64_t last = length_ - 1;
  if (k - last >= n) return static_cast<double>(n);
  // Taps i <= k-n see the whole block (n), taps k-n < i < k see k-i samples, taps i >= k none.
  const std::int64_t a = std::clamp<std::int64_t>(k - n, -1, last);
  const std::int64_t b = std::min<std::int64_t>(k - 1, last);
  double sum = static_cast<double>(n) * p_[static_cast<std::size_t>(a + 1)];
  if (b >= a + 1) {
    sum += static_cast<double>(k) * (p_[static_cast<std::size_t>(b + 1)] - p_[static_cast<std::size_t>(a + 1)]) -
           (pi_[static_cast<std::size_t>(b + 1)] - pi_[static_cast<std::size_t>(a + 1)]);
  }
  return sum;
}

double FirFilter::progress(double k, double n) const noexcept {
  if (k <= 0.0) return 0.0;
  const double last = static_cast<double>(length_ - 1);
  if (k - last >= n) return n;
  // Taps i <= k-n see the whole block (n), taps k-n < i < k see k-i, taps i >= k none. With real k
  // and n the boundaries are floor(k - n) and ceil(k) - 1 (equal to k - n and k - 1 for integers).
  // floor and ceil by truncation (the look-ahead planner's verification calls this per pulse and
  // period; std::floor / std::ceil are library calls without SSE4.1). k > 0 and k - n > -2^62
  // here: the truncated values are exact.
  const double kn = k - n;
  auto fl = static_cast<std::int64_t>(kn);
  if (static_cast<double>(fl) > kn) --fl;
  auto ce = static_cast<std::int64_t>(k);
  if (static_cast<double>(ce) < k) ++ce;
  const std::int64_t a = std::clamp<std::int64_t>(fl, -1, length_ - 1);
  const std::int64_t b = std::min<std::int64_t>(ce - 1, length_ - 1);
  double sum = n * p_[static_cast<std::size_t>(a + 1)];
  if (b >= a + 1) {
    sum += k * (p_[static_cast<std::size_t>(b + 1)] - p_[static_cast<std::size_t>(a + 1)]) -
           (pi_[static_cast<std::size_t>(b + 1)] - pi_[static_cast<std::size_t>(a + 1)]);
  }
  return sum;
}

void Interpolator::configure(const InterpolatorParams& p, const Eigen::Vector3d& start_mm) {
  if (p.capacity < 4) throw std::invalid_argument("interpolator capacity must be >= 4");
  if (!(p.override_max >= 0.0)) throw std::invalid_argument("override_max must be >= 0");
  p_ = p;
  fir_.configure(p.fir_taps, p.fir2_taps);
  ring_.assign(p.capacity, PlannedSegment{});
  cap_ = p.capacity;
  head_ = count_ = 0;
  shift_ = 0;
  base_mm_ = start_mm;
  base_progress_mm_ = 0.0;
  tau_ = 0.0;
  // Start at 100 %: the plan itself starts from rest, a ramp here would only stretch time.
  ovr_ = std::min(1.0, p.override_max);
  holding_ = resumed_hold_ = done_ = false;
  whole_phase_ = snap_phase_ = false;
  rapid_now_ = false;
  next_start_ = brake_for_ = -1;
  on_line_ = 0;
  next_new_line_ = sb_braking_ = sb_stopped_ = sb_go_ = false;
  sb_pass_ = sb_for_ = -1;
  next_rapid_ = false;
  last_ = InterpOutput{};
  last_.position_mm = start_mm;
}

bool Interpolator::push(const PlannedSegment& seg) noexcept {
  if (count_ == cap_) return false;
  PlannedSegment s = seg;
  s.start_cycle += shift_;
  // A block that arrives after its planned start (planner starved the RT loop) may only start
  // from rest: after every queued block has stopped, which is the path the planner verified
  // (it always assumes a stop after the newest block).
  const auto now = static_cast<std::int64_t>(std::ceil(tau_));
  if (s.start_cycle < now) {
    std::int64_t from = now;
    for (std::size_t i = 0; i < count_; ++i) {
      const PlannedSegment& q = at(i);
      if (q.kind == SegmentKind::kMotion)
        from = std::max(from, q.start_cycle + static_cast<std::int64_t>(std::ceil(
                                                  q.start_offset_cycles + segment_duration(q))) +
                                  fir_.length() - 1);
    }
    shift_ += from - s.start_cycle;
    s.start_cycle = from;
  }
  ring_[slot(count_)] = s;
  ++count_;
  return true;
}

void Interpolator::resume() noexcept {
  if (holding_) resumed_hold_ = true;
  if (sb_stopped_) sb_go_ = true;
}

Eigen::Vector3d Interpolator::position_at(std::int64_t t, double* progress_mm,
                                          int* line) const noexcept {
  Eigen::Vector3d q = base_mm_;
  double prog = base_progress_mm_;
  int ln = last_line_;
  for (std::size_t i = 0; i < count_; ++i) {
    const PlannedSegment& s = at(i);
    if (s.kind != SegmentKind::kMotion) continue;
    if (s.start_cycle > t) break;
    double f = 0.0;
    if (s.duration_cycles > 0.0) {
      const double k = static_cast<double>(t - s.start_cycle) - s.start_offset_cycles;
      f = fir_.progress(k, s.duration_cycles) / s.duration_cycles;
    } else {
      f = fir_.progress(t - s.start_cycle, s.samples) / static_cast<double>(s.samples);
    }
    q += f * (s.end_mm - s.start_mm);
    prog += f * s.length_mm;
    ln = s.line;
  }
  if (progress_mm != nullptr) *progress_mm = prog;
  if (line != nullptr) *line = ln;
  return q;
}

void Interpolator::drop_finished(std::int64_t t) noexcept {
  const std::int64_t tail = fir_.length() - 1;
  while (count_ > 0) {
    const PlannedSegment& s = at(0);
    if (s.kind != SegmentKind::kMotion) break;
    if (static_cast<double>(s.start_cycle + tail) + s.start_offset_cycles + segment_duration(s) >
        static_cast<double>(t))
      break;
    base_mm_ = s.end_mm;
    base_progress_mm_ = s.path_start_mm + s.length_mm;
    last_line_ = s.line;
    last_.spindle = s.spindle;
    last_.spindle_rpm = s.spindle_rpm;
    last_.mist = s.mist;
    last_.flood = s.flood;
    last_.tool = s.tool;
    pop_front();
  }
}

void Interpolator::set_hold_marker(const PlannedSegment* m) noexcept {
  last_.hold_kind = m != nullptr ? m->kind : SegmentKind::kMotion;
  last_.hold_tool = m != nullptr ? m->tool : 0;
  last_.user_m = m != nullptr ? m->user_m : 0;
  last_.user_p = m != nullptr ? m->user_p : -1.0;
  last_.user_q = m != nullptr ? m->user_q : -1.0;
}

InterpStatus Interpolator::step(double feed_ratio, double rapid_ratio, InterpOutput& out) noexcept {
  if (done_) {
    out = last_;
    return out.status;
  }
  auto clean = [this](double r) { return std::isnan(r) ? 0.0 : std::clamp(r, 0.0, p_.override_max); };
  double target = clean(rapid_now_ ? rapid_ratio : feed_ratio);
  if (next_start_ >= 0 && next_rapid_ != rapid_now_) {
    // The next segment runs at a lower ratio: start braking when the plan time left before it
    // starts is what a ramp from the present ratio down to its ratio consumes (plus a cycle).
    const double r_next = clean(next_rapid_ ? rapid_ratio : feed_ratio);
    const double r_rate = 1.0 / std::max(1, fir_.length() - 1);
    const double need = (ovr_ * ovr_ - r_next * r_next) / (2.0 * r_rate) + ovr_;
    if (r_next < target &&
        (brake_for_ == next_start_ || static_cast<double>(next_start_) - tau_ <= need)) {
      brake_for_ = next_start_;
      target = r_next;
    }
  }
  if (sb_stopped_) {
    if (!sb_go_) {
      ovr_ = 0.0;
      last_.status = InterpStatus::kHolding;
      out = last_;
      return out.status;
    }
    // Released: the next line starts (the override ramps up from 0 as after a feed hold).
    sb_stopped_ = sb_go_ = sb_braking_ = false;
    whole_phase_ = true;
    // The line braked for starts now; a stand that came too late (inside that line) releases
    // nothing: the path runs to the end of the line it stands in and stops again.
    sb_pass_ = next_start_ == sb_for_ ? sb_for_ : -1;
    last_.single_block_stop = false;
  }
  if (p_.single_block && !sb_braking_ && next_new_line_ && next_start_ != sb_pass_) {
    // Stand before the next line: brake when the plan time left before it starts is what the
    // ramp from the present ratio to 0 consumes (plus a cycle), as for a slower next segment.
    const double r_rate = 1.0 / std::max(1, fir_.length() - 1);
    if (static_cast<double>(next_start_) - tau_ <= ovr_ * ovr_ / (2.0 * r_rate) + ovr_) {
      sb_braking_ = true;
      sb_for_ = next_start_;
      sb_line_ = on_line_;
    }
  }
  if (sb_braking_) target = 0.0;
  if (holding_) {
    if (!resumed_hold_) {
      ovr_ = 0.0;
      last_.status = hold_status_;
      out = last_;
      return out.status;
    }
    // Leave the hold marker behind.
    holding_ = resumed_hold_ = false;
    whole_phase_ = true;
    pop_front();
    last_.message_id = -1;
    set_hold_marker(nullptr);
  }
  // Spread override changes over at least t_A (rate limit 1/(L-1) per period).
  const double rate = 1.0 / std::max(1, fir_.length() - 1);
  double dr = std::clamp(target - ovr_, -rate, rate);
  if (whole_phase_) {
    // The ramp from a stand (plan time a whole number) up to 100 % advances plan time by
    // sum k rate, k = 1..n (n = L - 1): (n + 1) / 2, half a period off for an even n, and every
    // later sample would then lie halfway between two of the samples the planner verified (whose
    // polyline cuts the vertices differently: 50.0002 um at P = 50 um on a pcb2gcode program
    // after its M0). Starting with half a step makes it sum (k - 1/2) rate = n / 2 plus the last
    // half step: a whole number, so at 100 % the output samples are the verified ones again
    // (snapped to it when the ramp ends: rate = 1 / n is not exact in binary for every n).
    whole_phase_ = false;
    snap_phase_ = dr > 0.0;
    if (dr > 0.0 && (fir_.length() - 1) % 2 == 0) dr = std::min(dr, 0.5 * rate);
  }
  if (snap_phase_ && !(dr > 0.0)) snap_phase_ = false;  // the ramp ended below 100 %: no snap
  ovr_ += dr;
  if (sb_braking_) {
    // The ramp to the single-block stand ends up to a cycle short of it: creep the rest at the
    // smallest ramp step, so that the stand is exactly where the next line would start (with
    // exact stop: the block's end point).
    const double left = static_cast<double>(sb_for_) - tau_;
    if (left > 1e-9 && ovr_ < rate) ovr_ = std::min(rate, left);
  }

  // Horizon: the first marker, else where the last queued block stops (starvation stop).
  double limit = tau_;
  const PlannedSegment* marker = nullptr;
  const std::int64_t tail = fir_.length() - 1;
  for (std::size_t i = 0; i < count_; ++i) {
    const PlannedSegment& s = at(i);
    // Later entries start after this cycle can reach: the horizon is at least there (keeps the
    // scan O(blocks in motion) instead of O(queue)).
    if (static_cast<double>(s.start_cycle) > tau_ + p_.override_max + 2.0) {
      limit = std::max(limit, static_cast<double>(s.start_cycle));
      break;
    }
    if (s.kind != SegmentKind::kMotion) {
      marker = &s;
      limit = static_cast<double>(s.start_cycle);
      break;
    }
    limit = std::max(limit, std::ceil(static_cast<double>(s.start_cycle + tail) +
                                      s.start_offset_cycles + segment_duration(s)));
  }
  double next = std::min(tau_ + ovr_, std::max(limit, tau_));
  if (snap_phase_ && ovr_ >= 1.0) {
    snap_phase_ = false;
    const double whole = std::nearbyint(next);
    if (std::abs(next - whole) < 1e-6) next = whole;
  }
  tau_ = next;
  InterpStatus st = InterpStatus::kRunning;
  if (count_ == 0) st = base_progress_mm_ > 0.0 ? InterpStatus::kStarved : InterpStatus::kIdle;
  if (tau_ >= limit) {
    if (marker != nullptr) {
      if (marker->kind == SegmentKind::kEnd) {
        st = InterpStatus::kDone;
      } else if (marker->kind == SegmentKind::kOptionalHold && !p_.optional_stop) {
        // Marker is the first non-motion entry; all motion before it has finished at `limit`.
        drop_finished(static_cast<std::int64_t>(limit));
        if (count_ > 0 && at(0).kind == SegmentKind::kOptionalHold) {
          pop_front();
        }
      } else if (marker->kind == SegmentKind::kSpindleSync) {
        st = InterpStatus::kSpindleWait;
        hold_status_ = st;
        holding_ = true;
        ovr_ = 0.0;
      } else {
        st = InterpStatus::kHolding;
        hold_status_ = st;
        holding_ = true;
        last_.message_id = marker->message_id;
        ovr_ = 0.0;
      }
    } else if (count_ > 0) {
      st = InterpStatus::kStarved;
    }
  }
  const auto t0 = static_cast<std::int64_t>(std::floor(tau_));
  drop_finished(t0);
  const double frac = tau_ - static_cast<double>(t0);
  double prog0 = 0.0;
  int ln = 0;
  Eigen::Vector3d q = position_at(t0, &prog0, &ln);
  if (frac > 0.0) {
    double prog1 = 0.0;
    const Eigen::Vector3d q1 = position_at(t0 + 1, &prog1, nullptr);
    q += frac * (q1 - q);
    prog0 += frac * (prog1 - prog0);
  }
  if (sb_braking_ && ovr_ <= 0.0 && st == InterpStatus::kRunning) {
    st = InterpStatus::kHolding;  // the single-block stand (no marker: hold_kind stays kMotion)
    sb_stopped_ = true;
    last_.single_block_stop = true;
    // Standing exactly where the next line starts counts that segment as begun (its start is
    // not after the plan time) though it has not moved: the line is the one braked in, unless
    // the stand came late (inside the next line).
    if (tau_ <= static_cast<double>(sb_for_) + 1e-9) ln = sb_line_;
  }
  if (st == InterpStatus::kHolding || st == InterpStatus::kSpindleWait) {
    drop_finished(t0);
    if (count_ > 0) {
      // The hold marker must now be at the front (motion before it has stopped).
      last_.message_id = at(0).kind == SegmentKind::kMotion ? -1 : at(0).message_id;
      set_hold_marker(at(0).kind == SegmentKind::kMotion ? nullptr : &at(0));
      if (st == InterpStatus::kSpindleWait && at(0).kind == SegmentKind::kSpindleSync) {
        last_.spindle = at(0).spindle;  // the new speed is commanded while the path waits
        last_.spindle_rpm = at(0).spindle_rpm;
      }
    }
  }
  if (st == InterpStatus::kDone) {
    done_ = true;
    q = base_mm_;  // exact final point: end_mm of the last finished block
  }
  // Modal state of the newest block in motion; the segment the path is on (that one, else the
  // next to start) says which override applies next cycle.
  const PlannedSegment* on = nullptr;
  const PlannedSegment* next_seg = nullptr;
  for (std::size_t i = 0; i < count_; ++i) {
    const PlannedSegment& s = at(i);
    if (s.kind != SegmentKind::kMotion) break;
    if (s.start_cycle > t0) {
      if (on == nullptr) {
        on = &s;
      } else {
        next_seg = &s;
      }
      break;
    }
    on = &s;
    last_.spindle = s.spindle;
    last_.spindle_rpm = s.spindle_rpm;
    last_.mist = s.mist;
    last_.flood = s.flood;
    last_.tool = s.tool;
  }
  if (on != nullptr) {
    rapid_now_ = on->rapid;
    on_line_ = on->line;
  }
  next_start_ = next_seg != nullptr ? next_seg->start_cycle : -1;
  next_new_line_ = next_seg != nullptr && next_seg->line != on_line_;
  next_rapid_ = next_seg != nullptr && next_seg->rapid;
  last_.rapid = rapid_now_;
  last_.position_mm = q;
  last_.path_progress_mm = prog0;
  last_.line = ln;
  last_.override_applied = ovr_;
  last_.plan_time_cycles = tau_;
  last_.status = st;
  out = last_;
  return st;
}

}  // namespace contour::control
