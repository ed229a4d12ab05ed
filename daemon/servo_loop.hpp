#pragma once
// The real-time servo cycle (architecture.md "The 1 kHz cycle", issue 9 "Real-time loop"), as a
// pipeline of named stages (ros2_control's read -> update -> write; moteus' latched faults).
// ServoLoop::cycle() runs ONE cycle:
//   boundary   the staged gains/limits swap (ServoController::set_gains keeps the controller
//              state, so it is allowed in every state, RUNNING and HOLD included)
//   read       SYNC, TPDOs (missed ones counted), force sample, E-stop input -> one Feedback
//              snapshot (daemon/loop_stages.hpp); every later stage reads only the snapshot
//   commands   the pending reset window, then queued commands (after the TPDOs, so that `reset`
//              judges the drives' current fault bits); E-stop input latch -> ESTOP this cycle
//   logic      one scan of the machine logic over the snapshot (room for the soft PLC; its
//              requests go through the state machine and the supervisor, never around them)
//   reference  the state machine's ENABLING -> READY step, then exactly one reference source
//              (daemon/reference_sources.hpp: program, jog, hold, stop) -> RefPoint
//   control    contour-error model (Smith-predicted P_hat), axis + coupling controllers,
//              v = K*u, velocity clamp, acceleration clamp |v - v_actual| <= a_max * tau_drive;
//              or the stop source's ramp (FAULT), quick stop (ESTOP), zero (otherwise)
//   channels   force (2-DOF controller -> feed override from the NEXT cycle, spindle speed) and
//              spindle (limits, ramp, at-speed) (daemon/loop_channels.hpp)
//   write      RPDOs (velocities, drive mode, spindle speed)
//   supervise  every safety rule in SafetySupervisor (daemon/safety_supervisor.hpp): drive and
//              bus faults, following error, soft limits, contour error -> FAULT with a named
//              cause; the program's in-position check at its end
//   publish    telemetry sample (SPSC ring, dropped when full) and the seqlock status
// cycle() is noexcept, allocation-free and lock-free and does not log: events go to an SPSC ring
// of fixed-size records. Budget: < 50 us at 1 kHz (measured: see daemon/README.md).
//
// Threads: cycle() runs on the RT thread only (or the test's thread). post(), stage_gains() and
// stage_limits() are called from non-RT threads (a mutex serialises producers; the RT consumer
// never locks: the staged set is a double buffer handed over by an atomic flag).
// Outputs that are GPIO lines (drive enable, spindle enable, coolant) are only PUBLISHED in the
// status; the I/O supervisor thread (io_channels.hpp) sets the lines (libgpiod calls are ioctls).
// status() is a seqlock read, callable from any thread.
//
// Units: mm, mm/s, s. Positions in machine coordinates.
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>

#include "config/config.hpp"
#include "control/chatter_monitor.hpp"
#include "control/contour_error.hpp"
#include "control/fir_interpolator.hpp"
#include "control/servo_controller.hpp"
#include "control/force_controller.hpp"
#include "daemon/axis_bus.hpp"
#include "daemon/io_channels.hpp"
#include "daemon/loop_channels.hpp"
#include "daemon/loop_stages.hpp"
#include "daemon/machine_state.hpp"
#include "daemon/plc_engine.hpp"
#include "daemon/program_job.hpp"
#include "daemon/reference_sources.hpp"
#include "daemon/rt_timing.hpp"
#include "daemon/safety_supervisor.hpp"
#include "daemon/spsc_ring.hpp"

