#include "control/lookahead_planner.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <stdexcept>

#include "control/path.hpp"

namespace contour::control {

namespace {
using Eigen::Vector3d;
constexpr double kTiny = 1e-12;  // mm: positions closer than this are the same
constexpr int kFine = 8;          // fine braking steps per window
constexpr double kEpsMargin = 0.99;  // verification tolerance / programmed tolerance
// Collinear merging: a programmed vertex may be merged over when it lies within this share of P
// of the merged chord; chords are merged while one of the two is shorter than kMergeShortPeriods
// periods at its feed; at most kMergeMax vertices per chord.
constexpr double kMergeShare = 0.04;
constexpr double kMergeShortPeriods = 2.0;
constexpr std::size_t kMergeMax = 256;
// Out-and-back spikes up to this share of P are dropped (try_drop_spike).
constexpr double kSpikeShare = 0.4;

// Upper bound of max over [0,1] of min(d_a, d_b) on a chord, given both convex distance
// functions at its two ends (each is below its chord interpolation).
double chord_bound(double a0, double a1, double b0, double b1) {
  double m = std::max(std::min(a0, b0), std::min(a1, b1));
  const double da = a1 - a0, db = b1 - b0;
  const double den = da - db;
  if (std::abs(den) > 1e-300) {
    const double lam = (b0 - a0) / den;
    if (lam > 0.0 && lam < 1.0) m = std::max(m, a0 + lam * da);
  }
  return m;
}

// Whether the line b may still change the last chord c instead of starting a new one (try_merge,
// try_drop_spike): c is not decided, stopped or committed, no committed pulse or verified
// continuation reaches it, and b runs in the same blend context (within the same tolerance, the
// same motion kind, spindle, coolant and tool).
template <class ChordT, class PulseT>
bool last_chord_open(const ChordT& c, const Block& b, const PlannerParams& p, std::int64_t committed,
                     const std::vector<PulseT>& fallback, const std::vector<PulseT>& tail) {
  const BlendMode mode = p.force_mode.value_or(b.blend);
  if (c.decided || c.stop || c.id <= committed || mode != BlendMode::kLimited ||
      c.mode != BlendMode::kLimited || c.rapid != b.rapid || c.spindle != b.spindle ||
      c.rpm != b.spindle_rpm || c.mist != b.mist || c.flood != b.flood || c.tool != b.tool)
    return false;
  const double tol = p.force_tolerance_mm.value_or(b.tolerance_mm > 0.0 ? b.tolerance_mm
                                                                        : p.default_tolerance_mm);
  if (tol != c.tol || !std::isfinite(c.eps)) return false;
  for (const auto& q : fallback)
    if (q.chord >= c.id) return false;
  for (const auto& q : tail)
    if (q.chord >= c.id) return false;
  return true;
}
}  // namespace

LookaheadPlanner::LookaheadPlanner(const PlannerParams& p, const Vector3d& start_mm)
    : p_(p), pos_(start_mm) {
  if (!(p.period_s > 0.0)) throw std::invalid_argument("planner period must be > 0");
  if (!(p.arc_chord_fraction > 0.0 && p.arc_chord_fraction < 1.0))
    throw std::invalid_argument("arc_chord_fraction must be in (0, 1)");
  if (!(p.min_segment_cycles > 0.0)) throw std::invalid_argument("min_segment_cycles must be > 0");
  fir_.configure(p.fir_taps, p.fir2_taps);
  L_ = fir_.length();
  L1_ = std::max(1, p.fir_taps);
  T_ = p.period_s;
  for (int i = 0; i < 3; ++i) {
    const double a = p.max_accel_mm_s2[i];
    if (!(a > 0.0)) throw std::invalid_argument("axis acceleration limits must be > 0");
    if (!(p.max_velocity_mm_min[i] > 0.0))
      throw std::invalid_argument("axis velocity limits must be > 0");
    // Planned strictly inside the limit: rounding never lands a period on the wrong side.
    A_[i] = std::isfinite(a) ? a * T_ * T_ * L1_ * (1.0 - 1e-9) : kInf;
    vmax_[i] = p.max_velocity_mm_min[i] / 60.0 * T_;
  }
  rr_ = static_cast<double>(L_ + 1);
  rr_in_ = 0.5 * L_ + 2.0;
  delta_ = static_cast<double>(L1_ + 1) / kFine;
  // Filter moments (periods) and the sharp-corner displacement alpha(g): at the middle of the
  // overlap t* = (L - 1 + g) / 2 the output is vertex + v alpha (u2 - u1) (symmetric filter).
  double mean = 0.0, m2 = 0.0;
  for (int i = 0; i < L_; ++i) {
    mean += fir_.weight(i) * i;
    m2 += fir_.weight(i) * i * i;
  }
  sigma2_ = std::max(0.0, m2 - mean * mean);
  alpha_.assign(static_cast<std::size_t>(L_), 0.0);
  for (int g = 0; g < L_; ++g) {
    const double ts = 0.5 * (L_ - 1 + g);
    double a = 0.0;
    for (int i = 0; i < L_; ++i)
      if (i > ts) a += fir_.weight(i) * (i - ts);
    alpha_[static_cast<std::size_t>(g)] = a;
  }
  committed_.hist.ring.assign(static_cast<std::size_t>(L1_ + 3), Vector3d::Zero());
  committed_.tau = 0.0;
  committed_.chord = 0;
  vcommitted_.t = 0;
  vcommitted_.y = start_mm;
}

double LookaheadPlanner::corner_model_mm(double theta, double v, int gap) const {
  const int g = std::clamp(gap, 0, L_ - 1);
  const double s = std::sin(0.5 * theta);
  return v * (2.0 * alpha_[static_cast<std::size_t>(g)] * s + s / (4.0 * std::max(1, L_ - g)));
}

bool LookaheadPlanner::pop(PlannedSegment& out) {
  if (out_.empty()) return false;
  out = out_.front();
  out_.pop_front();
  return true;
}

// ------------------------------------------------------------------------------------------------
// Input

void LookaheadPlanner::push(const Block& b) {
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
      double tol = p_.force_tolerance_mm.value_or(mode == BlendMode::kLimited ? b.tolerance_mm
                                                                               : p_.default_tolerance_mm);
      if (mode == BlendMode::kLimited && b.tolerance_mm <= 0.0 && !p_.force_tolerance_mm)
        tol = p_.default_tolerance_mm;
      if (b.seg.kind == PathSegment::Kind::kLine) {
        add_chord(b, pos_, b.seg.end, 0.0);
      } else {
        const double chord_err = p_.arc_chord_fraction * tol;
        chord_buf_.clear();
        chord_points(b.seg, chord_err, chord_buf_);
        Vector3d a = pos_;
        for (const auto& e : chord_buf_) {
          add_chord(b, a, e, chord_err);
          a = e;
        }
      }
      pos_ = b.seg.end;
      maybe_plan();
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

void LookaheadPlanner::add_chord(const Block& b, const Vector3d& a, const Vector3d& e,
                                 double chord_err) {
  const Vector3d d = e - a;
  const double len = d.norm();
  if (len < 1e-9) {
    ++stats_.dropped_zero_length;
    return;
  }
  if (chord_err == 0.0 && spike_mm_ == 0.0 && try_drop_spike(b, e)) return;
  if (chord_err == 0.0 && spike_mm_ == 0.0 && try_merge(b, e)) return;
  Chord c;
  c.id = next_id_++;
  c.a = a;
  c.b = e;
  c.u = d / len;
  c.len = len;
  c.s0 = path_mm_;
  c.line = b.line;
  c.rapid = b.rapid;
  c.mode = p_.force_mode.value_or(b.blend);
  c.tol = p_.force_tolerance_mm.value_or(b.tolerance_mm > 0.0 ? b.tolerance_mm
                                                              : p_.default_tolerance_mm);
  // G64 without P blends without a tolerance; G61 stops at every vertex (nothing to verify).
  // Verified with the 1 % margin kTrue holds (overlap_planner.hpp): the meter found 50.19 um at
  // a reversal of pcb2gcode-multivibrator-clockwise-back (P = 50 um) that this verification had
  // passed at <= 50 um (a difference between the verification's output and the meter's).
  c.eps = c.mode == BlendMode::kLimited ? kEpsMargin * (c.tol - chord_err - spike_mm_) : kInf;
  spike_mm_ = 0.0;
  c.spindle = b.spindle;
  c.rpm = b.spindle_rpm;
  c.mist = b.mist;
  c.flood = b.flood;
  c.tool = b.tool;
  c.block_feed_mm_min = b.feed_mm_min;
  set_limits(c, b.line);
  if (!chords_.empty() && !start_from_rest_) {
    const Chord& pr = chords_.back();
    const double cth = std::clamp(pr.u.dot(c.u), -1.0, 1.0);
    c.turn = std::acos(cth);
    c.has_prev = true;
    if (pr.mode == BlendMode::kExactStop || force_stop_next_) c.stop = true;
  }
  start_from_rest_ = false;
  force_stop_next_ = false;
  vmax_seen_ = std::max(vmax_seen_, c.cap);
  dvmin_seen_ = std::min(dvmin_seen_, c.dv);
  dvmax_seen_ = std::max(dvmax_seen_, c.dv);
  path_mm_ += len;
  ++stats_.moves;
  chords_.push_back(c);
  stats_.max_window = std::max(stats_.max_window, chords_.size());
}

// Why: pcb2gcode's isolation paths go out and back along the same line by 14-16 um at 177 of the
// vertices of multivibrator-clockwise-back (two 180-degree reversals each, planned as near-stops).
// The tip T of such a spike lies h from the vertex V it returns to; the spike is dropped and the
// next chord's verification tolerance (and so V's vertex tolerance) shrinks by h, so the output
// passes within eps - h of V and within eps of T. At a stop (a barrier, the program end) the
// output rests at V itself.
bool LookaheadPlanner::try_drop_spike(const Block& b, const Vector3d& e) {
  if (chords_.size() < 2 || start_from_rest_ || force_stop_next_) return false;
  const Chord& sp = chords_.back();
  const Chord& pr = chords_[chords_.size() - 2];
  if (!last_chord_open(sp, b, p_, committed_.chord, fallback_, vcommitted_.tail) ||
      !sp.dropped.empty() || pr.id + 1 != sp.id || (pr.b - sp.a).norm() > 1e-9)
    return false;
  // Back to where the spike started, and short against the tolerance.
  if ((e - sp.a).norm() > 1e-9 || sp.len > kSpikeShare * sp.tol) return false;
  spike_mm_ = sp.len;
  path_mm_ = sp.s0;
  --next_id_;
  chords_.pop_back();
  ++stats_.moves;
  return true;
}

void LookaheadPlanner::set_limits(Chord& c, int line) {
  double f = c.block_feed_mm_min;
  if (c.rapid) f = std::min(f, p_.rapid_mm_min);
  for (int i = 0; i < 3; ++i) {
    const double ui = std::abs(c.u[i]);
    if (ui > 1e-12) f = std::min(f, p_.max_velocity_mm_min[i] / ui);
  }
  if (!(f > 0.0)) f = 1e-6;
  c.feed_mm_min = f;
  const double v = f / 60.0 * T_;
  // A move of more than ~31 years at its feed is not a real program (e.g. Y1e65 or a vanishing
  // feed); refuse it before times overflow (fuzz regression-1).
  if (!(c.len / v < 1e12)) {
    throw std::invalid_argument("line " + std::to_string(line) + ": move of " +
                                std::to_string(c.len) + " mm at " + std::to_string(f) +
                                " mm/min is too long to interpolate");
  }
  c.cap = std::min(v, c.len / p_.min_segment_cycles);
  c.dv = kInf;
  for (int i = 0; i < 3; ++i) {
    const double ui = std::abs(c.u[i]);
    if (ui > 1e-12) c.dv = std::min(c.dv, A_[i] / ui);
  }
}

// Why: the segment-duration floor (len / min_segment_cycles) held the CAM output of pcb2gcode
// (alternating 1 um and 8 um chords) at 60 mm/min: D1MiniGSR-front took 13x LinuxCNC's time.
// LinuxCNC merges such chords (G64 Q); here the merge error is counted inside P: a merged chord is
// verified against eps - kMergeShare P, and every programmed vertex merged over lies within
// kMergeShare P of it, so the output stays within eps of the programmed path and its vertices
// (a continuous output within e of a segment, running from one end to the other, passes within e
// of every point of it).
bool LookaheadPlanner::try_merge(const Block& b, const Vector3d& e) {
  if (chords_.empty() || start_from_rest_ || force_stop_next_) return false;
  Chord& pr = chords_.back();
  if (!last_chord_open(pr, b, p_, committed_.chord, fallback_, vcommitted_.tail) ||
      pr.block_feed_mm_min != b.feed_mm_min || pr.dropped.size() >= kMergeMax)
    return false;
  const double short_mm = kMergeShortPeriods * pr.feed_mm_min / 60.0 * T_;
  const double len_new = (e - pr.b).norm();
  if (pr.len > short_mm && len_new > short_mm) return false;
  const Vector3d d = e - pr.a;
  const double len = d.norm();
  if (len < 1e-9) return false;
  const double dmax = kMergeShare * pr.tol;
  if (distance_point_segment(pr.b, pr.a, e) > dmax) return false;
  for (const auto& q : pr.dropped)
    if (distance_point_segment(q, pr.a, e) > dmax) return false;
  // Merge.
  pr.dropped.push_back(pr.b);
  if (pr.dropped.size() == 1) pr.eps -= dmax;  // (on top of a dropped spike's share)
  pr.b = e;
  pr.u = d / len;
  pr.len = len;
  pr.line = b.line;
  set_limits(pr, b.line);
  if (pr.has_prev && chords_.size() >= 2) {
    const Chord& pp = chords_[chords_.size() - 2];
    pr.turn = std::acos(std::clamp(pp.u.dot(pr.u), -1.0, 1.0));
  }
  vmax_seen_ = std::max(vmax_seen_, pr.cap);
  dvmin_seen_ = std::min(dvmin_seen_, pr.dv);
  dvmax_seen_ = std::max(dvmax_seen_, pr.dv);
  path_mm_ = pr.s0 + len;
  ++stats_.moves;
  return true;
}

// ------------------------------------------------------------------------------------------------
// Planning

double LookaheadPlanner::lookahead_mm() const {
  const double vmax = vmax_seen_, dvmin = dvmin_seen_, dvmax = dvmax_seen_;
  const double aq = dvmin * kFine / ((kFine + 1.0) * (L1_ + 1.0));
  double brake = std::isfinite(aq) ? vmax * vmax / (2.0 * aq) : 0.0;
  brake += 2.0 * rr_ * vmax;
  if (p_.lookahead_mm > 0.0) brake = p_.lookahead_mm;
  const double margin = std::min(dvmax, vmax) * (L_ + 1.0) + vmax * rr_;
  return brake + margin;
}

void LookaheadPlanner::maybe_plan() {
  if (chords_.empty()) return;
  const double s_c = committed_.chord < next_id_ && committed_.chord >= chords_.front().id
                         ? chord(committed_.chord).s0 + committed_.x
                         : path_mm_;
  const double ahead = path_mm_ - s_c;
  const std::int64_t n_ahead = next_id_ - committed_.chord;
  if (ahead >= 2.0 * lookahead_mm() ||
      n_ahead >= static_cast<std::int64_t>(p_.max_lookahead_chords))
    plan(false);
}

// The speed a stop at the start of chord id can be entered with: the command drops to zero at
// the vertex in one step, which the window rule allows when every command velocity of the L1
// periods before it is within A_i on each axis (speed <= dv of its chord): the smallest dv of the
// chords within that reach (at that speed) before the vertex. The output then brakes at the full
// axis rate over the window while the command rests (the rest is the time the stop costs).
double LookaheadPlanner::stop_entry(std::int64_t id) const {
  if (id <= chords_.front().id) return 0.0;
  const Chord& c = chord(id);
  double v = chord(id - 1).dv;
  if (!std::isfinite(v)) return kInf;
  for (std::int64_t k = id - 2; k >= chords_.front().id; --k) {
    const Chord& q = chord(k);
    if (c.s0 - (q.s0 + q.len) > v * rr_) break;
    v = std::min(v, q.dv);
  }
  return 0.999 * v;  // (dv is the window rule's bound itself: no rounding may cross it)
}

void LookaheadPlanner::decide(std::int64_t id, bool final) {
  Chord& c = chord(id);
  if (c.decided) return;
  c.C = kInf;
  c.C_acc = kInf;
  c.gap = 0;
  c.r = 0.0;
  c.C_out = kInf;
  c.C_after = kInf;
  c.short_regions = false;
  c.model_e = 0.0;
  c.stop_in = 0.0;
  if (c.stop) {
    c.C = 0.0;
    c.gap = L_ - 1;
    c.stop_in = stop_entry(id);
    c.decided = true;
    return;
  }
  if (id == chords_.front().id || c.turn < 1e-9) {
    c.decided = true;
    return;
  }
  const Chord& pr = chord(id - 1);
  const double dv0 = std::min(pr.dv, c.dv);
  const double q0 = std::isfinite(dv0) ? dv0 / (kFine + 1.0) : 0.0;  // slowest non-stop cap
  const double p = c.s0;
  const double v0 = std::min({pr.cap, pr.repair_cap, c.cap, c.repair_cap});
  // Neighbourhood within the largest half-span (v0 * rr / 2 on each side): per-axis direction
  // ranges and the turning of the other vertices, by distance from this vertex.
  const double span_max = v0 * rr_;
  // Each neighbour's per-axis direction change goes into du_at_: a chord before the vertex against
  // the next chord, one after it against the previous chord (see acc_cap below).
  const Vector3d u_prev = pr.u, u_next = c.u;
  std::vector<Nb>& nb = nb_;
  nb.clear();
  // The turn at the vertex between two chords as a vector: its angle along the change of direction.
  auto turn_vec = [](const Chord& before, const Chord& after) {
    const Vector3d du = after.u - before.u;
    return du.norm() > 1e-15 ? Vector3d(after.turn * du.normalized()) : Vector3d::Zero();
  };
  du_at_.clear();
  for (std::int64_t k = id - 1; k >= chords_.front().id; --k) {
    const Chord& q = chord(k);
    const double d = p - (q.s0 + q.len);  // distance from the vertex to q's end
    if (k < id - 1 && d > span_max) break;
    nb.push_back({std::max(0.0, d), k < id - 1 ? turn_vec(q, chord(k + 1)) : Vector3d::Zero()});
    du_at_.push_back({std::max(0.0, d), (u_next - q.u).cwiseAbs()});
  }
  for (std::int64_t k = id; k < next_id_; ++k) {
    const Chord& q = chord(k);
    const double d = q.s0 - p;
    if (k > id && d > span_max) break;
    nb.push_back({d, k > id ? turn_vec(chord(k - 1), q) : Vector3d::Zero()});
    du_at_.push_back({d, (q.u - u_prev).cwiseAbs()});
  }
  (void)final;
  // Per-axis acceleration cap at speed v. The window rule compares command velocities L1 periods
  // apart, i.e. up to W = v (L1 + 1) <= v rr of path apart. Every such pair (p1 before p2) straddles
  // the vertex at the start of p2's chord, with p2's chord at distance 0 after it and p1's chord
  // within W before it (and that vertex's cap covers both: its region is +-C rr). So each vertex
  // checks its next chord against the chords within v rr before it, and its previous chord against
  // the chords within v rr after it (one-sided). The first version (+-v rr / 2 on both sides)
  // missed pairs across three short chords: cam_dense_random's chords 945/948 made the window
  // infeasible at 0.0667 mm/period and the repair crawled at 7e-10 mm/period (12 GB of pulses);
  // +-v rr on both sides is safe but counts pairs 2 W apart (trochoidal_chords 1.64x slower).
  // The direction changes by distance, as a running maximum: acc_cap(v) looks up the neighbours
  // within v L1 in O(log n) (the fixed-point search below calls it ~15 times). v L1, not v rr:
  // the earlier period of a pair reaches at most one period of path past v L1, and there its
  // mean velocity mixes the chord's direction with the next one's; counting that chord whole held
  // the curves of chords at the speed where v rr reaches the next chord boundary
  // (trochoidal_chords, r = 2 mm in 0.25 mm chords: 0.98 x 55.5 mm/s; v L1: 4.6 % faster, the
  // window repairs unchanged on the 32 tp_compare programs; v (L1 - 1): 22 % slower, repairs). The
  // forward pass enforces the window rule exactly either way.
  std::sort(du_at_.begin(), du_at_.end(), [](const DuAt& a, const DuAt& b) { return a.d < b.d; });
  for (std::size_t k = 1; k < du_at_.size(); ++k) {
    du_at_[k].du = du_at_[k].du.cwiseMax(du_at_[k - 1].du);
  }
  auto du_within = [&](double v) {
    const double s = v * L1_;
    // The neighbours with d <= s (d == 0, the chords at the vertex, always).
    const auto it = std::upper_bound(du_at_.begin(), du_at_.end(), std::max(s, 0.0),
                                     [](double x, const DuAt& a) { return x < a.d; });
    return it == du_at_.begin() ? Vector3d::Zero() : Vector3d(std::prev(it)->du);
  };
  auto acc_cap = [&](double v) {
    const Vector3d du = du_within(v);
    double cap = kInf;
    for (int i = 0; i < 3; ++i)
      if (du[i] > 1e-12) cap = std::min(cap, A_[i] / du[i]);
    return cap;
  };
  // The largest constant speed the window rule allows through the neighbourhood (the span, and
  // so the direction change, shrinks with the speed). acc_cap is non-increasing in v, so the
  // speeds with acc_cap(v) >= v are an interval [0, v*]; v* lies between v1 = acc_cap(v0) and
  // acc_cap(v1). Two fixed-point steps from above, then a bisection: stopping at v1 (as the
  // first version did) held pcb2gcode's round pads (chords of 0.15 mm turning 5.7 degrees, r 1.5
  // mm) at about half the sqrt(a r) the axes allow (multivibrator-back 85.4 s -> 76.9 s).
  double cacc = acc_cap(v0);
  if (cacc < v0) {
    const double v1 = cacc;
    const double c1 = acc_cap(v1);
    double v = c1 >= v1 ? std::min(c1, v0) : v1;
    if (acc_cap(v) < v) {
      double lo = v1, hi = v;
      for (int it = 0; it < 16 && hi - lo > 1e-3 * lo; ++it) {
        const double mid = 0.5 * (lo + hi);
        if (acc_cap(mid) >= mid) lo = mid; else hi = mid;
      }
      v = lo;
    }
    cacc = v;
  }
  c.C_acc = cacc;
  c.du_acc = std::isfinite(cacc) ? du_within(cacc) : Vector3d::Zero();
  const double vhi = std::min(v0, acc_margin_ * (std::isfinite(cacc) ? cacc : kInf));
  // Tolerance model: e(v, g) = v (ks(g) + |sum_others(v) n_j| sigma^2 / (2 rr)).
  const BlendMode mode = pr.mode;
  double eps = std::min(pr.eps, c.eps) * c.f;
  if (mode == BlendMode::kFull) eps = kInf;
  const double st = std::sin(0.5 * c.turn);
  auto ks = [&](int g) {
    return 2.0 * alpha_[static_cast<std::size_t>(g)] * st + st / (4.0 * std::max(1, L_ - g));
  };
  // The curve term sums the neighbours within the output window as vectors (each displaces the
  // output towards the inside of its turn, so turns the other way cancel: a chord zigzag, an S),
  // not their angles: pcb2gcode multivibrator-milldrill 29.1 -> 26.9 s, 3D_Chips 63.9 -> 62.8 s.
  // (Summing the vertex's own turn into the same vector was faster still on multivibrator-back,
  // 57.5 -> 55.7 s, but underestimated often enough to triple the tolerance repairs there, and
  // planning fell to 675x real time.)
  auto others = [&](double vv) {
    const double s = 0.5 * vv * rr_;
    Vector3d t = Vector3d::Zero();
    for (const auto& n : nb)
      if (n.d <= s) t += n.n;
    return t.norm();
  };
  auto err = [&](double vv, int g) { return vv * (ks(g) + others(vv) * sigma2_ / (2.0 * rr_)); };
  // Largest speed <= vtop with err <= eps (err is increasing in v).
  auto speed_for = [&](double vtop, int g) {
    if (!std::isfinite(eps) || err(vtop, g) <= eps) return vtop;
    double lo = 0.0, hi = vtop;
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (err(mid, g) <= eps) lo = mid; else hi = mid;
    }
    return lo;
  };
  const double aq = dv0 * kFine / ((kFine + 1.0) * (L1_ + 1.0));
  // Short regions. The tolerance model only needs the cap over the window of the output nearest
  // the vertex: +-cc rr_in (err() counts the other vertices within cc rr / 2). The window rule
  // across the vertex needs every command velocity w of the L1 periods before it to allow cc on
  // the chords after it that the L1 periods after it reach, |w_i - cc ua_i| <= A_i (then cc lies in
  // the forward pass's window interval there; the rise after the inner region is the forward
  // pass's own): a cap cb over the rr periods before the vertex (cb rr of path, so the L1 periods
  // before it lie on the chords within cb rr). Returns 0 where no cap cb >= cc does it.
  // The directions it needs are collected once per decision: per axis the largest positive and
  // the largest negative component of the chords before the vertex (within v_before rr, as cb <=
  // v_before), and the running min / max of the chords after it by distance (within v_after rr).
  // With |cc ua_i| <= lim every pair's bound is (cc ua_i + lim) / ub_i (ub_i > 0) or
  // (lim - cc ua_i) / |ub_i| (ub_i < 0), so the smallest is that of the extreme components.
  constexpr std::size_t kMaxChords = 48;
  const double v_before = std::min(pr.cap, pr.repair_cap);
  const double v_after = std::min(c.cap, c.repair_cap);
  // The chords before the vertex (by the distance of their end from it, within v_before rr) and
  // after it (by the distance of their start, within v_after rr), each as running per-axis min /
  // max of their directions, at most kMaxChords; *_overflow_d: the distance of the first chord
  // left out.
  auto add_running = [&](std::vector<UaAt>& list, double d, const Vector3d& u, double& overflow_d) {
    if (list.size() == kMaxChords) {
      overflow_d = d;
      return false;
    }
    UaAt e{d, u, u};
    if (!list.empty()) {
      e.mn = e.mn.cwiseMin(list.back().mn);
      e.mx = e.mx.cwiseMax(list.back().mx);
    }
    list.push_back(e);
    return true;
  };
  ub_at_.clear();
  double ub_overflow_d = kInf;
  for (std::int64_t k = id - 1; k >= chords_.front().id; --k) {
    const Chord& q = chord(k);
    const double d = k == id - 1 ? 0.0 : p - (q.s0 + q.len);
    if (k < id - 1 && d > v_before * rr_) break;
    if (!add_running(ub_at_, d, q.u, ub_overflow_d)) break;
  }
  ua_at_.clear();
  double ua_overflow_d = kInf;
  for (std::int64_t k = id; k < next_id_; ++k) {
    const Chord& q = chord(k);
    const double d = k == id ? 0.0 : q.s0 - p;
    if (k > id && d > v_after * rr_) break;
    if (!add_running(ua_at_, d, q.u, ua_overflow_d)) break;
  }
  // The largest cap cb >= cc over the rr periods before the vertex that keeps the window rule
  // across it with the chords within cb rr before it (a lower cb reaches fewer chords, so the
  // chords far back on a curve, whose directions differ most, do not count against it), or 0.
  // The after side: cc ua_i for the chords the L1 periods after the vertex reach. For g = 0 the
  // pairs only bound cb from above here: a speed before the vertex far below cc (a lower bound
  // where |cc ua_i| > A_i) is left to the forward pass, which holds the window rule exactly and
  // repairs a cap where it cannot; across a rest (g > 0) the command is zero, so |cc ua_i| <= A_i.
  auto cap_before = [&](double cc, int g) {
    if (ub_at_.empty()) return 0.0;
    const double reach_a = cc * rr_in_ + v_after * (rr_ - rr_in_);
    if (reach_a >= ua_overflow_d) return 0.0;
    std::size_t m = 0;  // the chords after the vertex the L1 periods after it reach: [0, m]
    while (m + 1 < ua_at_.size() && ua_at_[m + 1].d <= reach_a) ++m;
    const Vector3d& mn = ua_at_[m].mn;
    const Vector3d& mx = ua_at_[m].mx;
    Vector3d lim;
    for (int i = 0; i < 3; ++i) {
      lim[i] = A_[i] * (1.0 - 1e-6);
      if (std::isfinite(A_[i]) && g > 0 && (std::abs(cc * mn[i]) > lim[i] || std::abs(cc * mx[i]) > lim[i]))
        return 0.0;
    }
    // The bound with the chords before within [0, j].
    auto bound = [&](std::size_t j) {
      const Vector3d ub_pos = ub_at_[j].mx.cwiseMax(0.0), ub_neg = (-ub_at_[j].mn).cwiseMax(0.0);
      double cb = v_before;
      for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(A_[i])) continue;
        // [lo, hi] = [b - lim, b + lim] for v ub_i (and within [-lim, lim] across a rest).
        if (ub_pos[i] > 1e-15) {
          double hi = cc * mn[i] + lim[i];
          if (g > 0) hi = std::min(hi, lim[i]);
          cb = std::min(cb, hi / ub_pos[i]);
        }
        if (ub_neg[i] > 1e-15) {
          double lo = cc * mx[i] - lim[i];
          if (g > 0) lo = std::max(lo, -lim[i]);
          cb = std::min(cb, lo / -ub_neg[i]);
        }
      }
      return cb;
    };
    // cb rr reaches the chords [0, j] for cb in [d_j / rr, d_{j+1} / rr); the bound does not
    // increase with j, so the first range without a feasible cb ends the search.
    double best = 0.0;
    for (std::size_t j = 0; j < ub_at_.size(); ++j) {
      const double x_lo = std::max(cc, ub_at_[j].d / rr_);
      double x_hi = (j + 1 < ub_at_.size() ? ub_at_[j + 1].d : ub_overflow_d) / rr_;
      x_hi = std::min(x_hi * (1.0 - 1e-9), v_before);
      if (x_lo > x_hi) {
        if (x_lo > v_before) break;
        continue;
      }
      const double x = std::min(bound(j), x_hi);
      if (x < x_lo) break;
      best = std::max(best, x);
    }
    return best >= cc ? best : 0.0;
  };
  auto cost = [&](double cc, int g) {
    double pen = 2.0 * rr_ * (1.0 - cc / v0);
    const double cb = cap_before(cc, g);
    if (cb > 0.0) {
      pen = 2.0 * rr_in_ * (1.0 - cc / v0);
      if (cb < v0) pen += (rr_ - rr_in_) * (1.0 - cb / v0);
    }
    if (std::isfinite(aq) && aq > 0.0) pen += (v0 - cc) * (v0 - cc) / (aq * v0);
    return g + pen;
  };
  double best_c = 0.0, best_cost = kInf;
  int best_g = L_ - 1;
  // Stop at the vertex: always possible. Its rest is what it costs, plus the braking before it
  // and the rise after it. A sharp corner (>= 90 deg) the feed reaches at no more than the
  // speed the command may drop to zero from in one step (stop_entry) needs no braking: the
  // output brakes at the full axis rate over the window while the command rests, and the rise
  // reaches c.dv in one step (short_reversals: 11.07 -> 10.71 s; LinuxCNC 10.43 s). Elsewhere
  // braking to a stop is charged at the fine ramp's rate (choosing stops where the feed must
  // first brake to stop_entry made pcb2gcode's 5-degree pads stops: multivibrator-back 1.45x).
  const double stop_in = stop_entry(id);
  {
    double cs = L_ - 1;
    if (std::isfinite(aq) && aq > 0.0) {
      if (c.turn >= 0.5 * std::numbers::pi && v0 <= stop_in) {
        const double up = std::max(0.0, v0 - c.dv);
        cs += up * up / (2.0 * aq * v0);
      } else {
        cs += v0 / aq;
      }
    }
    best_cost = cs;
  }
  // Speed only (g = 0) and with a rest (the overlap reduction of seed 004) at speeds up to what
  // a rest allows (the command drops to zero at the vertex: v |u_i| <= A_i on both sides).
  const double c_speed = speed_for(vhi, 0);
  // A corner the chords' own caps already hold below q0 (a slow feed next to a rapid) is passed at
  // that speed, not turned into an exact stop with its rest of L - 1 periods: openvoronoi-ttt-vcarve
  // (F6 plunges between rapids) stopped ~1000 times, 16 s of its 112 s excess over LinuxCNC.
  const bool uncapped = c_speed >= v0 * (1.0 - 1e-9);
  if ((c_speed > q0 || uncapped) && cost(c_speed, 0) < best_cost) {
    best_c = c_speed;
    best_g = 0;
    best_cost = cost(c_speed, 0);
  }
  if (std::isfinite(eps)) {
    const double c_rest = std::min(vhi, dv0 * (1.0 - 1e-9));
    for (int k = 0; k <= 4; ++k) {
      const double cc = c_speed + (c_rest - c_speed) * k / 4.0;
      if (!(cc > q0) || cc < c_speed) continue;
      int g = 0;
      while (g < L_ - 1 && err(cc, g) > eps) ++g;
      if (err(cc, g) > eps) continue;
      if (cost(cc, g) < best_cost) {
        best_cost = cost(cc, g);
        best_c = cc;
        best_g = g;
      }
    }
  }
  if (best_c <= 0.0) {
    c.C = 0.0;
    c.gap = L_ - 1;
    c.stop = true;
    c.stop_in = stop_in;
  } else {
    c.C = best_c;
    c.gap = best_g;
    const double cb = cap_before(best_c, best_g);
    c.short_regions = cb > 0.0;
    c.C_out = cb > best_c && cb < v_before ? cb : kInf;
    c.r = !c.short_regions ? best_c * rr_
                           : std::max(best_c * rr_in_, std::isfinite(c.C_out) ? c.C_out * rr_ : 0.0);
    c.model_e = err(best_c, best_g);
    // After the vertex the forward pass holds the window rule against the real history, so a
    // cap there only serves the tolerance: where C is the acceleration cap's, the speed the
    // tolerance model allows holds over the output window after the vertex instead (the curve's
    // last vertex no longer holds its cap L + 1 periods into the straight after it).
    c.C_after = best_g == 0 ? std::max(best_c, speed_for(v0, 0)) : best_c;
    if (std::isfinite(c.C_after) && c.C_after > best_c) c.r = std::max(c.r, c.C_after * rr_in_);
  }
  c.decided = true;
}

