#pragma once
// Look-ahead velocity plan before the FIR interpolator (BlendMethod::kLookahead, experimental).
// Non-RT: runs ahead of the RT loop (planner thread / contour-sim), allocates, bounded memory.
//
// Model. The RT interpolator filters a command velocity v[n] (mm per period) with a fixed FIR of
// L1 taps (+ an optional second stage, L taps in all). The output acceleration of axis i is then
// exactly (v_i[n] - v_i[n - L1]) / (L1 T^2), so every axis stays within its limit a_i when
//     |v_i[n] - v_i[n - L1]| <= A_i = a_i T^2 L1        for every n          (window rule)
// (the second stage averages this, it cannot raise it). The output velocity is an average of
// command velocities, so |v_i| <= vmax_i T on the command bounds the output. The planner builds
// the command as a sequence of segments ("pulses"), each one straight piece of a programmed line
// or arc chord at one speed, with fractional start times (no rounding to whole periods), and
// decides every speed so that the window rule holds against the exact command history
// (Tajima & Sencer's FIR segment timing, generalised to per-axis limits and a look-ahead):
//  - speed changes are staircases: up by at most A per window (the greedy maximum), down as a
//    fine ramp that follows the braking profile of the look-ahead (at most A per window);
//  - a corner or curve gets a speed cap C over +-(L/2 + 2) periods, the window of the output
//    nearest it, with a cap over the L + 1 periods before it that keeps the window rule across
//    the vertex feasible (decide(); where no such cap exists, C over (L + 1) periods on each
//    side); out-and-back spikes shorter than 0.4 P are dropped (try_drop_spike); C comes from
//    the per-axis velocity change across the window (accel) and from the FIR's blend error
//    (tolerance: sharp-corner displacement 2 alpha_g C sin(theta/2), alpha_g from the filter
//    taps, plus the moving-average error of curves kappa C^2 sigma^2 / 2); sharp corners may
//    instead keep a higher speed and rest g periods at the vertex (seed 004's overlap
//    reduction), whichever the cost model says is faster;
//  - the backward pass limits every position to what the rest of the look-ahead can still brake
//    for (the look-ahead end is a stop), with the tangential budget left by the corner caps;
//  - the forward pass picks each pulse's speed as the largest the window rule, the caps and the
//    braking profile allow; G61 and barriers are exact stops (rest L - 1 periods at the vertex).
// Verification (the guarantee). Every plan is checked on the true output, independently of the
// models: the FIR output at every period (the interpolator's own formula), the distance of every
// output chord to the programmed chords in motion (upper bound: ends + crossing of the two
// nearest convex distance functions), and every programmed vertex against the output polyline
// (two-sided). A failed sample or vertex tightens the corners in its window and the plan is
// redone; an infeasible window lowers the speed cap where it happened. Only a prefix of a
// verified plan is committed; the rest (ending at rest) is kept as the fallback continuation, so
// the committed output plus a verified path to rest always exists (used if a new plan cannot be
// verified). Arc chords: eps_verify = eps (1 - arc_chord_fraction), as in the overlap planners.
#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"
#include "control/planner_types.hpp"

namespace contour::control {

class LookaheadPlanner {
 public:
  LookaheadPlanner(const PlannerParams& p, const Eigen::Vector3d& start_mm);

  void push(const Block& b);
  bool pop(PlannedSegment& out);
  [[nodiscard]] std::size_t ready() const { return out_.size(); }
  [[nodiscard]] bool ended() const { return ended_; }

  void on_corner(std::function<void(const CornerReport&)> cb) { corner_cb_ = std::move(cb); }
  [[nodiscard]] const std::vector<std::string>& messages() const { return messages_; }
  [[nodiscard]] const PlannerStats& stats() const { return stats_; }
  [[nodiscard]] int fir_length() const { return fir_.length(); }

  // Model of the sharp-corner blend (exposed for tests): distance from the vertex to the FIR
  // output of two long lines turning by theta at constant speed v (mm/period) with a rest of
  // gap periods at the vertex, mm.
  [[nodiscard]] double corner_model_mm(double theta_rad, double v_mm_per_cycle, int gap) const;

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();

