#pragma once
// FIR interpolator (seed 004 §1, eq 1): each block is a rectangular feed command (N_b samples of
// delta_b / N_b) fed through a moving-average FIR filter of t_A/T + 1 taps (optionally a second
// cascaded stage: trapezoidal -> jerk-limited S-curve). By linearity the output is the sum of every
// block's individually filtered profile, so block overlap = starting block b+1's command before
// block b's filtered output has stopped.
//
// Time base: "plan time" t counts interpolation periods; q(t) is the reference point after t
// periods. A segment with command start s and duration N periods contributes delta * P(t - s) / N,
// where P(k) = sum_i w_i clamp(k - i, 0, N) (FirFilter::progress, O(1) from prefix sums). It has
// stopped at t = s + N + L - 1 (L = filter length in taps). s and N may be fractional (the
// look-ahead planner times short segments exactly instead of rounding each to whole periods): the
// command position is then the piecewise-linear ramp sampled at whole periods, and the same closed
// form holds with real boundaries (seed 004's integer blocks are the special case).
//
// Interpolator: the RT consumer. step() is noexcept, allocation-free, O(segments in motion); the
// planner keeps every segment at least PlannerParams::min_segment_cycles long, so at most
// (L - 1) / min_segment_cycles + 2 segments are in motion at once; the segment ring is sized at
// configure(). Feed override (0..max) scales the plan-time advance
// per cycle (path unchanged: between plan samples the point moves on the straight chord between
// consecutive plan samples, which is the path the planner verified); the override is rate-limited
// so its change is spread over at least t_A. It starts at 100 %; while it is not 100 % the output
// points lie on the verified plan chords but the straight line between two output points may cut a
// plan sample vertex by the sagitta of two consecutive plan chords (sub-um at 1 ms).
// After a hold (and a single-block stand) the time scale ramps up from 0 so that plan time
// reaches a whole period again: at 100 % the output samples are then the plan samples themselves.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "control/gcode.hpp"

namespace contour::control {

class FirFilter {
 public:
  // taps1 >= 1 (t_A/T + 1 in the paper's convention), taps2 = 0 for one stage, else >= 1.
  void configure(int taps1, int taps2);
  [[nodiscard]] int length() const noexcept { return length_; }  // total taps L
  // Filtered command progress in samples (0..n) after k command periods of an n-sample block.
  [[nodiscard]] double progress(std::int64_t k, std::int64_t n) const noexcept;
  // Same for a fractional start offset and duration: k = t - s (real), n > 0 (real). Equal to
  // the integer form (bit for bit) when k and n are whole numbers.
  [[nodiscard]] double progress(double k, double n) const noexcept;
  [[nodiscard]] double weight(int i) const noexcept { return w_[static_cast<std::size_t>(i)]; }