namespace contour::daemon {

inline constexpr int kOverrideFeed = 0, kOverrideRapid = 1, kOverrideSpindle = 2;

enum class CommandKind : std::uint8_t {
  kEnable, kDisable, kRun, kHold, kResume, kStop, kEstop, kReset, kJog, kAttachJob,
  kSetOverride,  // axis: 0 feed, 1 rapid, 2 spindle (kOverrideFeed..); a = ratio, clamped to its limits
  kRecordFlag,
  kSetPosition,  // axis, a = position mm; DISABLED/READY only (bus.set_position on the RT thread)
  kForce,        // axis: 1 = on, 0 = off, -1 = unchanged; a = reference N (NaN = unchanged)
  kIdentify,     // axis: play the identification excitation on it (READY, nothing loaded/jogging)
  kJogBrake,     // brake a jog at the axis' deceleration (continuous jog's dead-man); else nothing
  kHome,         // axis (-1: every axis with a homing method, in home.sequence order); READY
  kSetOptionalStop,  // a != 0: M1 holds (the optional stop switch), live
  kSetSingleBlock,   // a != 0: the program stops before each new line (single block), live
};

// Drive identification (issue 16, `contourctl identify`): the loop plays a preallocated velocity
// excitation (control::make_excitation) on one axis at rest while the others hold, and records
// the target it wrote and the position it read in every cycle. The non-RT side fits the model
// (control::identify_axis) from identify_record() once the state is kDone.
enum class IdentifyState : std::uint8_t { kIdle, kRunning, kDone, kAborted };
[[nodiscard]] const char* to_string(IdentifyState s) noexcept;

// Fixed-size command record (non-RT -> RT).
struct LoopCommand {
  CommandKind kind = CommandKind::kEnable;
  int axis = 0;
  double a = 0.0;  // jog: velocity mm/s; override: ratio; record: 0/1
  double b = 0.0;  // jog: distance mm
  ProgramJob* job = nullptr;
};

enum class EventKind : std::uint8_t {
  kTransition, kFault, kUnderrun, kUnderrunEnd, kProgramDone, kGainsSwapped, kCommandRefused,
  kProgramAborted,
  kForceOn,        // value: reference N
  kForceOff,
  kForceFallback,  // stale/invalid force: value = age s; limit = stale age s; axis = ForceStatus
  kForceCeiling,   // value: force N, limit: ceiling N
  kForceRecovered, // a valid sample again after a fallback (force control stays off until `force on`)
  kLimitsSwapped,
  kSpindleAtSpeed, // a feed move waited for the spindle: value = wait s, limit = actual rpm
  kProgramPause,   // M0/M1/M6 reached: axis = message id (ProgramPlanner::message); waits for resume
  kStandstillTimeout,  // a stop's axes did not come to rest: axis, value = speed mm/s (NaN: no
                       // fresh feedback), limit = safety.standstill_timeout_s; quick stop now
  kLimitCycleWarning,  // safety.chatter warning level held: axis, value/limit, detail = figure
                       // (control::ChatterFigureKind: 1 command chatter mm/s, 2 clamped cycles/s)
  kHomed,          // axis homed: value = latch position before the shift (mm), limit = home_offset_mm
  kHomingFailed,   // axis, value = travelled mm; detail 1 no switch input, 2 switch never closed,
                   // 3 never opened, 4 never closed on the latch approach, 5 aborted (stop / state),
                   // 6..11 homing_failure_text (8..11 home.method drive)
};

// Fixed-size event record (RT -> logger thread).
struct RtEvent {
  std::uint64_t cycle = 0;
  EventKind kind = EventKind::kTransition;
  MachineState from = MachineState::kDisabled;
  MachineState to = MachineState::kDisabled;
  FaultCause cause = FaultCause::kNone;
  CommandKind command = CommandKind::kEnable;
  int axis = -1;
  double value = 0.0;  // fault: the measured value; limit in `limit`
  double limit = 0.0;
  std::uint64_t job = 0;
  std::uint8_t detail = 0;  // kLimitCycle fault / kLimitCycleWarning: control::ChatterFigureKind;
                            // kPlcFault raised by the PLC engine: its PlcFaultKind (0: a request)
};

// One telemetry sample (RT -> writer thread).
struct TelemetrySample {
  std::uint64_t cycle = 0;
  std::uint64_t job = 0;  // 0: no program
  double t_s = 0.0;       // cycle * period
  std::array<double, 3> ref_mm{};
  std::array<double, 3> act_mm{};    // measured position
  std::array<double, 3> eps_mm{};    // model contour-error vector
  std::array<double, 3> cmd_mm_s{};  // velocity commands
  double progress_mm = 0.0;
  double override_applied = 0.0;
  int line = 0;
  MachineState state = MachineState::kDisabled;
  bool recording = false;
  bool in_program = false;  // RUNNING/HOLD with a program attached
  double force_N = 0.0;     // averaged (filtered) resultant force, 0 without a dynamometer
  double force_override = 1.0;
  double spindle_rpm = 0.0;
  float lateness_us = 0.0F;  // wake-up lateness of this cycle (0 when cycle() is stepped by a test)
};

// The last thing the soft PLC did to the machine (status: why it is in FAULT / ESTOP / HOLD).
enum class PlcAction : std::uint8_t { kNone, kEstop, kFault, kAxisFault, kEngineFault, kStop, kHold };
struct PlcStopCause {
  PlcAction action = PlcAction::kNone;
  std::uint64_t cycle = 0;
  int axis = -1;                               // kAxisFault: the axis; kEngineFault: the engine
                                               // fault's index (coupler, program), not an axis
  std::int32_t code = 0;                       // NC.fault_code, or the engine fault's code
  PlcFaultKind engine = PlcFaultKind::kNone;   // kEngineFault: which
};
[[nodiscard]] const char* to_string(PlcAction a) noexcept;

// Published status (seqlock).
struct LoopStatus {
  std::uint64_t cycle = 0;
  MachineState state = MachineState::kDisabled;
  SourceKind source = SourceKind::kHold;  // the reference source of the last cycle
  FaultCause cause = FaultCause::kNone;
  int fault_axis = -1;
  double fault_value = 0.0;
  double fault_limit = 0.0;
  std::uint8_t fault_detail = 0;  // FaultReport::detail (kMissedTpdo: MissedPdo)
  std::array<double, 3> ref_mm{};
  std::array<double, 3> act_mm{};
  std::array<double, 3> cmd_mm_s{};
  double eps_norm_mm = 0.0;
  double progress_mm = 0.0;
  int line = 0;
  double override_applied = 0.0;
  double feed_override = 1.0;
  double rapid_override = 1.0;    // ratio, for rapids (G0); the feed override does not apply to them
  double spindle_override = 1.0;  // ratio of the programmed spindle speed
  bool on_rapid = false;          // the path is on a rapid: override_applied follows rapid_override
  bool optional_stop = false;     // the M1 switch
  bool single_block = false;      // the single-block switch
  std::uint64_t attached_job = 0;   // program the loop is executing (0 = none)
  std::uint64_t finished_job = 0;   // last program that ended (done, stopped or aborted)
  bool finished_ok = false;         // finished_job ran to its end
  std::uint64_t finished_cycle = 0;
  std::uint64_t released_job = 0;   // the loop no longer touches this job (may be freed)
  std::uint64_t underruns = 0;
  std::uint64_t missed_tpdos = 0;
  std::uint64_t velocity_clamps = 0;
  std::uint64_t gains_generation = 0;
  std::uint64_t gains_cycle = 0;    // cycle at which the last gains swap took effect
  bool jogging = false;
  // Homing (issue 18): which axes are homed (bit per axis), whether homing is running, each
  // axis' phase (HomingSource::Phase), and the machine-coordinate shift homing applied.
  std::uint32_t homed_mask = 0;
  bool homing = false;
  std::array<std::uint8_t, 3> home_phase{};
  std::array<double, 3> home_shift_mm{};
  std::uint64_t homing_runs = 0;      // `home` commands the loop accepted
  std::uint8_t homing_failure = 0;    // of the last run: 0 none, else kHomingFailed's detail
  int homing_failure_axis = -1;
  double homing_failure_value = 0.0;  // kHomingFailed's value (11: the object, index << 8 | sub)
  bool interp_holding = false;      // M0/M1/M6 hold in the program
  bool hold_single_block = false;   // while interp_holding: a single-block stop, not a marker
  int hold_line = 0;                // while interp_holding: the hold's source line,
  int hold_tool = 0;                // the tool after it (M6: the tool to load),
  int hold_message_id = -1;         // and its message (ProgramPlanner::message)
  bool recording = false;
  bool drives_enabled = false;     // every axis drive in operation enabled
  std::uint64_t accel_clamps = 0;
  std::uint64_t limits_generation = 0;
  // Command chatter (issue 16, control/chatter_monitor.hpp): the watchdog's sliding-window figures
  // per axis, and the RMS/max of |v(k) - v(k-1)| over the program chatter_job (the running one,
  // else the last one that ran). The loop publishes the raw sums; status() derives the figures
  // (square roots and divisions are the reader's work, not the cycle's).
  control::ChatterWindowSums chatter_window_sums{};
  control::ChatterMeter job_chatter_meter{};
  std::array<double, 3> chatter_window_mm_s{};
  std::array<double, 3> chatter_window_clamps_per_s{};
  std::uint8_t chatter_level = 0;  // control::ChatterLevel: 0 ok, 1 warning, 2 fault
  std::uint64_t chatter_job = 0;
  std::array<double, 3> job_chatter_rms_mm_s{};
  std::array<double, 3> job_chatter_max_mm_s{};
  // Force channel (step 3 / 7).
  bool force_available = false;     // an RtIo with a dynamometer is attached
  drivers::modbus::ForceState force_state = drivers::modbus::ForceState::kNoData;
  std::array<double, 3> force_xyz_N{};  // filtered channels (0 when not mapped)
  double force_N = 0.0;             // resultant of the filtered channels (controller input)
  double force_age_s = 0.0;
  std::uint64_t force_seq = 0;
  bool force_requested = false;     // `force on` (or force.enable at start-up)
  bool force_active = false;        // the 2-DOF controller is regulating now
  control::ForceStatus force_status = control::ForceStatus::kNotConfigured;
  double force_ref_N = 0.0;
  double force_override = 1.0;      // override from the force controller (1 when off)
  bool force_fallback = false;      // stale/invalid fallback latched (until `force on`)
  std::uint64_t force_fallbacks = 0;
  double spindle_rpm_cmd = 0.0;     // AxisCommands::spindle_rpm (clamped, rate-limited)
  // Spindle (spindle: section limits; bus feedback when the bus has a spindle).
  bool spindle_present = false;     // a spindle is configured (spindle.type or bus.spindle)
  bool spindle_feedback = false;    // its speed is fed back
  double spindle_target_rpm = 0.0;  // requested (program / force controller), clamped
  double spindle_actual_rpm = 0.0;
  bool spindle_at_speed = false;
  bool spindle_waiting = false;     // a feed move waits for at-speed
  std::uint64_t spindle_waits = 0;  // feed moves that waited
  double spindle_last_wait_s = 0.0; // how long the last wait took
  // Counters since start (soak test: they must match what was injected).
  std::array<std::uint32_t, kFaultCauseCount> fault_counts{};  // FAULT/ESTOP entries by cause
  std::uint64_t resets = 0;         // accepted resets (FAULT/ESTOP -> re-enable)
  std::uint64_t emcy_frames = 0;    // EMCY frames the bus received
  // Outputs for the GPIO lines (applied by the I/O supervisor) and the E-stop input.
  bool out_drive_enable = false;
  bool out_spindle_enable = false;
  bool out_mist = false;
  bool out_flood = false;
  bool estop_input = false;         // RtIo latch seen by the loop
  // Stops (issue 16).
  StopSource::Phase stop_phase = StopSource::Phase::kOff;  // the controlled stop / power-down
  ResetBlock reset_block{};         // why the last reset was refused (kNone: not refused)
  // `reset` verdicts: counted each time a reset command is decided (done, or refused at once or
  // when its kResetWindowCycles window closes). The command handler waits for the count to move,
  // so its answer is the loop's verdict, however slowly the cycles run.
  std::uint64_t reset_verdicts = 0;
  bool reset_pending = false;       // a reset waits for its causes to clear (window open)
  std::array<double, 3> soft_min_mm{};  // live soft limits (machine coordinates)
  std::array<double, 3> soft_max_mm{};
  // Soft PLC (issue 20; attach_plc): its requests this cycle and the last PLC cause of a stop.
  bool plc_present = false;
  PlcRequests plc_requests{};
  PlcFault plc_engine_fault{};     // the last fault the engine latched (I/O stale, timeout, ...)
  PlcStopCause plc_cause{};        // what the PLC did to the machine last (FAULT/ESTOP/hold)
  // Drive identification: state, axis, completed (done or aborted) experiments, samples played.
  IdentifyState identify_state = IdentifyState::kIdle;
  int identify_axis = -1;
  std::uint64_t identify_seq = 0;
  std::size_t identify_samples = 0;
};

struct LoopOptions {
  // A stale/invalid force sample while force control is on faults the machine ("stale force
  // sample") instead of only the fallback: config `force.fallback: fault`.
  bool force_stale_faults = false;
};

class ServoLoop {
 public:
  // Setup: allocates everything the cycle needs. Throws on bad config (std::invalid_argument).
  // io: optional force/E-stop source (not owned; must outlive the loop). Setup throws on a bad
  // force design (std::invalid_argument).
  ServoLoop(const config::Config& cfg, AxisBus& bus, std::size_t event_capacity = 4096,
            RtIo* io = nullptr, LoopOptions opt = {});