  struct Chord {
    std::int64_t id = 0;
    Eigen::Vector3d a, b, u;
    double len = 0.0;
    double s0 = 0.0;         // path position of a (mm since the planner started)
    double cap = 0.0;        // speed cap, mm/period (feed, axis velocities, shortest segment)
    double dv = 0.0;         // window rule along u: min_i A_i / |u_i|, mm/period
    double feed_mm_min = 0.0;
    double tol = 0.0, eps = 0.0;  // programmed tolerance; verification tolerance
    BlendMode mode = BlendMode::kFull;
    int line = 0;
    bool rapid = false;
    SpindleDir spindle = SpindleDir::kOff;
    double rpm = 0.0;
    bool mist = false, flood = false;
    int tool = 0;
    // The vertex at `a` (between the previous chord and this one).
    bool stop = false;       // exact stop at a (start from rest, G61, cap below the floor)
    double turn = 0.0;       // turning angle, rad (0 when stop or first)
    bool decided = false;
    double f = 1.0;          // tolerance repair factor (model target = f * eps)
    double repair_cap = kInf;  // mm/period, lowered after an infeasible window
    double C = kInf;         // speed cap around the vertex, mm/period
    double C_acc = kInf;     // the pure per-axis acceleration cap (no margin), mm/period
    Eigen::Vector3d du_acc = Eigen::Vector3d::Zero();  // per-axis direction change C_acc sees
    int gap = 0;             // rest at the vertex, periods
    double r = 0.0;          // reach of its regions, mm
    bool short_regions = false;  // C over +-C rr_in only, C_out over the rr periods before it
    double C_out = kInf;     // window-rule cap over C_out rr before the vertex, mm/period
    double C_after = kInf;   // short regions: the cap after the vertex (>= C), mm/period
    double stop_in = 0.0;    // a stop: the speed it is entered with (stop_entry), mm/period
    double model_e = 0.0;    // modelled error at the decision, mm
    bool reported = false;
    // Collinear merging (try_merge): programmed vertices inside this chord, the block feed and
    // whether `turn` was computed against a previous chord.
    std::vector<Eigen::Vector3d> dropped;
    double block_feed_mm_min = 0.0;
    bool has_prev = false;
  };
  struct Piece {
    double s0 = 0.0, s1 = 0.0;
    std::int64_t chord = 0;  // chord id
    double cap = 0.0;        // mm/period
    double cacc = kInf;      // pure acceleration cap of the regions covering it
    std::int64_t cacc_chord = -1;  // the vertex (chord id) whose C_acc that is
    double qe = 0.0, aq = 0.0;  // braking profile: Q(s) = min(cap^2, qe + 2 aq (s1 - s))
  };
  struct Pulse {
    double t0 = 0.0, dur = 0.0;  // command start and duration, periods
    std::int64_t chord = 0;
    double x0 = 0.0, x1 = 0.0;   // offsets along the chord, mm
    double v = 0.0;              // mm/period (0: rest)
  };
  // Command velocity history of the last periods (window rule), indexed by absolute period n
  // (period n covers plan time (n-1, n]).
  struct History {
    std::vector<Eigen::Vector3d> ring;
    std::int64_t newest = 0;  // last complete period
    Eigen::Vector3d partial = Eigen::Vector3d::Zero();  // period newest + 1 so far
    Eigen::Vector3d w_prev = Eigen::Vector3d::Zero();   // velocity of the last pulse
  };
  // Planner state at a pulse boundary, and the verification state at an output period.
  struct State {
    double tau = 0.0;           // plan time of the boundary
    std::int64_t chord = 0;     // chord id and offset of the position
    double x = 0.0;
    History hist;
    bool rest_done = false;     // the rest at the current chord's vertex is already in
  };
  struct VerifyState {
    std::int64_t t = 0;                     // last final output period
    Eigen::Vector3d y = Eigen::Vector3d::Zero();  // output at t
    std::vector<Pulse> tail;                // pulses still moving the output after t
    std::vector<std::pair<std::int64_t, double>> vbest;  // open vertices: chord id, best mm
  };
  struct Failure {
    enum class Kind { kNone, kWindow, kSample, kVertex } kind = Kind::kNone;
    std::int64_t chord = 0;       // window: chord; vertex: the vertex's chord
    std::int64_t lo = 0, hi = 0;  // sample: chord range in motion
    double e = 0.0, eps = 0.0, cap = 0.0;
  };

