#pragma once
// The reference sources of the servo loop (the `reference` stage). Exactly one is active per
// cycle; the loop's state machine chooses it at the cycle boundary (ServoLoop::select_source):
//
//   ProgramSource  RUNNING/HOLD with a program: interpolator + planner segment queue; HOLD, stop
//                  and underrun decelerate along the path through the interpolator's override ramp
//   JogSource      READY, a jog in progress: one axis to a target, trapezoidal at the axis limits
//   HoldSource     READY otherwise: the reference stays; DISABLED/ENABLING/ESTOP: it follows the
//                  measured position (the drives do not servo)
//   StopSource     FAULT, and DISABLED while the drives still run: the controlled stop, each
//                  axis ramped down monotonically from a velocity it really has at
//                  safety.stop_decel_mm_s2, then the drives disabled at standstill
//
// Each is a small class: start() (non-RT or at a cycle boundary), a noexcept, allocation-free
// step() and done(). What a step wants from the state machine (a hold at M0, a stop after a
// planner error, ...) comes back as flags in its result; the loop acts on them in order.
// Units: mm, mm/s, s, rpm. Positions in machine coordinates.
#include <array>
#include <cstdint>

#include <Eigen/Core>

#include "config/spindle_config.hpp"
#include "control/fir_interpolator.hpp"
#include "daemon/loop_stages.hpp"
#include "daemon/program_job.hpp"
#include "daemon/safety_supervisor.hpp"

namespace contour::daemon {

// What one ProgramSource step asks the loop to do (in this order).
struct ProgramStep {
  control::InterpStatus status = control::InterpStatus::kIdle;
  bool underrun_begin = false;   // the queue ran dry before the planner finished
  bool underrun_end = false;
  bool planner_failed = false;   // planning error: request kStop (the source now decelerates)
  bool program_hold = false;     // M0/M1/M6 reached while RUNNING: request kHold
  bool spindle_at_speed = false; // a spindle wait ended (last_wait_s())
  bool spindle_waiting = false;  // still waiting: the supervisor judges waited_cycles()
  bool stopped = false;          // stopping and standing: detach the program, request kStopped
};

// The interpolator + segment queue of an attached ProgramJob.
class ProgramSource {
 public:
  struct Inputs {
    bool running = false;           // state RUNNING (else HOLD)
    double override_ratio = 0.0;    // user x force override (0 while HOLD / stopping is applied here)
    double rapid_override_ratio = 1.0;  // rapids (G0): the rapid override alone
    double spindle_override = 1.0;      // scales the programmed spindle speed (S)
    bool optional_stop = false;         // the M1 switch
    bool single_block = false;          // stop before each new line
    bool wait_for_spindle = false;  // a spindle is present and at_speed_wait asks for the wait
    bool spindle_at_speed = false;  // the spindle channel's judgement (previous cycle)
    double spindle_target_rpm = 0.0;  // the spindle channel's clamped target (previous cycle)
  };

  ProgramSource() = default;
  ProgramSource(const drivers::SpindleLimits& spindle_limits, double period_s) noexcept
      : spindle_limits_(spindle_limits), period_s_(period_s) {}

  // Attach a program (READY): the loop owns no memory of it; released by detach().
  void attach(ProgramJob* job) noexcept;
  // Detach (program done, aborted or replaced). ok = false also tells the planner to stop.
  ProgramJob* detach(bool ok) noexcept;
  [[nodiscard]] ProgramJob* job() const noexcept { return job_; }
  [[nodiscard]] bool attached() const noexcept { return job_ != nullptr; }

  // `run`: a fresh start of the interpolator output (the job was attached in READY).
  void start() noexcept;
  // `stop`: decelerate along the path and flush (the planner is told to stop).
  void request_stop() noexcept;
  [[nodiscard]] bool stopping() const noexcept { return stopping_; }
  // `resume` after HOLD / M0 / M1 / M6.
  void resume() noexcept;