  // One cycle (see the header comment). noexcept, no allocation, no lock, no logging.
  void cycle() noexcept;

  // RT thread body: CycleClock at loop.period_us until stop flag; fills stats().
  void run(const std::atomic<bool>& stop) noexcept;

  // Non-RT producers. post() returns false when the command ring is full.
  bool post(const LoopCommand& c);
  // Validates (ServoController::validate + check_live_compatible; throws std::invalid_argument),
  // waits (up to 2 s) until the previous staged set was taken and stages this one; the loop
  // applies it at the next cycle boundary with ServoController::set_gains (state kept, bumpless
  // integral), in any state. Returns the gains generation.
  std::uint64_t stage_gains(const control::ServoParams& p);
  // Same for the live safety limits (validate(LiveLimits)). Returns the limits generation.
  std::uint64_t stage_limits(const LiveLimits& l);

  // The soft PLC (daemon/plc_engine.hpp), scanned in the `logic` stage; not owned, attached
  // before run() (null: no PLC). Its requests act through the state machine: NC.estop_req ->
  // ESTOP, NC.fault_req / NC.axis_fault_* / an engine fault -> FAULT (controlled stop),
  // NC.stop_req -> stop, NC.feed_hold_req -> HOLD and resume refused, NC.inhibit_start -> run,
  // resume and jog refused, NC.spindle_inhibit -> spindle speed 0. A reset is refused while the
  // PLC still requests (PlcEngine::causes_gone()); an accepted one resets the engine.
  void attach_plc(PlcEngine* plc) noexcept { plc_ = plc; }