void LookaheadPlanner::build_pieces(double s_from, double s_stop, bool final) {
  (void)final;
  pieces_.clear();
  struct Ev {
    double pos;
    bool start;
    double cap, cacc;
    std::int64_t id;
  };
  thread_local std::vector<Ev> ev;
  ev.clear();
  for (const auto& c : chords_) {
    if (c.decided && c.stop && c.stop_in > 0.0 && std::isfinite(c.stop_in)) {
      // A stop entered at stop_in: every command velocity of the window before it within A_i.
      if (c.s0 > s_from && c.s0 - c.stop_in * rr_ < s_stop) {
        ev.push_back({c.s0 - c.stop_in * rr_, true, c.stop_in, kInf, c.id});
        ev.push_back({c.s0, false, c.stop_in, kInf, c.id});
      }
      continue;
    }
    if (!c.decided || c.stop || !std::isfinite(c.C)) continue;
    if (c.s0 + c.r <= s_from || c.s0 - c.r >= s_stop) continue;
    const double ri = c.C * (c.short_regions ? rr_in_ : rr_);
    ev.push_back({c.s0 - ri, true, c.C, c.C_acc, c.id});
    if (c.C_after > c.C) {
      // C before the vertex, C_after over the output window after it (see decide()).
      ev.push_back({c.s0, false, c.C, c.C_acc, c.id});
      if (std::isfinite(c.C_after)) {
        ev.push_back({c.s0, true, c.C_after, c.C_acc, c.id});
        ev.push_back({c.s0 + c.C_after * rr_in_, false, c.C_after, c.C_acc, c.id});
      }
    } else {
      ev.push_back({c.s0 + ri, false, c.C, c.C_acc, c.id});
    }
    if (c.short_regions && std::isfinite(c.C_out)) {
      // The window rule's cap, not a curve's: it takes nothing from the braking there.
      ev.push_back({c.s0 - c.C_out * rr_, true, c.C_out, kInf, c.id});
      ev.push_back({c.s0, false, c.C_out, kInf, c.id});
    }
  }
  std::sort(ev.begin(), ev.end(), [](const Ev& x, const Ev& y) { return x.pos < y.pos; });
  std::multiset<double> caps;
  std::multiset<std::pair<double, std::int64_t>> caccs;
  std::size_t ei = 0;
  auto apply_to = [&](double x) {
    while (ei < ev.size() && ev[ei].pos <= x + kTiny) {
      if (ev[ei].start) {
        caps.insert(ev[ei].cap);
        caccs.insert({ev[ei].cacc, ev[ei].id});
      } else {
        caps.erase(caps.find(ev[ei].cap));
        caccs.erase(caccs.find({ev[ei].cacc, ev[ei].id}));
      }
      ++ei;
    }
  };
  for (std::int64_t k = committed_.chord; k < next_id_; ++k) {
    const Chord& c = chord(k);
    double x0 = std::max(s_from, c.s0);
    const double x1 = std::min(s_stop, c.s0 + c.len);
    if (x1 <= x0 + kTiny) {
      if (c.s0 >= s_stop) break;
      continue;
    }
    while (x0 < x1 - kTiny) {
      apply_to(x0);
      double nx = x1;
      if (ei < ev.size() && ev[ei].pos < x1 - kTiny) nx = std::max(ev[ei].pos, x0 + kTiny);
      Piece pc;
      pc.s0 = x0;
      pc.s1 = nx;
      pc.chord = k;
      pc.cap = std::min(c.cap, c.repair_cap);
      if (!caps.empty()) pc.cap = std::min(pc.cap, *caps.begin());
      if (!caccs.empty()) {
        pc.cacc = caccs.begin()->first;
        pc.cacc_chord = caccs.begin()->second;
      }
      pieces_.push_back(pc);
      x0 = nx;
    }
  }
}