  // Moves planned segments into the interpolator (every cycle while attached, READY included).
  void drain() noexcept;
  // One cycle of the program: reference in position_mm. Precondition: attached().
  RefPoint step(const Inputs& in, ProgramStep& out) noexcept;
  // After the spindle supervisor's timeout: the wait is over (a fault follows).
  void cancel_spindle_wait() noexcept { spindle_waiting_ = false; }
  // The interpolator is done: true once the tool is in position (2 um) or after the settle
  // timeout; then the loop detaches the program as completed.
  bool settled(const Eigen::Vector3d& ref_mm, const Eigen::Vector3d& act_mm, int axes) noexcept;
  [[nodiscard]] bool settling() const noexcept { return settling_; }

  [[nodiscard]] const control::InterpOutput& output() const noexcept { return iout_; }
  void reset_output() noexcept { iout_ = control::InterpOutput{}; }
  // Signed speed of the program's modal spindle state (M3 +, M4 -, M5 0) times the spindle
  // override, before the limits.
  [[nodiscard]] double programmed_spindle_rpm() const noexcept;
  [[nodiscard]] bool spindle_waiting() const noexcept { return spindle_waiting_; }
  [[nodiscard]] std::int64_t waited_cycles() const noexcept { return spindle_wait_cycles_; }
  // The clamped speed the current (or last) wait is for.
  [[nodiscard]] double wait_target_rpm() const noexcept { return spindle_wait_target_rpm_; }
  [[nodiscard]] std::uint64_t spindle_waits() const noexcept { return spindle_waits_; }
  [[nodiscard]] double last_wait_s() const noexcept { return spindle_last_wait_s_; }
  [[nodiscard]] std::uint64_t underruns() const noexcept { return underruns_; }

 private:
  static constexpr int kMaxSegmentsPerCycle = 64;
  static constexpr double kInPositionMm = 0.002;  // program end: tool within 2 um (4 BLU) of the end
  static constexpr double kSettleTimeoutS = 5.0;  // then end anyway (the end error is in the status)

  drivers::SpindleLimits spindle_limits_{};
  double period_s_ = 0.001;
  ProgramJob* job_ = nullptr;
  control::InterpOutput iout_{};
  control::PlannedSegment seg_{};
  SegmentRecord rec_{};  // drain()'s scratch (a local was zeroed every cycle: ~5 % of the cycle)
  double spindle_override_ = 1.0;  // of the last step(): programmed_spindle_rpm() includes it
  bool stopping_ = false;
  bool underrun_ = false;
  bool settling_ = false;
  std::uint64_t settle_cycles_ = 0;
  std::uint64_t underruns_ = 0;
  bool spindle_waiting_ = false;
  std::int64_t spindle_wait_cycles_ = 0;
  double spindle_wait_target_rpm_ = 0.0;
  std::uint64_t spindle_waits_ = 0;
  double spindle_last_wait_s_ = 0.0;
};

// Single-axis jog to a target at up to the requested speed, trapezoidal at the axis' live
// velocity and acceleration limits.
class JogSource {
 public:
  void start(int axis, double velocity_mm_s, double target_mm) noexcept;
  // `stop` while jogging: a new target at the braking distance from `ref_axis_mm`.
  void brake(double ref_axis_mm, double decel_mm_s2) noexcept;
  void cancel() noexcept { active_ = false; }
  [[nodiscard]] bool active() const noexcept { return active_; }
  [[nodiscard]] bool done() const noexcept { return !active_; }
  [[nodiscard]] int axis() const noexcept { return axis_; }
  [[nodiscard]] double target_mm() const noexcept { return target_mm_; }
  // Advances the reference `ref_mm` (READY). Ends (done()) at the target.
  RefPoint step(const Eigen::Vector3d& ref_mm, const LiveLimits& lim, double period_s) noexcept;