  // Drive identification record (non-RT, after status().identify_state == kDone): the targets
  // written (mm/s) and positions read (mm) of the axis, one per cycle. False unless done.
  bool identify_record(int& axis, std::vector<double>& v_cmd_mm_s,
                       std::vector<double>& position_mm) const;
  // The excitation the loop plays (control::make_excitation with the defaults at the loop period).
  [[nodiscard]] const std::vector<double>& identify_excitation() const noexcept { return ident_exc_; }

  [[nodiscard]] LoopStatus status() const noexcept;
  [[nodiscard]] CycleStats& stats() noexcept { return stats_; }
  SpscRing<RtEvent>& events() noexcept { return events_; }
  SpscRing<TelemetrySample>& telemetry() noexcept { return telemetry_; }
  // The gains the loop runs with now (or, between staging and the next cycle, the previous set).
  // Non-RT (takes the producer mutex); a copy, never a reference into RT-owned data.
  [[nodiscard]] control::ServoParams active_params() const;
  [[nodiscard]] LiveLimits active_limits() const;
  [[nodiscard]] bool force_configured() const noexcept { return force_.configured(); }
  [[nodiscard]] double period_s() const noexcept { return period_s_; }
  [[nodiscard]] int axes() const noexcept { return axes_; }

 private:
  // Stages of cycle(), in order (see the header comment).
  void take_staged() noexcept;
  void read() noexcept;
  void run_commands() noexcept;
  void logic() noexcept;  // one soft PLC scan, its requests to the state machine
  MachineState advance_state() noexcept;
  RefPoint reference(MachineState st, bool servo) noexcept;
  AxisCommands control_step(const RefPoint& r, MachineState st, bool servo,
                            const Eigen::Vector3d& v_ref, double& eps_norm) noexcept;
  void channels(MachineState st, AxisCommands& out) noexcept;
  void write(const AxisCommands& out) noexcept;
  void supervise(MachineState st, bool servo, const Eigen::Vector3d& v_ref, double eps_norm) noexcept;
  void publish_cycle() noexcept;