void LookaheadPlanner::backward_pass(bool final) {
  (void)final;
  const double wd = L1_ + 1.0;
  auto aq_of = [&](double dv) { return dv * kFine / ((kFine + 1.0) * wd); };
  if (pieces_.empty()) return;
  const Chord& last = chord(pieces_.back().chord);
  const double q0e = last.dv / (kFine + 1.0);
  double qnext = q0e * q0e;
  for (std::size_t k = pieces_.size(); k-- > 0;) {
    Piece& pc = pieces_[k];
    const Chord& c = chord(pc.chord);
    double qe = qnext;
    // A stop or a rest at the vertex at this piece's end.
    if (k + 1 < pieces_.size() && pieces_[k + 1].chord != pc.chord) {
      const Chord& nx = chord(pieces_[k + 1].chord);
      if (nx.stop) {
        const double q0 = std::min(c.dv, nx.dv) / (kFine + 1.0);
        const double vin = nx.decided && nx.stop_in > q0 ? nx.stop_in : q0;
        qe = std::min(qe, vin * vin);
      }
    }
    pc.qe = qe;
    const double len = pc.s1 - pc.s0;
    const double a_line = aq_of(c.dv);
    double vhi2 = pc.cap * pc.cap;
    if (std::isfinite(a_line)) vhi2 = std::min(vhi2, qe + 2.0 * a_line * len);
    double dv = c.dv;
    if (std::isfinite(pc.cacc)) {
      // The tangential budget left by the curve, per axis: over a window the curve turns the
      // velocity of axis i by about v du_i (v / C_acc) (du_i: the direction change C_acc sees;
      // the window's span shrinks with v), and the speed may change by the rest of A_i along
      // u_i. An axis the curve loads but the path does not run along does not limit the
      // braking (the isotropic 1 - v / C_acc did: pcb2gcode's pads braked at 1/5 of the limit).
      const Vector3d& du = chord(pc.cacc_chord).du_acc;
      const double use = vhi2 / pc.cacc;
      double b = kInf;
      for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(A_[i])) continue;
        const double ui = std::abs(c.u[i]);
        if (ui > 1e-12) b = std::min(b, std::max(0.0, A_[i] - use * du[i]) / ui);
      }
      dv = std::min(dv, b);
    }
    pc.aq = aq_of(dv);
    double qs = pc.cap * pc.cap;
    if (std::isfinite(pc.aq)) qs = std::min(qs, qe + 2.0 * pc.aq * len);
    qnext = qs;
  }
}