 private:
  bool active_ = false;
  int axis_ = 0;
  double target_mm_ = 0.0;
  double v_mm_s_ = 0.0;
  double speed_mm_s_ = 0.0;
};

// Homing (issue 18, `home`): the axes of one sequence group at a time search their home switch
// (the drive's 0x60FD bit 2), back off, latch at the slow speed (on the release edge when
// latch_vel has the opposite sign of search_vel, else on the closing edge of a second, slow
// approach) and stop; when every axis of the group has latched the loop shifts their machine
// coordinates so that the latch point reads home_offset_mm (shift_pending()/shifted()); then they
// move to home_position_mm and the next group starts. Each axis is a velocity ramp at the live
// acceleration limit: the reference never jumps. The search is bounded by search_distance_mm, the
// back-off by the same distance: a switch that never closes or never opens fails the homing
// (failed(): the axes brake and the source ends). READY only; abort() brakes everything to rest.
class HomingSource {
 public:
  enum class Phase : std::uint8_t {
    kIdle, kSearch, kBrakeSearch, kBackoff, kBrakeBackoff, kApproach, kBrakeLatch, kLatched,
    kFinal, kDone, kBraking /* abort or failure */,
    kIndex /* past the switch edge at the latch speed, waiting for the encoder index */,
    kDrive /* home.method drive: the drive homes itself (mode 6), the reference follows it */,
    kDriveStop /* a drive homing abandoned: following the drive while it stops */,
  };
  struct AxisPlan {
    bool home = false;  // this axis is homed by this run
    int sequence = 0;
    double search_mm_s = 0.0;  // signed
    double latch_mm_s = 0.0;   // signed
    double offset_mm = 0.0;
    double position_mm = 0.0;
    double search_distance_mm = 0.0;
    bool use_index = false;  // home.use_index: the index after the switch edge is the latch
    // home.method drive: the drive homes itself (the bus was given method, speeds, acceleration);
    // no "attained" within drive_timeout_s fails the homing (code 9).
    bool drive = false;
    double drive_timeout_s = 60.0;
  };
  static constexpr std::uint32_t kHomeSwitchBit = 1u << 2;  // CiA 402 0x60FD bit 2

