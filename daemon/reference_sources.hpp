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
  // Signed speed of the program's modal spindle state (M3 +, M4 -, M5 0), before the limits.
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