  [[nodiscard]] SourceKind select_source(MachineState st) const noexcept;
  void program_step(MachineState st, RefPoint& r) noexcept;
  bool logic_takes_hold() noexcept;
  void apply_command(const LoopCommand& c) noexcept;
  void transition(const Transition& t, FaultCause cause) noexcept;
  void raise_fault(const FaultReport& f) noexcept;
  void emit(EventKind k, FaultCause c = FaultCause::kNone, int axis = -1, double value = 0.0,
            double limit = 0.0, std::uint8_t detail = 0) noexcept;
  void watch_chatter(bool servo) noexcept;  // safety.chatter watchdog and the job's figure
  void detach_job(bool ok) noexcept;
  void refuse_command(CommandKind k) noexcept;  // kCommandRefused event
  bool try_reset() noexcept;  // FAULT/ESTOP -> enable when every cause is gone
  void hold_here() noexcept;  // reference := current measured position, controller state reset
  // Homing (issue 18).
  [[nodiscard]] bool soft_limits_apply(int axis) const noexcept;  // homed, or allow_unhomed
  [[nodiscard]] bool program_may_run() const noexcept;            // every axis homed, or allowed
  void update_effective_limits() noexcept;                        // limits_eff_ from limits_
  void cancel_homing() noexcept;                                  // leaving READY
  RefPoint homing_step() noexcept;
  void publish() noexcept;
  void enter_estop(FaultCause cause) noexcept;
  // The velocity each axis really has, to start a controlled stop from (see the definition).
  [[nodiscard]] std::array<double, kMaxAxes> stop_velocity() const noexcept;
  // Every axis drive reports CiA 402 "operation enabled" (this cycle's feedback).
  [[nodiscard]] bool all_axes_enabled() const noexcept;
  [[nodiscard]] bool in_program(MachineState st) const noexcept {
    return program_.attached() && (st == MachineState::kRunning || st == MachineState::kHold);
  }