double LookaheadPlanner::q_at(double s, std::size_t from) const {
  double q = kInf;
  for (std::size_t k = from; k < pieces_.size(); ++k) {
    const Piece& pc = pieces_[k];
    if (s < pc.s1) {
      double v = pc.cap * pc.cap;
      if (std::isfinite(pc.aq)) v = std::min(v, pc.qe + 2.0 * pc.aq * (pc.s1 - std::max(s, pc.s0)));
      return std::min(q, v);
    }
    q = std::min(q, pc.qe);
  }
  return pieces_.empty() ? 0.0 : std::min(q, pieces_.back().qe);
}

void LookaheadPlanner::window_interval(const History& h, const Vector3d& u, double& lo,
                                       double& hi) const {
  lo = 0.0;
  hi = kInf;
  const std::size_t H = h.ring.size();
  Vector3d mn = h.w_prev, mx = h.w_prev;
  for (std::int64_t n = h.newest + 1 - L1_; n <= h.newest; ++n) {
    const auto idx = static_cast<std::size_t>(((n % static_cast<std::int64_t>(H)) +
                                               static_cast<std::int64_t>(H)) %
                                              static_cast<std::int64_t>(H));
    mn = mn.cwiseMin(h.ring[idx]);
    mx = mx.cwiseMax(h.ring[idx]);
  }
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(A_[i])) continue;
    const double ui = u[i];
    if (std::abs(ui) < 1e-12) {
      if (mx[i] > A_[i] || mn[i] < -A_[i]) lo = kInf;
      continue;
    }
    const double up = mn[i] + A_[i], dn = mx[i] - A_[i];  // dn <= v ui <= up
    if (ui > 0) {
      hi = std::min(hi, up / ui);
      lo = std::max(lo, dn / ui);
    } else {
      hi = std::min(hi, dn / ui);
      lo = std::max(lo, up / ui);
    }
  }
}