  // Non-RT or at a cycle boundary: home the axes of `plan` with home = true, from `ref_mm`.
  void start(const std::array<AxisPlan, kMaxAxes>& plan, int axes, const Eigen::Vector3d& ref_mm) noexcept;
  RefPoint step(const Feedback& fb, const LiveLimits& lim, double period_s) noexcept;
  // Brake every moving axis to rest, then end (stop, dead-man, leaving READY is cancel()).
  void abort() noexcept;
  void cancel() noexcept { active_ = false; shift_pending_ = false; }
  [[nodiscard]] bool active() const noexcept { return active_; }
  // The current group latched and stands: the loop applies the shifts (latch_mm -> offset_mm),
  // then calls shifted() with the reference in the new coordinates.
  [[nodiscard]] bool shift_pending() const noexcept { return shift_pending_; }
  [[nodiscard]] std::uint32_t group_mask() const noexcept { return group_mask_; }
  [[nodiscard]] double latch_mm(int axis) const noexcept { return latch_mm_[static_cast<std::size_t>(axis)]; }
  [[nodiscard]] double offset_mm(int axis) const noexcept { return plan_[static_cast<std::size_t>(axis)].offset_mm; }
  void shifted(const Eigen::Vector3d& ref_mm) noexcept;
  // Ended by a failure: the axis, and its code (homing_failure_text; EventKind::kHomingFailed's
  // detail).
  [[nodiscard]] bool failed() const noexcept { return failed_axis_ >= 0; }
  [[nodiscard]] int failed_axis() const noexcept { return failed_axis_; }
  [[nodiscard]] std::uint8_t failure_code() const noexcept { return failure_code_; }
  [[nodiscard]] double failure_value() const noexcept { return failure_value_; }
  [[nodiscard]] Phase phase(int axis) const noexcept { return phase_[static_cast<std::size_t>(axis)]; }
  // The encoder index latch of the axis must be armed (AxisCommands::index_arm) this cycle.
  [[nodiscard]] bool index_armed(int axis) const noexcept {
    return active_ && phase_[static_cast<std::size_t>(axis)] == Phase::kIndex;
  }
  // Home by the drive (AxisCommands::drive_home) this cycle: the kDrive phase, until the drive
  // reports attained (then it stands in the cyclic mode and the loop holds it like a latched
  // switch axis until the group's shift).
  [[nodiscard]] bool drive_home_request(int axis) const noexcept {
    return active_ && phase_[static_cast<std::size_t>(axis)] == Phase::kDrive;
  }
  // The drive moves the axis on its own (kDrive, kDriveStop): the reference follows the measured
  // position (no following error for motion the loop did not command) and the loop commands no
  // velocity on this axis.
  // From "attained" to the group's shift the drive-homed axis stays so (kLatched): its drive
  // holds it at rest under the zero command, and the controllers, whose drive model missed the
  // whole homing travel, restart only at the shift (ServoLoop::homing_step).
  [[nodiscard]] bool drive_moves(int axis) const noexcept {
    const auto a = static_cast<std::size_t>(axis);
    const Phase p = phase_[a];
    return active_ && (p == Phase::kDrive || p == Phase::kDriveStop || (p == Phase::kLatched && plan_[a].drive));
  }
  // The current sequence group has an axis homed by its drive (the loop keeps the controllers'
  // axes apart while it runs: ServoLoop::control_step).
  [[nodiscard]] bool drive_group() const noexcept {
    if (!active_) return false;
    for (int i = 0; i < axes_; ++i) {
      if ((group_mask_ >> i & 1u) != 0 && plan_[static_cast<std::size_t>(i)].drive) return true;
    }
    return false;
  }
  // Axes that finished (moved to home_position_mm) since start(); the loop marks them homed at the shift.
  [[nodiscard]] std::uint32_t homing_mask() const noexcept { return homing_mask_; }

 private:
  // kDriveStop ends when the axis moves slower than this (fresh feedback, mm/s).
  static constexpr double kDriveRestMmS = 0.5;
  void start_group() noexcept;
  void fail(int axis, std::uint8_t code, double value) noexcept;
  // One velocity-ramp step of axis a towards v_target; returns the new velocity.
  void ramp(std::size_t a, double v_target, double acc, double period_s) noexcept;

  std::array<AxisPlan, kMaxAxes> plan_{};
  std::array<Phase, kMaxAxes> phase_{};
  std::array<double, kMaxAxes> v_{};
  std::array<double, kMaxAxes> start_mm_{};  // where the current phase began (distance bound)
  std::array<double, kMaxAxes> latch_mm_{};
  std::array<double, kMaxAxes> index_v_{};  // kIndex: the speed the switch edge was met at
  std::array<double, kMaxAxes> drive_s_{};  // kDrive: time since the request
  Eigen::Vector3d pos_mm_ = Eigen::Vector3d::Zero();
  int axes_ = 0;
  int group_ = -1;                 // current sequence number
  std::uint32_t group_mask_ = 0;   // axes of the current group
  std::uint32_t homing_mask_ = 0;  // axes still to home (all groups)
  bool active_ = false;
  bool shift_pending_ = false;
  int failed_axis_ = -1;
  std::uint8_t failure_code_ = 0;
  double failure_value_ = 0.0;
};
const char* to_string(HomingSource::Phase p) noexcept;
// Why homing ended without homing (the log, status.homing.failure): 1 no digital inputs, 2 the
// switch did not close within search_distance_mm, 3 did not open again, 4 did not close again on
// the latch approach, 6 home.use_index on a bus that cannot latch the index, 7 no index within
// search_distance_mm after the switch edge, 8 home.method drive on a bus that cannot ask the drive
// to home, 9 no "homing attained" within drive_timeout_s, 10 the drive reported a homing error
// (statusword bit 13; value = statusword), 11 the drive refused a homing object (SDO abort; value =
// index << 8 | sub-index), anything else aborted (the loop's code 5: stop, or the machine left
// READY).
const char* homing_failure_text(std::uint8_t code) noexcept;

// Standstill. Servoing (READY): the reference stays at the position given to start(). Not
// servoing (DISABLED, ENABLING, ESTOP): the reference follows the measured position, so that the
// controllers start from where the axes are when the drives come back.
class HoldSource {
 public:
  void start(const Eigen::Vector3d& position_mm) noexcept { held_mm_ = position_mm; }
  RefPoint step(const Feedback& fb, bool servo) noexcept;
  [[nodiscard]] bool done() const noexcept { return false; }  // holds until another source takes over
  [[nodiscard]] const Eigen::Vector3d& position_mm() const noexcept { return held_mm_; }