 private:
  int length_ = 1;
  std::vector<double> w_;   // impulse response, sums to 1
  std::vector<double> p_;   // prefix sums of w (size L+1)
  std::vector<double> pi_;  // prefix sums of i*w_i (size L+1)
};

// kSpindleSync: exact stop, the marker's spindle state is output at once, and the interpolator
// waits (InterpStatus::kSpindleWait) until resume() — the loop resumes it when the spindle is at
// speed (LinuxCNC's spindle.N.at-speed before a feed move).
// kToolChange (M6) and kUserMcode (M100..M199) are holds like kHold (exact stop,
// InterpStatus::kHolding until resume()); InterpOutput::hold_kind tells the loop which, so that
// the machine logic can run them (a PLC tool changer / M-code sequence) instead of the operator.
enum class SegmentKind : std::uint8_t {
  kMotion, kHold, kOptionalHold, kEnd, kSpindleSync, kToolChange, kUserMcode
};

// One planned micro-block (a line, an arc chord or a part of one at one command speed) with its
// command start time. Produced by BlendPlanner (non-RT), consumed by Interpolator (RT).
// Command start = start_cycle + start_offset_cycles, duration = duration_cycles when > 0, else
// samples (the seed-004 planners use whole periods: offset 0, duration 0).
struct PlannedSegment {
  SegmentKind kind = SegmentKind::kMotion;
  std::int64_t start_cycle = 0;  // s: first command period (integer part of the start)
  std::int64_t samples = 0;      // N >= 1 for motion: periods touched, ceil(offset + duration)
  double start_offset_cycles = 0.0;  // fractional part of the command start, [0, 1)
  double duration_cycles = 0.0;      // exact command duration (periods); 0 = `samples`
  Eigen::Vector3d start_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d end_mm = Eigen::Vector3d::Zero();
  double length_mm = 0.0;
  double path_start_mm = 0.0;  // programmed arc length at the segment start
  double feed_mm_min = 0.0;    // programmed (after axis-limit clamping)
  double speed_mm_min = 0.0;   // planned command speed of this segment (0: feed_mm_min)
  int line = 0;                // source line
  bool rapid = false;          // G0 (and G28/G30/G53 rapids): a rapid override may apply
  SpindleDir spindle = SpindleDir::kOff;
  double spindle_rpm = 0.0;
  bool mist = false;
  bool flood = false;
  int tool = 0;
  int message_id = -1;  // holds: index into the planner's message table
  int user_m = 0;       // kUserMcode: the M number (100..199) and its P and Q words
  double user_p = -1.0;  // (-1 when absent, as the interpreter and LinuxCNC pass them)
  double user_q = -1.0;
};

enum class InterpStatus : std::uint8_t {
  kIdle,      // nothing queued yet
  kRunning,
  kHolding,   // at M0/M1/M6: waits for resume()
  kStarved,   // queue ran dry mid-program: stopped on the path (exact stop at the last vertex)
  kDone,      // end of program reached; reference is exactly the final point
  kSpindleWait  // stopped at a kSpindleSync marker with its spindle state: waits for resume()
};

struct InterpOutput {
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();
  double path_progress_mm = 0.0;  // blended programmed arc length
  int line = 0;                   // source line of the newest segment in motion
  double override_applied = 1.0;  // after rate limiting
  double plan_time_cycles = 0.0;
  SpindleDir spindle = SpindleDir::kOff;
  double spindle_rpm = 0.0;
  bool mist = false;
  bool flood = false;
  int tool = 0;
  int message_id = -1;  // while holding
  // While holding: the marker's kind (kHold, kOptionalHold, kToolChange with `hold_tool` the
  // tool to load, kUserMcode with its M number and words); kMotion otherwise.
  SegmentKind hold_kind = SegmentKind::kMotion;
  int hold_tool = 0;
  int user_m = 0;
  double user_p = -1.0;
  double user_q = -1.0;
  InterpStatus status = InterpStatus::kIdle;
  // The segment the path is on is a rapid (G0): the rapid override applies, not the feed override.
  bool rapid = false;
  // kHolding at a single-block stop (not at a marker): the path stands before the next line.
  bool single_block_stop = false;
};

struct InterpolatorParams {
  int fir_taps = 101;       // t_A/T + 1
  int fir2_taps = 0;        // second stage (0 = off)
  double period_s = 0.001;
  double override_max = 1.5;
  bool optional_stop = false;  // M1 holds when true
  bool single_block = false;   // stop before every new source line (see set_single_block)
  std::size_t capacity = 4096;  // segment ring size (> blocks in motion at once)
};

// Command duration and the plan time at which a motion segment has stopped (output at its end).
[[nodiscard]] inline double segment_duration(const PlannedSegment& s) noexcept {
  return s.duration_cycles > 0.0 ? s.duration_cycles : static_cast<double>(s.samples);
}

class Interpolator {
 public:
  // Setup-time: allocates the ring. Throws std::invalid_argument on bad parameters.
  void configure(const InterpolatorParams& p, const Eigen::Vector3d& start_mm);

  // Producer side: call from the RT thread (the daemon drains the planner's SPSC queue into it at
  // the start of a cycle) or the single thread of contour-sim. Returns false when the ring is full.
  // Segments arrive in start order. A segment whose start is already past is delayed until every
  // queued block has stopped (never a path change).
  bool push(const PlannedSegment& s) noexcept;
  [[nodiscard]] std::size_t free_slots() const noexcept { return cap_ - count_; }