void LookaheadPlanner::append(State& st, const Pulse& p) const {
  History& h = st.hist;
  const Vector3d w = p.v > 0.0 ? Vector3d(chord(p.chord).u * p.v) : Vector3d::Zero();
  const double t0 = p.t0, t1 = p.t0 + p.dur;
  const auto H = static_cast<std::int64_t>(h.ring.size());
  const std::int64_t n_first = h.newest + 1;
  const auto n_done = static_cast<std::int64_t>(std::floor(t1));
  auto slot = [&](std::int64_t n) -> Vector3d& {
    return h.ring[static_cast<std::size_t>(((n % H) + H) % H)];
  };
  if (n_done >= n_first) {
    for (std::int64_t n = std::max(n_first, n_done - H + 1); n <= n_done; ++n) {
      const double ov = std::min(static_cast<double>(n), t1) - std::max(static_cast<double>(n - 1), t0);
      slot(n) = (n == n_first ? h.partial : Vector3d::Zero()) + w * std::max(0.0, ov);
    }
    h.newest = n_done;
    h.partial = w * (t1 - static_cast<double>(n_done));
  } else {
    h.partial += w * (t1 - t0);
  }
  h.w_prev = w;
  st.tau = t1;
  if (p.v > 0.0) {
    st.chord = p.chord;
    st.x = p.x1;
    const Chord& c = chord(p.chord);
    if (st.x >= c.len - kTiny) {
      st.chord = p.chord + 1;
      st.x = 0.0;
      st.rest_done = false;
    }
  }
}