  const config::Config cfg_;
  AxisBus& bus_;
  RtIo* io_ = nullptr;
  LoopOptions opt_{};
  int axes_ = 3;
  double period_s_ = 0.001;
  std::array<double, 3> gain_per_s_{};
  std::array<double, 3> tau_s_{};  // drive velocity-loop lag (acceleration clamp)
  std::array<double, 3> lag_alpha_{};  // 1 - exp(-T / tau): velocity estimate while stale
  LiveLimits limits_{};  // RT copy

  StateMachine sm_;
  SafetySupervisor supervisor_;
  control::ServoController ctrl_;
  control::ServoParams base_params_{};  // start-up set: the structure live swaps must keep
  control::ContourErrorModel model_;

  // Reference sources (one active per cycle) and channels.
  ProgramSource program_;
  JogSource jog_;
  HomingSource homing_;
  HoldSource hold_;
  // Homing: machine position = bus position + home_shift_mm_ (absolute axes: home_offset_mm from
  // the start; switch axes: set at the latch). Soft limits and the program checks apply to an axis
  // once it is homed, or always with machine.allow_unhomed; limits_eff_ is limits_ with the soft
  // limits of the other axes (and of the axes being homed) opened.
  std::array<double, kMaxAxes> home_shift_mm_{};
  std::array<bool, kMaxAxes> homed_{};
  bool homing_was_active_ = false;
  std::uint64_t homing_runs_ = 0;
  std::uint8_t homing_failure_ = 0;
  int homing_failure_axis_ = -1;
  double homing_failure_value_ = 0.0;
  bool homing_drive_ = false;  // a drive-homed group ran since the last controller restart
  LiveLimits limits_eff_{};
  bool limits_eff_dirty_ = true;  // recomputed at the next reference stage (swap, homing change)
  StopSource stop_;
  SourceKind source_ = SourceKind::kHold;
  ForceChannel force_;
  SpindleChannel spindle_;

  // Command mailbox and gains/limits double buffer: the producer writes staged_* only while the
  // flag is clear; the loop reads them only while it is set, then clears it.
  SpscRing<LoopCommand> commands_;
  mutable std::mutex producer_mu_;  // non-RT producers only
  control::ServoParams staged_params_{};
  control::ServoParams applied_params_{};  // non-RT shadow of the set before staged_params_
  std::atomic<bool> staged_ready_{false};
  std::atomic<std::uint64_t> staged_generation_{0};
  LiveLimits staged_limits_{};
  LiveLimits applied_limits_{};
  std::atomic<bool> staged_limits_ready_{false};
  std::atomic<std::uint64_t> staged_limits_generation_{0};
  std::uint64_t limits_generation_ = 0;