  // One interpolation period. override in [0, override_max] (clamped; NaN -> 0). noexcept, no
  // allocation, O(L). Time budget: < 5 us on the target for L = 101 (bench_planner.cpp).
  InterpStatus step(double override_ratio, InterpOutput& out) noexcept {
    return step(override_ratio, override_ratio, out);
  }
  // The same with LinuxCNC's split: feed moves follow feed_ratio, rapids (PlannedSegment::rapid)
  // rapid_ratio. Which one applies is decided by the segment the path is on (the newest one
  // started, else the next to start); a change between them is rate-limited like any override
  // change, so the time scale never steps.
  InterpStatus step(double feed_ratio, double rapid_ratio, InterpOutput& out) noexcept;
  void resume() noexcept;
  // The optional stop switch (M1 holds when on), live: judged when the path reaches an M1.
  void set_optional_stop(bool on) noexcept { p_.optional_stop = on; }
  // Single block (LinuxCNC's step, a commercial control's SBK), live: when on, the path brakes
  // along itself (the override ramp, as a feed hold) to stand before the first segment of the
  // next source line starts, and holds there (InterpStatus::kHolding, single_block_stop) until
  // resume(); the segments of one line (an arc's chords) never stop between them. With exact stop
  // (G61) the stand is the block's end point; with blending it is where the next line's command
  // would start, on the path already verified. If the switch comes on too late to stand before
  // the next line, the path stands as soon as the ramp allows (inside that line) and runs to the
  // end of it after resume(). Switching off releases a brake that has not reached standstill.
  void set_single_block(bool on) noexcept {
    p_.single_block = on;
    if (!on && !sb_stopped_) sb_braking_ = false;
  }

  // Reference point at an integer plan time using the queued segments (RT-safe, no state change).
  [[nodiscard]] Eigen::Vector3d position_at(std::int64_t t, double* progress_mm = nullptr,
                                            int* line = nullptr) const noexcept;

 private:
  // Ring slot of queue entry i (i < count_ <= cap_: one subtraction; no division per access).
  [[nodiscard]] std::size_t slot(std::size_t i) const noexcept {
    std::size_t k = head_ + i;
    while (k >= cap_) k -= cap_;
    return k;
  }
  void pop_front() noexcept {
    if (++head_ == cap_) head_ = 0;
    --count_;
  }
  const PlannedSegment& at(std::size_t i) const noexcept { return ring_[slot(i)]; }
  void drop_finished(std::int64_t t) noexcept;

  InterpolatorParams p_;
  FirFilter fir_;
  std::vector<PlannedSegment> ring_;
  std::size_t cap_ = 0, head_ = 0, count_ = 0;
  Eigen::Vector3d base_mm_ = Eigen::Vector3d::Zero();  // end of the last dropped segment
  double base_progress_mm_ = 0.0;
  int last_line_ = 0;
  double tau_ = 0.0;  // plan time
  std::int64_t shift_ = 0;  // added to start_cycle after a starvation stop
  double ovr_ = 0.0;  // applied override
  bool holding_ = false;
  InterpStatus hold_status_ = InterpStatus::kHolding;  // kHolding or kSpindleWait
  void set_hold_marker(const PlannedSegment* m) noexcept;
  bool resumed_hold_ = false;
  bool whole_phase_ = false;  // the next ramp up starts from a stand (see step())
  bool snap_phase_ = false;   // that ramp is under way: snap plan time when it reaches 100 %
  bool done_ = false;
  bool rapid_now_ = false;  // the segment the path is on is a rapid
  // The next motion segment to start, when of the other kind (-1: none): a lower override for it
  // brakes the path in time to stand at its start (LinuxCNC: a feed move at 0 % feed override
  // after a rapid does not creep). brake_for_ latches the braking until that segment starts.
  std::int64_t next_start_ = -1;
  bool next_rapid_ = false;
  std::int64_t brake_for_ = -1;
  // Single block: the line the path is on and the next segment's line (when it starts a new
  // line); braking for the stop, standing at it, released by resume(); sb_pass_ = start of the
  // segment released (it does not brake again).
  int on_line_ = 0;
  bool next_new_line_ = false;
  bool sb_braking_ = false;
  bool sb_stopped_ = false;
  bool sb_go_ = false;
  std::int64_t sb_pass_ = -1;
  std::int64_t sb_for_ = -1;  // start of the segment the brake stands before
  int sb_line_ = 0;           // the line the brake began in
  InterpOutput last_{};
};

}  // namespace contour::control