bool LookaheadPlanner::forward(const State& start, double s_stop, double s_commit, Failure& fail) {
  State st = start;
  pulses_.clear();
  bool snapped = false;
  std::size_t pi = 0;
  auto pos_of = [&](const State& s) {
    return s.chord < next_id_ ? chord(s.chord).s0 + s.x : path_mm_;
  };
  auto rest_ok = [&](const History& h) {
    double lo = 0.0, hi = 0.0;
    window_interval(h, Vector3d::Zero(), lo, hi);
    return !(lo > 0.0);
  };
  while (true) {
    const double pos = pos_of(st);
    if (!snapped && pos >= s_commit - kTiny) {
      st_commit_ = st;
      commit_pulses_ = pulses_.size();
      snapped = true;
    }
    if (pos >= s_stop - kTiny || st.chord >= next_id_) break;
    const Chord& c = chord(st.chord);
    if (st.x <= kTiny && !st.rest_done) {
      st.rest_done = true;
      const int rest = c.stop ? L_ - 1 : (c.decided ? c.gap : 0);
      if (rest > 0) {
        if (!rest_ok(st.hist)) {
          fail.kind = Failure::Kind::kWindow;
          fail.chord = st.chord - 1;
          fail.cap = st.hist.w_prev.norm();
          return false;
        }
        Pulse r;
        r.t0 = st.tau;
        r.dur = rest;
        r.chord = st.chord;
        append(st, r);
        pulses_.push_back(r);
        continue;
      }
    }
    while (pi + 1 < pieces_.size() && pieces_[pi].s1 <= pos + kTiny) ++pi;
    if (pieces_.empty() || pieces_[pi].s1 <= pos + kTiny) break;
    const Piece& pc = pieces_[pi];
    double lo = 0.0, hi = kInf;
    window_interval(st.hist, c.u, lo, hi);
    double v = std::min(pc.cap, hi);
    // Braking profile: the speed must be one the look-ahead can still brake from at the end of
    // a fine step (the largest fixed point of v = sqrt(Q(pos + v delta)), from above).
    double vb = v;
    double v_late = -1.0;  // a speed known to brake too late
    for (int it = 0; it < 6; ++it) {
      const double q = std::sqrt(std::max(0.0, q_at(pos + vb * delta_, pi)));
      if (q >= vb) break;
      v_late = vb;
      vb = q;
    }
    // The iteration from above can stop well below the largest fixed point: where the profile is
    // steep, the end of a fine step at the higher speed lands deep in the braking into a slow
    // vertex. The speeds with v <= sqrt(Q(pos + v delta)) are an interval [0, v*] (q_at takes the
    // minimum over the pieces passed, so it does not increase along the path): a bisection finds v*.
    if (v_late > 0.0) {
      double ok = std::sqrt(std::max(0.0, q_at(pos + vb * delta_, pi))) >= vb ? vb : 0.0;
      for (int it = 0; it < 12 && v_late - ok > 1e-4 * v_late; ++it) {
        const double mid = 0.5 * (ok + v_late);
        if (std::sqrt(std::max(0.0, q_at(pos + mid * delta_, pi))) >= mid) ok = mid; else v_late = mid;
      }
      vb = ok;
    }
    const bool braking = vb < v;
    v = std::min(v, vb);
    if (!(v > 0.0) || v < lo * (1.0 - 1e-9)) {
      fail.kind = Failure::Kind::kWindow;
      fail.chord = st.chord;
      fail.cap = std::max(0.0, std::min(pc.cap, hi));
      return false;
    }
    double e = 0.0;
    if (braking || hi < pc.cap) {
      e = pos + v * delta_;
    } else {
      // Cruise at the cap: until the braking profile falls below v.
      // Q(e) >= v^2 at the pulse end; Q within the piece already holds everything after it.
      e = pc.s1;
      if (pc.qe < v * v && std::isfinite(pc.aq)) {
        const double x = pc.aq > 0.0 ? pc.s1 - (v * v - pc.qe) / (2.0 * pc.aq) : pc.s0;
        e = std::min(e, std::max(x, pc.s0));
      }
      if (e < pos + 0.25 * v * delta_) e = pos + v * delta_;
    }
    e = std::min(e, pc.s1);
    if (pc.s1 - e < 0.25 * v * delta_) e = pc.s1;
    if (e > s_stop) e = s_stop;
    Pulse pl;
    pl.t0 = st.tau;
    pl.chord = c.id;
    pl.x0 = st.x;
    pl.x1 = (e >= c.s0 + c.len - kTiny) ? c.len : e - c.s0;
    pl.v = v;
    pl.dur = (pl.x1 - pl.x0) / v;
    if (!(pl.dur > 0.0)) {
      // Nothing left of this piece (rounding): step to the next piece.
      st.x = pl.x1;
      if (st.x >= c.len - kTiny) {
        st.chord = c.id + 1;
        st.x = 0.0;
        st.rest_done = false;
      }
      continue;
    }
    append(st, pl);
    pulses_.push_back(pl);
  }
  // The plan ends at rest: the drop to zero must satisfy the window rule too.
  if (!pulses_.empty() && !rest_ok(st.hist)) {
    fail.kind = Failure::Kind::kWindow;
    fail.chord = pulses_.back().chord;
    fail.cap = pulses_.back().v;
    return false;
  }
  st_end_ = st;
  if (!snapped) {
    st_commit_ = st;
    commit_pulses_ = pulses_.size();
  }
  return true;
}