 private:
  Eigen::Vector3d held_mm_ = Eigen::Vector3d::Zero();
};

// The controlled stop (FAULT) and the power-down of `disable` / SIGTERM (issue 16: a stop never
// adds energy; power stages off only at standstill). Three phases:
//   ramp    each axis' velocity command goes linearly from v0 (a velocity the axis really has,
//           chosen by the loop: ServoLoop::stop_velocity) to zero; all axes reach zero together,
//           so the direction of motion stays that of v0 (on a line of the path the tool stays on
//           it; on an arc it leaves along the tangent by at most d^2 / (2 R), d = |v0|^2 / (2 a));
//           the path speed falls at the live safety.stop_decel_mm_s2, each axis at that times
//           |v0_i| / |v0| <= the stop deceleration: |command| never increases on any axis.
//   settle  zero command, drives still enabled (their velocity loops brake what the lag left),
//           until every axis' measured speed (fresh feedback only) stays below
//           safety.standstill_velocity_mm_s for safety.standstill_time_s;
//   off     drives disabled (done());
//   quick_stop  the settle phase took longer than safety.standstill_timeout_s: the drives get the
//           CiA 402 quick stop (their own ramp, then disabled by the drive); timed_out() says so
//           once, naming the axis that still moved.
// The reference follows the measured position (the controllers do not servo). Starts in `off`.
class StopSource {
 public:
  enum class Phase : std::uint8_t { kRamp, kSettle, kOff, kQuickStop };

  // Cycle boundary: the stop begins with these per-axis velocities (mm/s).
  void start(const std::array<double, kMaxAxes>& v0_mm_s, int axes) noexcept;
  RefPoint step(const Feedback& fb, const LiveLimits& lim, double period_s) noexcept;
  [[nodiscard]] bool done() const noexcept { return phase_ == Phase::kOff || phase_ == Phase::kQuickStop; }
  [[nodiscard]] Phase phase() const noexcept { return phase_; }
  // The standstill timeout fired in the last step (true once per stop).
  [[nodiscard]] bool timed_out() const noexcept { return timed_out_; }
  // The axis that moved fastest in the last settle step, and its speed (mm/s).
  [[nodiscard]] int moving_axis() const noexcept { return moving_axis_; }
  [[nodiscard]] double moving_speed_mm_s() const noexcept { return moving_speed_; }
  [[nodiscard]] const std::array<double, kMaxAxes>& start_velocity_mm_s() const noexcept { return v0_; }

 private:
  std::array<double, kMaxAxes> v0_{};
  double speed0_ = 0.0;      // |v0|
  double ramp_speed_ = 0.0;  // path speed of the ramp now
  double settle_s_ = 0.0;    // time in the settle phase
  double still_s_ = 0.0;     // time every axis has been below the standstill speed
  int axes_ = 0;
  int moving_axis_ = -1;
  double moving_speed_ = 0.0;
  bool timed_out_ = false;
  Phase phase_ = Phase::kOff;
};
const char* to_string(StopSource::Phase p) noexcept;

}  // namespace contour::daemon