  std::array<std::uint32_t, kFaultCauseCount> fault_counts_{};
  std::uint64_t resets_ = 0;
  std::uint64_t accel_clamps_ = 0;

  SpscRing<RtEvent> events_;
  SpscRing<TelemetrySample> telemetry_;
  CycleStats stats_;

  // Cycle state.
  std::uint64_t cycle_ = 0;
  float lateness_us_ = 0.0F;  // set by run() before each cycle
  static constexpr int kResetWindowCycles = 250;  // a pending `reset` waits this long for causes
  int reset_pending_cycles_ = 0;
  std::uint64_t reset_verdicts_ = 0;
  Feedback fb_{};
  AxisCommands out_{};
  Eigen::Vector3d ref_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d ref_prev_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d eps_ = Eigen::Vector3d::Zero();
  double eps_norm_ = 0.0;
  int telemetry_phase_ = 0;  // cycle_ modulo telemetry.decimation  // |eps_| of this cycle (computed once, by control_step)
  std::array<double, 3> v_cmd_{};
  std::array<bool, 3> clamped_{};  // this cycle's command was clamped (velocity or acceleration)
  control::ChatterMonitor chatter_mon_;
  bool chatter_enabled_ = true;
  bool chatter_armed_ = false;      // the watchdog has seen servo cycles since its last reset
  bool chatter_published_armed_ = true;  // publish() copied an armed watchdog last time (or never ran)
  control::ChatterMeter job_chatter_;
  std::uint64_t job_chatter_id_ = 0;
  std::array<double, kMaxAxes> v_est_{};  // measured velocity, or the drive-model estimate when stale
  Eigen::Vector3d v_ref_ = Eigen::Vector3d::Zero();  // reference velocity of the last cycle
  bool last_servo_ = false;                            // the last cycle servoed the axes
  ResetBlock reset_block_{};                           // why the last reset attempt was refused
  double feed_override_ = 1.0;
  double rapid_override_ = 1.0;
  double spindle_override_ = 1.0;
  bool optional_stop_ = false;  // interpolator.optional_stop at start-up
  bool single_block_ = false;   // off at start-up (LinuxCNC)
  bool recording_ = false;
  int fault_axis_ = -1;
  double fault_value_ = 0.0, fault_limit_ = 0.0;
  std::uint8_t fault_detail_ = 0;  // FaultReport::detail
  std::uint64_t finished_job_ = 0, released_job_ = 0, finished_cycle_ = 0;
  bool finished_ok_ = false;
  std::uint64_t missed_tpdos_ = 0, clamps_ = 0;
  std::uint64_t gains_generation_ = 0, gains_cycle_ = 0;

  // Soft PLC (logic stage).
  // Drive identification (allocated at construction; written by the RT thread only while kRunning).
  std::vector<double> ident_exc_, ident_v_, ident_x_;
  std::atomic<IdentifyState> ident_state_{IdentifyState::kIdle};
  int ident_axis_ = -1;
  std::size_t ident_k_ = 0;
  std::uint64_t ident_seq_ = 0;
  void identify_step(MachineState st) noexcept;
  PlcEngine* plc_ = nullptr;
  PlcCycleOutput plc_out_{};
  // Cycles since each axis' 0x60FD last came fresh (kDriveInputsNever: not yet), and the age
  // from which it is stale (safety.missed_tpdo_streak).
  static constexpr int kDriveInputsNever = 1 << 30;
  std::array<int, kMaxAxes> drive_inputs_age_{kDriveInputsNever, kDriveInputsNever, kDriveInputsNever};
  int drive_inputs_max_age_ = 3;
  // CiA 401 modules (BusFeedback::io, slot k): cycles since their TPDOs last came in full (the
  // same staleness rule as 0x60FD), and the PLC's view of them (PlcNcInput::cia401).
  std::array<int, kMaxIoModules> io_age_{};
  std::array<Cia401Inputs, kMaxIoModules> cia401_in_{};
  PlcRequests plc_req_{};  // this cycle's requests (commands use the previous cycle's)
  PlcFault plc_engine_fault_{};
  PlcStopCause plc_cause_{};

  // Seqlock-published status.
  mutable std::atomic<std::uint64_t> seq_{0};
  LoopStatus pub_{};
};

}  // namespace contour::daemon