bool LookaheadPlanner::verify(const VerifyState& vs0, std::int64_t t_commit, VerifyState& at_commit,
                              VerifyState& at_end, Failure& fail) {
  ++stats_.verifications;
  seq_.clear();
  seq_.insert(seq_.end(), vs0.tail.begin(), vs0.tail.end());
  const std::size_t n_tail = seq_.size();
  std::size_t n_committed = n_tail;  // pulses of seq_ that belong to the commit
  for (std::size_t i = 0; i < pulses_.size(); ++i) {
    if (pulses_[i].v <= 0.0) continue;
    seq_.push_back(pulses_[i]);
    if (i < commit_pulses_) n_committed = seq_.size();
  }
  const double tau_end = st_end_.tau;
  const auto t_end = static_cast<std::int64_t>(std::ceil(tau_end - 1e-9)) + L_ - 1;
  std::vector<std::pair<std::int64_t, double>> open = vs0.vbest;
  seq_geo_.resize(seq_.size());
  for (std::size_t i = 0; i < seq_.size(); ++i) {
    const Chord& c = chord(seq_[i].chord);
    PulseGeo& g = seq_geo_[i];
    g.p0 = point(c, seq_[i].x0);
    g.p1 = point(c, seq_[i].x1);
    g.d = g.p1 - g.p0;
  }
  std::size_t lo = 0, hi = 0;
  Vector3d base = seq_.empty() ? vs0.y : seq_geo_[0].p0;
  Vector3d y_prev = vs0.y;
  std::int64_t pmin = -1, pmax = -1;  // chord range of the previous period
  if (!vs0.tail.empty()) {
    pmin = vs0.tail.front().chord;
    pmax = vs0.tail.back().chord;
  }
  std::size_t lo_at_commit = 0;
  bool commit_snapped = false;
  auto vertex_eps = [&](std::int64_t k) {
    const Chord& c = chord(k);
    return k > chords_.front().id ? std::min(c.eps, chord(k - 1).eps) : c.eps;
  };
  auto snapshot = [&](std::int64_t t, VerifyState& vs) {
    vs.t = t;
    vs.y = y_prev;
    vs.vbest = open;
    lo_at_commit = lo;
    commit_snapped = true;
  };
  if (t_commit <= vs0.t) snapshot(vs0.t, at_commit);
  std::int64_t last_chord = seq_.empty() ? committed_.chord : seq_.back().chord;
  std::int64_t dist_lo = 0, dist_hi = -1;  // chords with a distance in dist_prev_
  for (std::int64_t t = vs0.t + 1; t <= t_end; ++t) {
    const double td = static_cast<double>(t);
    while (hi < seq_.size() && seq_[hi].t0 < td) ++hi;
    while (lo < hi && seq_[lo].t0 + seq_[lo].dur + (L_ - 1) <= td) {
      base = seq_geo_[lo].p1;
      ++lo;
    }
    Vector3d y = base;
    for (std::size_t i = lo; i < hi; ++i) {
      const Pulse& p = seq_[i];
      const double f = fir_.progress(td - p.t0, p.dur) / p.dur;
      y += f * seq_geo_[i].d;
    }
    std::int64_t cmin = -1, cmax = -1;
    if (lo < hi) {
      cmin = seq_[lo].chord;
      cmax = seq_[hi - 1].chord;
    } else if (lo < seq_.size()) {
      cmin = cmax = seq_[lo].chord;
    } else {
      cmin = cmax = last_chord;
    }
    std::int64_t umin = cmin, umax = cmax;
    if (pmin >= 0) {
      umin = std::min(umin, pmin);
      umax = std::max(umax, pmax);
    }
    umin = std::max(umin, chords_.front().id);
    umax = std::min(umax, next_id_ - 1);
    if (umax > umin) {
      // Path error of the output chord [y_prev, y] against the programmed chords in motion.
      // A chord checked in the previous period has its distance to y_prev from then.
      double a0 = kInf, a1 = kInf, b0 = kInf, b1 = kInf, eps = kInf;
      dist_now_.resize(static_cast<std::size_t>(umax - umin + 1));
      for (std::int64_t k = umin; k <= umax; ++k) {
        const Chord& c = chord(k);
        const double d0 = k >= dist_lo && k <= dist_hi
                              ? dist_prev_[static_cast<std::size_t>(k - dist_lo)]
                              : distance_point_segment(y_prev, c.a, c.b);
        const double d1 = distance_point_segment(y, c.a, c.b);
        dist_now_[static_cast<std::size_t>(k - umin)] = d1;
        eps = std::min(eps, c.eps);
        if (d0 < a0) {
          a0 = d0;
          a1 = d1;
        }
        if (d1 < b1) {
          b1 = d1;
          b0 = d0;
        }
      }
      dist_prev_.swap(dist_now_);
      dist_lo = umin;
      dist_hi = umax;
      const double e = chord_bound(a0, a1, b0, b1);
      if (e > eps) {
        fail.kind = Failure::Kind::kSample;
        fail.lo = umin;
        fail.hi = umax;
        fail.e = e;
        fail.eps = eps;
        return false;
      }
      // Vertices in motion: two-sided (each within eps of the output polyline).
      for (std::int64_t k = umin + 1; k <= umax; ++k) {
        const Chord& c = chord(k);
        if (c.turn <= 0.0) continue;
        const double d = distance_point_segment(c.a, y_prev, y);
        auto it = std::find_if(open.begin(), open.end(), [&](const auto& o) { return o.first == k; });
        if (it == open.end()) {
          open.emplace_back(k, d);
        } else {
          it->second = std::min(it->second, d);
        }
      }
    } else {
      dist_hi = dist_lo - 1;  // no distances from this period
    }
    // Vertices the output window has left.
    for (std::size_t i = 0; i < open.size();) {
      if (open[i].first < cmin) {
        if (open[i].second > vertex_eps(open[i].first)) {
          fail.kind = Failure::Kind::kVertex;
          fail.chord = open[i].first;
          fail.e = open[i].second;
          fail.eps = vertex_eps(open[i].first);
          return false;
        }
        open.erase(open.begin() + static_cast<std::ptrdiff_t>(i));
      } else {
        ++i;
      }
    }
    y_prev = y;
    pmin = cmin;
    pmax = cmax;
    if (!commit_snapped && t >= t_commit) snapshot(t, at_commit);
  }
  for (const auto& o : open) {
    if (o.second > vertex_eps(o.first)) {
      fail.kind = Failure::Kind::kVertex;
      fail.chord = o.first;
      fail.e = o.second;
      fail.eps = vertex_eps(o.first);
      return false;
    }
  }
  open.clear();  // the plan ends at rest: every vertex is final
  at_end.t = std::max(t_end, vs0.t);
  at_end.y = y_prev;
  at_end.tail.clear();
  at_end.vbest.clear();
  if (!commit_snapped) snapshot(at_end.t, at_commit);
  // Pulses of the commit still moving the output after its last final period.
  at_commit.tail.clear();
  for (std::size_t i = std::min(lo_at_commit, n_committed); i < n_committed; ++i)
    at_commit.tail.push_back(seq_[i]);
  (void)n_tail;
  return true;
}

void LookaheadPlanner::emit(const Pulse& p) {
  const Chord& c = chord(p.chord);
  PlannedSegment s;
  s.kind = SegmentKind::kMotion;
  const double fl = std::floor(p.t0);
  s.start_cycle = static_cast<std::int64_t>(fl);
  s.start_offset_cycles = p.t0 - fl;
  s.duration_cycles = p.dur;
  s.samples = std::max<std::int64_t>(
      1, static_cast<std::int64_t>(std::ceil(s.start_offset_cycles + p.dur - 1e-12)));
  s.start_mm = point(c, p.x0);
  s.end_mm = point(c, p.x1);
  s.length_mm = p.x1 - p.x0;
  s.path_start_mm = c.s0 + p.x0;
  s.feed_mm_min = c.feed_mm_min;
  s.speed_mm_min = p.v / T_ * 60.0;
  s.line = c.line;
  s.rapid = c.rapid;
  s.spindle = c.spindle;
  s.spindle_rpm = c.rpm;
  s.mist = c.mist;
  s.flood = c.flood;
  s.tool = c.tool;
  out_.push_back(s);
  ++stats_.segments;
}

void LookaheadPlanner::report_corner(Chord& c) {
  if (c.reported) return;
  c.reported = true;
  if (!corner_cb_ || c.id == chords_.front().id) return;
  if (c.turn <= 0.0 && !c.stop) return;
  const Chord& pr = chord(c.id - 1);
  CornerReport r;
  r.move_index = c.id;
  r.line = c.line;
  r.prev_line = pr.line;
  r.vertex_mm = c.a;
  r.angle_deg = c.turn * 180.0 / std::numbers::pi;
  r.overlap_cycles = L_ - 1 - (c.stop ? L_ - 1 : c.gap);
  r.model_error_mm = c.model_e;
  r.tolerance_mm = pr.mode == BlendMode::kLimited ? std::min(pr.tol, c.tol) : 0.0;
  r.corner_speed_mm_min = std::isfinite(c.C) ? c.C / T_ * 60.0 : pr.feed_mm_min;
  corner_cb_(r);
}

void LookaheadPlanner::commit(std::size_t n, const State& st, const VerifyState& vs) {
  for (std::size_t i = 0; i < n; ++i)
    if (pulses_[i].v > 0.0) emit(pulses_[i]);
  for (std::int64_t k = std::max(chords_.front().id, committed_.chord);
       k < next_id_ && (k < st.chord || (k == st.chord && st.x > 0.0)); ++k)
    report_corner(chord(k));
  committed_ = st;
  vcommitted_ = vs;
}