  void add_chord(const Block& b, const Eigen::Vector3d& a, const Eigen::Vector3d& e,
                 double chord_err);
  // Merges the line b (from the end of the last chord to e) into the last chord when it is short,
  // the last chord is not planned yet, and every programmed vertex inside stays within
  // kMergeShare * P of the merged chord (whose verification tolerance shrinks by that much).
  bool try_merge(const Block& b, const Eigen::Vector3d& e);
  // Drops the last chord when the line b (from its end to e) returns to its start and it is
  // shorter than kSpikeShare P; the next chord's tolerance shrinks by its length (spike_mm_).
  bool try_drop_spike(const Block& b, const Eigen::Vector3d& e);
  void set_limits(Chord& c, int line);
  [[nodiscard]] double stop_entry(std::int64_t id) const;
  void barrier(SegmentKind kind, const std::string& msg, const Block& b, double extra_s);
  void maybe_plan();
  // Plans from the committed state to the look-ahead end (a stop), verifies, commits a prefix.
  // final: the buffer ends at a barrier; everything is committed.
  void plan(bool final);
  Chord& chord(std::int64_t id) { return chords_[static_cast<std::size_t>(id - chords_.front().id)]; }
  const Chord& chord(std::int64_t id) const {
    return chords_[static_cast<std::size_t>(id - chords_.front().id)];
  }
  void decide(std::int64_t id, bool final);
  void build_pieces(double s_from, double s_stop, bool final);
  void backward_pass(bool final);
  double q_at(double s, std::size_t from_piece) const;
  bool forward(const State& start, double s_stop, double s_commit, Failure& fail);
  void append(State& st, const Pulse& p) const;
  void window_interval(const History& h, const Eigen::Vector3d& u, double& lo, double& hi) const;
  bool verify(const VerifyState& start, std::int64_t t_commit, VerifyState& at_commit,
              VerifyState& at_end, Failure& fail);
  void commit(std::size_t n_pulses, const State& st, const VerifyState& vs);
  void emit(const Pulse& p);
  void report_corner(Chord& c);
  void trim();
  double lookahead_mm() const;
  Eigen::Vector3d point(const Chord& c, double x) const {
    return x >= c.len ? c.b : Eigen::Vector3d(c.a + c.u * x);
  }

  PlannerParams p_;
  FirFilter fir_;
  int L_ = 1, L1_ = 1;           // total and first-stage taps
  double T_ = 0.001;
  Eigen::Vector3d A_;            // window rule per axis, mm/period
  Eigen::Vector3d vmax_;         // mm/period
  double rr_ = 2.0;              // acceleration region half-length in periods (L + 1)
  double rr_in_ = 2.0;           // corner cap region half-length in periods (L / 2 + 2)
  double delta_ = 1.0;           // fine ramp step, periods
  double sigma2_ = 0.0;          // filter variance, periods^2
  std::vector<double> alpha_;    // sharp-corner displacement per unit speed vs gap, periods
  double acc_margin_ = 0.98;     // share of the pure acceleration cap used on curves

  Eigen::Vector3d pos_;          // programmed position (end of the last chord pushed)
  double path_mm_ = 0.0;
  std::int64_t next_id_ = 0;
  std::deque<Chord> chords_;
  State committed_;
  VerifyState vcommitted_;
  bool have_fallback_ = false;
  std::vector<Pulse> fallback_;
  State fallback_end_;
  VerifyState vfallback_end_;
  bool start_from_rest_ = true;
  bool force_stop_next_ = false;
  double spike_mm_ = 0.0;        // a spike dropped at the end of the last chord (try_drop_spike)
  double vmax_seen_ = 0.0, dvmin_seen_ = kInf, dvmax_seen_ = 0.0;  // over every chord so far
  double earliest_tau_ = 0.0;
  SpindleDir synced_spindle_ = SpindleDir::kOff;
  double synced_rpm_ = 0.0;

  // Work buffers of one plan.
  struct Nb {
    double d;     // distance from the vertex being decided, mm
    Eigen::Vector3d n;  // its turning angle (rad) along its unit change of direction
  };
  std::vector<Nb> nb_;
  // decide(): the per-axis direction change of each neighbour (against the chord on the other
  // side of the vertex) at its distance; sorted by distance as a running maximum.
  struct DuAt {
    double d;
    Eigen::Vector3d du;
  };
  std::vector<DuAt> du_at_;
  // decide(): the chords after the vertex the short regions' window rule covers (cap_before), by
  // distance, with the running per-axis min / max of their directions.
  struct UaAt {
    double d;
    Eigen::Vector3d mn, mx;
  };
  std::vector<UaAt> ua_at_;
  // decide(): the chords before the vertex (cap_before), by the distance of their end from it.
  std::vector<UaAt> ub_at_;
  std::vector<Piece> pieces_;
  std::vector<Pulse> pulses_;
  std::size_t commit_pulses_ = 0;
  State st_commit_, st_end_;
  std::vector<Eigen::Vector3d> chord_buf_;
  std::vector<Pulse> seq_;
  // verify(): each pulse's start point and programmed displacement, computed once per
  // verification instead of once per pulse and output period.
  struct PulseGeo {
    Eigen::Vector3d p0, p1, d;  // d = p1 - p0
  };
  std::vector<PulseGeo> seq_geo_;
  // verify(): each chord's distance to the previous period's output point, and this period's
  // (the next period's y_prev is this period's y: the distance is reused, not recomputed).
  std::vector<double> dist_prev_, dist_now_;

  std::deque<PlannedSegment> out_;
  std::vector<std::string> messages_;
  std::function<void(const CornerReport&)> corner_cb_;
  PlannerStats stats_;
  bool ended_ = false;
};

}  // namespace contour::control