void LookaheadPlanner::trim() {
  if (chords_.empty()) return;
  const double s_c = committed_.chord < next_id_ ? chord(committed_.chord).s0 + committed_.x : path_mm_;
  std::int64_t keep = committed_.chord;
  for (const auto& p : vcommitted_.tail) keep = std::min(keep, p.chord);
  for (const auto& o : vcommitted_.vbest) keep = std::min(keep, o.first);
  if (have_fallback_) {
    for (const auto& p : fallback_) keep = std::min(keep, p.chord);
  }
  keep -= 1;  // the chord before a kept vertex (its eps)
  const double reach = vmax_seen_ * rr_ * 2.0 + 1e-6;
  while (chords_.size() > 1 && chords_.front().id < keep) {
    const Chord& c = chords_.front();
    if (c.s0 + c.len + c.r > s_c - reach) break;
    chords_.pop_front();
  }
}

void LookaheadPlanner::plan(bool final) {
  if (chords_.empty() || committed_.chord >= next_id_) return;
  ++stats_.plans;
  const double s_c = chord(committed_.chord).s0 + committed_.x;
  const double s_end = path_mm_;
  double margin = 0.0, brake = 0.0;
  if (!final) {
    const double la = lookahead_mm();
    margin = std::min(dvmax_seen_, vmax_seen_) * (L_ + 1.0) + vmax_seen_ * rr_;
    brake = la - margin;
  }
  double s_stop = s_end - margin;
  double s_commit = final ? kInf : s_stop - brake;
  bool forced_stop = false;
  if (!final && s_commit <= s_c + kTiny) {
    // Look-ahead full (chord count) but short: stop at its end; the next chord starts from rest.
    s_stop = s_end;
    s_commit = kInf;
    forced_stop = true;
  }
  const bool all = final || forced_stop;
  for (int iter = 0;; ++iter) {
    for (std::int64_t k = std::max(committed_.chord, chords_.front().id + 1); k < next_id_; ++k) {
      const Chord& c = chord(k);
      if (!all && c.s0 > s_stop) break;
      decide(k, all);
    }
    // Vertices behind the committed position whose regions reach forward are already decided.
    build_pieces(s_c, s_stop, all);
    backward_pass(all);
    Failure fail;
    bool ok = forward(committed_, s_stop, s_commit, fail);
    VerifyState vc, ve;
    if (ok) {
      const std::int64_t t_commit =
          all ? std::numeric_limits<std::int64_t>::max()
              : static_cast<std::int64_t>(std::floor(st_commit_.tau));
      ok = verify(vcommitted_, t_commit, vc, ve, fail);
    }
    if (ok) {
      std::vector<Pulse> rest_of_plan(pulses_.begin() + static_cast<std::ptrdiff_t>(commit_pulses_),
                                      pulses_.end());
      const State end_state = st_end_;
      commit(commit_pulses_, st_commit_, vc);
      if (all) {
        have_fallback_ = false;
        fallback_.clear();
      } else {
        have_fallback_ = true;
        fallback_ = std::move(rest_of_plan);
        fallback_end_ = end_state;
        vfallback_end_ = ve;
      }
      if (forced_stop) force_stop_next_ = true;  // no blend across the look-ahead end
      trim();
      return;
    }
    if (iter > 40 && have_fallback_) {
      // Commit the verified continuation to rest; plan again from there.
      ++stats_.fallbacks;
      pulses_ = fallback_;
      commit(pulses_.size(), fallback_end_, vfallback_end_);
      have_fallback_ = false;
      fallback_.clear();
      trim();
      if (committed_.chord < next_id_) plan(final);
      return;
    }
    if (iter > 200) throw std::logic_error("look-ahead planner: no feasible plan (bug)");
    if (fail.kind == Failure::Kind::kWindow) {
      ++stats_.accel_repairs;
      Chord& c = chord(std::clamp(fail.chord, chords_.front().id, next_id_ - 1));
      // Never below the speed a stop is one fine step from (q0): a window that no speed above it
      // satisfies at this chord is entered too fast, so the vertex at its start becomes an exact
      // stop (the backward pass then brakes for it) when it is still ahead of the committed
      // position. Without this floor a repair to 0.7 * 0 crawled forever (cam_dense_random).
      const double q0 = std::isfinite(c.dv) ? c.dv / (kFine + 1.0) : 0.0;
      double target = std::min(c.cap, 0.7 * fail.cap);
      if (iter > 30) target = std::min(target, 0.25 * std::min(c.repair_cap, c.cap));
      // Repeated failures at one place also end in a stop: speed caps that persist (repair_cap
      // is never raised again) cost more than one stop (random_corners crawled to 1042 s).
      if ((target < q0 || iter > 20) && c.id > committed_.chord && c.id > chords_.front().id &&
          !c.stop) {
        c.stop = true;
        c.decided = false;
      } else {
        // Below q0 only without a verified continuation to fall back on (after a barrier).
        c.repair_cap = std::min(c.repair_cap,
                                std::max(target, iter > 30 && !have_fallback_ ? 1e-3 * q0 : q0));
      }
      // Corners next to it see the lower speed.
      for (std::int64_t k = c.id; k <= std::min(c.id + 1, next_id_ - 1); ++k)
        if (k > committed_.chord) chord(k).decided = false;
      continue;
    }
    ++stats_.tolerance_repairs;
    const double factor = std::clamp(0.97 * fail.eps / std::max(fail.e, 1e-12), 0.3, 0.97);
    auto tighten = [&](std::int64_t k) {
      if (k <= chords_.front().id || k >= next_id_ || k < committed_.chord) return;
      Chord& c = chord(k);
      if (c.turn <= 0.0 || c.stop) return;
      c.f *= factor;
      c.decided = false;
      if (iter > 12) c.stop = true;
    };
    if (fail.kind == Failure::Kind::kVertex) {
      tighten(fail.chord);
    } else {
      bool any = false;
      for (std::int64_t k = fail.lo + 1; k <= fail.hi; ++k) {
        if (k > chords_.front().id && k < next_id_ && chord(k).turn > 0.0 && !chord(k).stop) {
          tighten(k);
          any = true;
        }
      }
      if (!any) tighten(fail.lo);
    }
  }
}

void LookaheadPlanner::barrier(SegmentKind kind, const std::string& msg, const Block& b,
                               double extra_s) {
  spike_mm_ = 0.0;  // the output rests at the vertex a dropped spike returned to
  plan(true);
  // The output has settled L - 1 periods after the last command.
  std::int64_t t_stop = static_cast<std::int64_t>(std::ceil(earliest_tau_));
  if (committed_.tau > earliest_tau_)
    t_stop = std::max(t_stop, static_cast<std::int64_t>(std::ceil(committed_.tau - 1e-9)) + L_ - 1);
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
  // After a hold marker the interpolator restarts its time scale from 0 and ramps it back to 1 at
  // 1/(L - 1) per period (Interpolator::step, the override rate limit): plan time advances by
  // k (k + 1) / (2 (L - 1)) in k periods, L / 2 until full speed. Motion planned inside that ramp
  // is played time-warped, its acceleration raised by p' s'': 2875 mm/s^2 per period and 2150 over
  // 10 ms on cam_post (limit 2000; the vertex error of multivibrator-back, 50.2 um, too). Motion
  // after a marker therefore starts when the scale is back at 1 (ceil(L / 2) + 1 periods later).
  const std::int64_t marker = kind != SegmentKind::kMotion ? (L_ + 1) / 2 + 1 : 0;
  earliest_tau_ = static_cast<double>(t_stop + marker + static_cast<std::int64_t>(
                                                   std::ceil(extra_s / T_ - 1e-9)));
  // Everything before has stopped exactly on the last point: start afresh from rest.
  if (!chords_.empty()) {
    for (auto& c : chords_) report_corner(c);
  }
  chords_.clear();
  have_fallback_ = false;
  fallback_.clear();
  committed_.tau = earliest_tau_;
  committed_.chord = next_id_;
  committed_.x = 0.0;
  committed_.rest_done = false;
  committed_.hist.ring.assign(committed_.hist.ring.size(), Vector3d::Zero());
  committed_.hist.newest = static_cast<std::int64_t>(earliest_tau_);
  committed_.hist.partial.setZero();
  committed_.hist.w_prev.setZero();
  vcommitted_.t = static_cast<std::int64_t>(earliest_tau_);
  vcommitted_.y = pos_;
  vcommitted_.tail.clear();
  vcommitted_.vbest.clear();
  start_from_rest_ = true;
}

}  // namespace contour::control
