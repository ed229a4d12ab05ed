#include "daemon/servo_loop.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace contour::daemon {

namespace {

constexpr double kInPositionMm = 0.002;       // program end: tool within 2 um (4 BLU) of the end
constexpr double kSettleTimeoutS = 5.0;       // then end anyway (the end error is in the status)
constexpr int kMaxCommandsPerCycle = 16;
constexpr int kMaxSegmentsPerCycle = 64;

control::ServoParams servo_params_from(const config::Config& cfg) {
  std::array<control::FeedDriveParams, 3> dp{};
  int delay = 0;
  const int axes = static_cast<int>(cfg.machine.axes.size());
  for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
    dp[i] = cfg.machine.axes[i].drive;
    dp[i].period_s = cfg.machine.period_s;
    delay = std::max(delay, dp[i].delay_cycles);
  }
  return config::make_servo_params(cfg.control, cfg.control.controller, dp, axes,
                                   cfg.machine.period_s, delay);
}

// Force design from `force:` with the loop period (force_config.hpp: period_s is the user's).
control::ForceDesignParams force_design_params(const config::Config& cfg) {
  control::ForceDesignParams dp = cfg.force.design;
  dp.period_s = cfg.machine.period_s;
  return dp;
}

}  // namespace

LiveLimits live_limits_from(const config::Config& cfg) {
  LiveLimits l;
  l.ferror_mm = cfg.safety.ferror_mm;
  l.min_ferror_mm = cfg.safety.min_ferror_mm;
  l.contour_error_limit_mm = cfg.safety.contour_error_limit_mm;
  l.stop_decel_mm_s2 = cfg.safety.stop_decel_mm_s2;
  for (std::size_t i = 0; i < 3; ++i) {
    if (i < cfg.machine.axes.size()) {
      l.max_velocity_mm_s[i] = cfg.machine.axes[i].max_velocity_mm_min / 60.0;
      l.max_accel_mm_s2[i] = cfg.machine.axes[i].max_accel_mm_s2;
    } else {
      l.max_velocity_mm_s[i] = 1.0;
      l.max_accel_mm_s2[i] = 1.0;
    }
  }
  return l;
}

void validate(const LiveLimits& l, int axes) {
  auto positive = [](double v, const std::string& name) {
    if (!std::isfinite(v) || !(v > 0.0)) {
      throw std::invalid_argument("limits: " + name + " = " + std::to_string(v) + " must be > 0");
    }
  };
  positive(l.ferror_mm, "safety.ferror_mm");
  positive(l.min_ferror_mm, "safety.min_ferror_mm");
  positive(l.contour_error_limit_mm, "safety.contour_error_limit_mm");
  positive(l.stop_decel_mm_s2, "safety.stop_decel_mm_s2");
  if (l.min_ferror_mm > l.ferror_mm) {
    throw std::invalid_argument("limits: safety.min_ferror_mm must be <= safety.ferror_mm");
  }
  for (int i = 0; i < axes && i < 3; ++i) {
    const auto a = static_cast<std::size_t>(i);
    positive(l.max_velocity_mm_s[a], "machine.axes[" + std::to_string(i) + "].max_velocity");
    positive(l.max_accel_mm_s2[a], "machine.axes[" + std::to_string(i) + "].max_accel_mm_s2");
  }
}

SegmentRecord to_record(const control::PlannedSegment& s) noexcept {
  SegmentRecord r;
  r.kind = s.kind;
  r.start_cycle = s.start_cycle;
  r.samples = s.samples;
  for (int i = 0; i < 3; ++i) {
    r.start_mm[static_cast<std::size_t>(i)] = s.start_mm[i];
    r.end_mm[static_cast<std::size_t>(i)] = s.end_mm[i];
  }
  r.length_mm = s.length_mm;
  r.path_start_mm = s.path_start_mm;
  r.feed_mm_min = s.feed_mm_min;
  r.line = s.line;
  r.spindle = s.spindle;
  r.spindle_rpm = s.spindle_rpm;
  r.mist = s.mist;
  r.flood = s.flood;
  r.tool = s.tool;
  r.message_id = s.message_id;
  return r;
}

void from_record(const SegmentRecord& r, control::PlannedSegment& s) noexcept {
  s.kind = r.kind;
  s.start_cycle = r.start_cycle;
  s.samples = r.samples;
  for (int i = 0; i < 3; ++i) {
    s.start_mm[i] = r.start_mm[static_cast<std::size_t>(i)];
    s.end_mm[i] = r.end_mm[static_cast<std::size_t>(i)];
  }
  s.length_mm = r.length_mm;
  s.path_start_mm = r.path_start_mm;
  s.feed_mm_min = r.feed_mm_min;
  s.line = r.line;
  s.spindle = r.spindle;
  s.spindle_rpm = r.spindle_rpm;
  s.mist = r.mist;
  s.flood = r.flood;
  s.tool = r.tool;
  s.message_id = r.message_id;
}

ServoLoop::ServoLoop(const config::Config& cfg, AxisBus& bus, std::size_t event_capacity,
                     RtIo* io, LoopOptions opt)
    : cfg_(cfg),
      bus_(bus),
      io_(io),
      opt_(opt),
      commands_(256),
      events_(event_capacity),
      telemetry_(static_cast<std::size_t>(cfg.telemetry.ring_capacity)) {
  axes_ = static_cast<int>(cfg.machine.axes.size());
  if (axes_ < 1 || axes_ > 3) throw std::invalid_argument("servo loop: 1 to 3 axes");
  period_s_ = cfg.machine.period_s;
  for (std::size_t i = 0; i < 3; ++i) {
    if (i < cfg.machine.axes.size()) {
      const auto& a = cfg.machine.axes[i];
      gain_per_s_[i] = a.drive.gain_per_s;
      tau_s_[i] = a.drive.tau_s;
      min_mm_[i] = a.min_mm;
      max_mm_[i] = a.max_mm;
    } else {
      min_mm_[i] = -1e300;
      max_mm_[i] = 1e300;
    }
  }
  limits_ = live_limits_from(cfg);
  validate(limits_, axes_);
  applied_limits_ = staged_limits_ = limits_;
  base_params_ = servo_params_from(cfg);
  ctrl_.configure(base_params_);
  applied_params_ = staged_params_ = base_params_;
  model_.configure(config::make_model_params(cfg.control));
  // Force channel: configured whenever there is a force source (force control can then be
  // switched on by command even when force.enable is false at start-up).
  if (io_ != nullptr && io_->has_force()) {
    force_.configure(control::design_force_2dof(force_design_params(cfg)), cfg.force.limits);
    force_configured_ = true;
    force_requested_ = cfg.force.enable;
  }
  force_ref_N_ = cfg.force.reference_N;
  spindle_present_ = cfg.spindle.type != "none" || cfg.bus.spindle.has_value();
  spindle_ramp_ = drivers::SpindleRamp(cfg.spindle.limits);
  publish();
}

control::ServoParams ServoLoop::active_params() const {
  std::lock_guard lk(producer_mu_);
  // staged_params_ is active once the loop has taken it (its generation is published).
  if (status().gains_generation == staged_generation_.load(std::memory_order_relaxed)) {
    return staged_params_;
  }
  return applied_params_;
}

LiveLimits ServoLoop::active_limits() const {
  std::lock_guard lk(producer_mu_);
  if (status().limits_generation == staged_limits_generation_.load(std::memory_order_relaxed)) {
    return staged_limits_;
  }
  return applied_limits_;
}

bool ServoLoop::post(const LoopCommand& c) {
  std::lock_guard lk(producer_mu_);
  return commands_.push(c);
}

std::uint64_t ServoLoop::stage_gains(const control::ServoParams& p) {
  control::ServoController check(base_params_);
  check.check_live_compatible(p);  // throws std::invalid_argument
  std::lock_guard lk(producer_mu_);
  // Wait for the loop to take the previously staged set (one cycle); bounded.
  for (int i = 0; i < 2000 && staged_ready_.load(std::memory_order_acquire); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (staged_ready_.load(std::memory_order_acquire)) {
    throw std::runtime_error("servo loop is not running: previous gains still staged");
  }
  applied_params_ = staged_params_;  // taken by the loop: it is the active set now
  staged_params_ = p;
  const std::uint64_t gen = staged_generation_.load(std::memory_order_relaxed) + 1;
  staged_generation_.store(gen, std::memory_order_relaxed);
  staged_ready_.store(true, std::memory_order_release);
  return gen;
}

std::uint64_t ServoLoop::stage_limits(const LiveLimits& l) {
  validate(l, axes_);  // throws std::invalid_argument
  std::lock_guard lk(producer_mu_);
  for (int i = 0; i < 2000 && staged_limits_ready_.load(std::memory_order_acquire); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (staged_limits_ready_.load(std::memory_order_acquire)) {
    throw std::runtime_error("servo loop is not running: previous limits still staged");
  }
  applied_limits_ = staged_limits_;
  staged_limits_ = l;
  const std::uint64_t gen = staged_limits_generation_.load(std::memory_order_relaxed) + 1;
  staged_limits_generation_.store(gen, std::memory_order_relaxed);
  staged_limits_ready_.store(true, std::memory_order_release);
  return gen;
}

void ServoLoop::emit(EventKind k, FaultCause c, int axis, double value, double limit) noexcept {
  RtEvent e;
  e.cycle = cycle_;
  e.kind = k;
  e.from = sm_.state();
  e.to = sm_.state();
  e.cause = c;
  e.axis = axis;
  e.value = value;
  e.limit = limit;
  e.job = job_ != nullptr ? job_->id : 0;
  events_.push(e);
}

void ServoLoop::transition(const Transition& t, FaultCause cause) noexcept {
  if (!t.accepted || t.from == t.to) return;
  RtEvent e;
  e.cycle = cycle_;
  e.kind = EventKind::kTransition;
  e.from = t.from;
  e.to = t.to;
  e.cause = cause;
  e.job = job_ != nullptr ? job_->id : 0;
  events_.push(e);
}

void ServoLoop::raise_fault(FaultCause c, int axis, double value, double limit) noexcept {
  const Transition t = sm_.fault(c);
  if (!t.accepted) return;
  ++fault_counts_[static_cast<std::size_t>(c)];
  fault_axis_ = axis;
  fault_value_ = value;
  fault_limit_ = limit;
  emit(EventKind::kFault, c, axis, value, limit);
  transition(t, c);
  if (job_ != nullptr) detach_job(false);
  jogging_ = false;
}

void ServoLoop::detach_job(bool ok) noexcept {
  if (job_ == nullptr) return;
  if (!ok) job_->abort.store(true, std::memory_order_release);
  finished_job_ = job_->id;
  finished_ok_ = ok;
  finished_cycle_ = cycle_;
  released_job_ = job_->id;
  events_.push(RtEvent{cycle_, ok ? EventKind::kProgramDone : EventKind::kProgramAborted,
                       sm_.state(), sm_.state(), FaultCause::kNone, CommandKind::kStop, -1,
                       iout_.path_progress_mm, 0.0, job_->id});
  job_ = nullptr;
  stopping_ = false;
  settling_ = false;
  underrun_ = false;
}

void ServoLoop::hold_here() noexcept {
  ref_ = act_;
  ref_prev_ = act_;
  ctrl_.reset();
  model_.reset();
  v_cmd_.fill(0.0);
  jogging_ = false;
}

void ServoLoop::enter_estop(FaultCause cause) noexcept {
  const Transition t = sm_.estop(cause);
  if (!t.accepted) return;
  ++fault_counts_[static_cast<std::size_t>(cause)];
  emit(EventKind::kFault, cause);
  transition(t, cause);
  if (job_ != nullptr) detach_job(false);
  jogging_ = false;
  v_cmd_.fill(0.0);
}

void ServoLoop::apply_command(const LoopCommand& c) noexcept {
  const MachineState st = sm_.state();
  auto refuse = [&]() { refuse_command(c.kind); };
  switch (c.kind) {
    case CommandKind::kEnable:
      transition(sm_.apply(Request::kEnable), FaultCause::kNone);
      break;
    case CommandKind::kDisable:
      transition(sm_.apply(Request::kDisable), FaultCause::kNone);
      break;
    case CommandKind::kAttachJob:
      if (st == MachineState::kRunning || st == MachineState::kHold || c.job == nullptr) {
        refuse();
        if (c.job != nullptr) released_job_ = c.job->id;
        break;
      }
      if (job_ != nullptr) detach_job(false);
      job_ = c.job;
      settling_ = stopping_ = underrun_ = false;
      break;
    case CommandKind::kRun:
      if (st != MachineState::kReady || job_ == nullptr || jogging_) {
        refuse();
        break;
      }
      model_.reset();
      ctrl_.reset();
      iout_ = control::InterpOutput{};
      planned_progress_mm_ = 0.0;
      transition(sm_.apply(Request::kRun), FaultCause::kNone);
      break;
    case CommandKind::kHold:
      transition(sm_.apply(Request::kHold), FaultCause::kNone);
      break;
    case CommandKind::kResume:
      if (stopping_) {
        refuse();
        break;
      }
      if (st == MachineState::kHold && job_ != nullptr) job_->interp.resume();
      transition(sm_.apply(Request::kResume), FaultCause::kNone);
      break;
    case CommandKind::kStop:
      if ((st == MachineState::kRunning || st == MachineState::kHold) && job_ != nullptr) {
        stopping_ = true;
        job_->abort.store(true, std::memory_order_release);
        transition(sm_.apply(Request::kStop), FaultCause::kNone);
      } else if (jogging_) {
        // Brake the jog at the axis deceleration.
        const auto a = static_cast<std::size_t>(jog_axis_);
        const double dec = limits_.max_accel_mm_s2[a];
        const double dir = jog_target_mm_ >= ref_[jog_axis_] ? 1.0 : -1.0;
        jog_target_mm_ = ref_[jog_axis_] + dir * jog_speed_mm_s_ * jog_speed_mm_s_ / (2.0 * dec);
      } else if (job_ != nullptr && st == MachineState::kReady) {
        detach_job(false);  // unload a program that was never started
      }
      break;
    case CommandKind::kEstop:
      enter_estop(FaultCause::kEstopCommand);
      break;
    case CommandKind::kReset: {
      // The E-stop input latch is cleared by the non-RT side (IoChannels::reset_estop) first.
      if (st != MachineState::kFault && st != MachineState::kEstop) {
        refuse();
        break;
      }
      if (!try_reset()) {
        // Drives in Fault leave it only on the CiA 402 fault-reset edge, and the master's latched
        // heartbeat/bus faults only when acknowledged: ask the bus, then give the causes up to
        // kResetWindowCycles to clear (the reset completes in the cycle they do, else refused).
        bus_.acknowledge_faults();
        reset_pending_cycles_ = kResetWindowCycles;
      }
      break;
    }
    case CommandKind::kJog: {
      if (st != MachineState::kReady || c.axis < 0 || c.axis >= axes_ || !(c.a > 0.0) ||
          !std::isfinite(c.b)) {
        refuse();
        break;
      }
      jogging_ = true;
      jog_axis_ = c.axis;
      jog_v_mm_s_ = c.a;
      jog_speed_mm_s_ = 0.0;
      jog_target_mm_ = ref_[c.axis] + c.b;
      break;
    }
    case CommandKind::kSetOverride:
      feed_override_ = std::clamp(c.a, 0.0, cfg_.interpolator.feed_override_max_percent / 100.0);
      break;
    case CommandKind::kRecordFlag:
      recording_ = c.a != 0.0;
      break;
    case CommandKind::kSetPosition:
      // SimBus::set_position only resets a plant state (no allocation); a CANopen bus would do it
      // with SDOs and must not be called here (its adapter refuses: returns false).
      if ((st != MachineState::kReady && st != MachineState::kDisabled) || job_ != nullptr ||
          jogging_ || c.axis < 0 || c.axis >= axes_ || !bus_.set_position(c.axis, c.a)) {
        refuse();
        break;
      }
      act_[c.axis] = c.a;
      hold_here();
      break;
    case CommandKind::kForce:
      if (!force_configured_) {
        refuse();
        break;
      }
      if (std::isfinite(c.a)) force_ref_N_ = c.a;
      if (c.axis == 1) {
        force_requested_ = true;
        force_fallback_ = false;  // `force on` clears a latched fallback (ForceController::enable)
      } else if (c.axis == 0) {
        force_requested_ = false;
        force_fallback_ = false;
        if (force_.active()) emit(EventKind::kForceOff);
        force_.disable();
      }
      break;
  }
}

void ServoLoop::refuse_command(CommandKind k) noexcept {
  RtEvent e;
  e.cycle = cycle_;
  e.kind = EventKind::kCommandRefused;
  e.from = e.to = sm_.state();
  e.command = k;
  events_.push(e);
}

bool ServoLoop::try_reset() noexcept {
  bool gone = !fb_.heartbeat_lost && !fb_.bus_error && !(io_ != nullptr && io_->estop_tripped());
  for (int i = 0; i < axes_; ++i) gone = gone && !fb_.axis[static_cast<std::size_t>(i)].fault;
  gone = gone && !fb_.spindle.fault;
  const Transition t = sm_.reset(gone);
  if (!t.accepted) return false;
  ++resets_;
  transition(t, FaultCause::kNone);
  force_fallback_ = false;
  fault_axis_ = -1;
  fault_value_ = fault_limit_ = 0.0;
  missed_streak_.fill(0);
  transition(sm_.apply(Request::kEnable), FaultCause::kNone);
  return true;
}

void ServoLoop::cycle() noexcept {
  // 1. Cycle boundary: the staged gains (state kept: ServoController::set_gains) and limits.
  if (staged_ready_.load(std::memory_order_acquire)) {
    ctrl_.set_gains(staged_params_);
    gains_generation_ = staged_generation_.load(std::memory_order_relaxed);
    gains_cycle_ = cycle_;
    staged_ready_.store(false, std::memory_order_release);
    emit(EventKind::kGainsSwapped, FaultCause::kNone, -1, static_cast<double>(gains_generation_));
  }
  if (staged_limits_ready_.load(std::memory_order_acquire)) {
    limits_ = staged_limits_;
    limits_generation_ = staged_limits_generation_.load(std::memory_order_relaxed);
    staged_limits_ready_.store(false, std::memory_order_release);
    emit(EventKind::kLimitsSwapped, FaultCause::kNone, -1, static_cast<double>(limits_generation_));
  }

  // 2. SYNC and TPDOs.
  bus_.begin_cycle();
  bus_.read(fb_);
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (fb_.axis[a].fresh) {
      act_[i] = fb_.axis[a].position_mm;
      missed_streak_[a] = 0;
    } else {
      ++missed_streak_[a];
      ++missed_tpdos_;
    }
  }

  // Commands after the TPDOs, so that `reset` judges the drives' current fault bits.
  if (reset_pending_cycles_ > 0) {
    --reset_pending_cycles_;
    const MachineState st = sm_.state();
    if (st != MachineState::kFault && st != MachineState::kEstop) {
      reset_pending_cycles_ = 0;
    } else if (try_reset()) {
      reset_pending_cycles_ = 0;
    } else if (reset_pending_cycles_ == 0) {
      refuse_command(CommandKind::kReset);  // the causes did not clear within the window
    }
  }
  LoopCommand c;
  for (int n = 0; n < kMaxCommandsPerCycle && commands_.pop(c); ++n) apply_command(c);

  // 3. Force sample and E-stop input (latched by the monitor thread): ESTOP in this cycle, so
  // this cycle's RPDOs already carry the quick stop.
  if (io_ != nullptr) {
    reading_ = io_->read_force();
    force_xyz_N_ = reading_.sample.filtered_N;
    double sq = 0.0;
    for (std::size_t i = 0; i < 3; ++i) {
      if (reading_.sample.present[i]) sq += force_xyz_N_[i] * force_xyz_N_[i];
    }
    force_N_ = std::sqrt(sq);
    force_age_s_ = static_cast<double>(reading_.age_ns) * 1e-9;
    estop_input_ = io_->estop_tripped();
    if (estop_input_) enter_estop(FaultCause::kEstopInput);
  }

  MachineState st = sm_.state();

  // 4. Reference.
  ref_prev_ = ref_;
  control::InterpStatus ist = control::InterpStatus::kIdle;
  if (st == MachineState::kEnabling) {
    if (all_axes_enabled()) {
      hold_here();
      transition(sm_.apply(Request::kEnabled), FaultCause::kNone);
      st = sm_.state();
    }
  }
  // After the ENABLING -> READY step: the cycle that reaches READY already commands the drives
  // enabled (judged before it, that cycle sent "disable voltage" and the drives dropped out of
  // operation enabled for ~8 cycles right after READY — a `run` in that window met disabled drives).
  const bool motion = st == MachineState::kReady || st == MachineState::kRunning ||
                      st == MachineState::kHold;
  if (job_ != nullptr) {
    SegmentRecord rec;
    for (int n = 0; n < kMaxSegmentsPerCycle && job_->interp.free_slots() > 0 &&
                    job_->queue.pop(rec);
         ++n) {
      from_record(rec, seg_);
      job_->interp.push(seg_);
    }
  }
  if (job_ != nullptr && (st == MachineState::kRunning || st == MachineState::kHold)) {
    // The force controller's override (step 7 of the previous cycle) scales the user's.
    const double ovr =
        (st == MachineState::kRunning && !stopping_) ? feed_override_ * force_override_ : 0.0;
    ist = job_->interp.step(ovr, iout_);
    ref_ = iout_.position_mm;
    const bool planner_done = job_->planner_done.load(std::memory_order_acquire);
    if (ist == control::InterpStatus::kStarved && !planner_done) {
      if (!underrun_) {
        underrun_ = true;
        ++underruns_;
        emit(EventKind::kUnderrun, FaultCause::kQueueUnderrun, -1, iout_.path_progress_mm);
      }
    } else if (underrun_ && ist == control::InterpStatus::kRunning) {
      underrun_ = false;
      emit(EventKind::kUnderrunEnd);
    }
    if (job_->planner_failed.load(std::memory_order_acquire) && !stopping_) {
      stopping_ = true;
      transition(sm_.apply(Request::kStop), FaultCause::kNone);
    }
    if (ist == control::InterpStatus::kHolding && st == MachineState::kRunning) {
      transition(sm_.apply(Request::kHold), FaultCause::kNone);  // M0/M1/M6
    }
    // A feed move after a spindle start / speed change (the planner's kSpindleSync marker): the
    // path waits at its exact stop while the marker's speed is commanded (step 7) until the
    // spindle is at speed, at most spindle.at_speed_timeout_s, then FAULT.
    const bool was_waiting = spindle_waiting_;
    spindle_waiting_ = false;
    if (ist == control::InterpStatus::kSpindleWait && !stopping_) {
      using Wait = config::SpindleConfig::Wait;
      const Wait policy = cfg_.spindle.at_speed_wait;
      const bool wait = spindle_present_ && (policy == Wait::kAlways ||
                                             (policy == Wait::kForce && force_requested_));
      if (!wait) {
        job_->interp.resume();
      } else if (st == MachineState::kRunning) {
        if (!was_waiting) spindle_wait_cycles_ = 0;
        spindle_waiting_ = true;
        // Judged on the target of the marker (the ramp and the feedback of the previous cycle
        // must both be there): at_speed_ of an older target does not count.
        const double target =
            drivers::clamp_spindle_rpm(programmed_spindle_rpm(), cfg_.spindle.limits);
        if (spindle_at_speed_ && target == spindle_target_rpm_) {
          spindle_waiting_ = false;
          ++spindle_waits_;
          spindle_last_wait_s_ = static_cast<double>(spindle_wait_cycles_) * period_s_;
          job_->interp.resume();
          emit(EventKind::kSpindleAtSpeed, FaultCause::kNone, -1, spindle_last_wait_s_,
               fb_.spindle.actual_rpm);
        } else if (static_cast<double>(++spindle_wait_cycles_) * period_s_ >
                   cfg_.spindle.at_speed_timeout_s) {
          spindle_waiting_ = false;
          raise_fault(FaultCause::kSpindleNotAtSpeed, -1, fb_.spindle.actual_rpm, target);
        }
      }
    }
    const bool stationary = iout_.override_applied <= 0.0 ||
                            ist == control::InterpStatus::kSpindleWait ||
                            ist == control::InterpStatus::kHolding ||
                            ist == control::InterpStatus::kStarved ||
                            ist == control::InterpStatus::kDone;
    if (stopping_ && stationary) {
      detach_job(false);
      transition(sm_.apply(Request::kStopped), FaultCause::kNone);
    } else if (ist == control::InterpStatus::kDone ||
               (ist == control::InterpStatus::kStarved && planner_done &&
                job_->queue.size() == 0)) {
      if (!settling_) {
        settling_ = true;
        settle_cycles_ = 0;
      }
    }
  } else if (jogging_ && st == MachineState::kReady) {
    const auto a = static_cast<std::size_t>(jog_axis_);
    const double acc = limits_.max_accel_mm_s2[a];
    const double rem = jog_target_mm_ - ref_[jog_axis_];
    const double dir = rem >= 0.0 ? 1.0 : -1.0;
    const double v_brake = std::sqrt(2.0 * acc * std::abs(rem));
    const double v_des = std::min({jog_v_mm_s_, v_brake, limits_.max_velocity_mm_s[a]});
    jog_speed_mm_s_ = std::min(v_des, jog_speed_mm_s_ + acc * period_s_);
    const double step = std::min(jog_speed_mm_s_ * period_s_, std::abs(rem));
    ref_[jog_axis_] += dir * step;
    if (std::abs(jog_target_mm_ - ref_[jog_axis_]) < 1e-9) {
      ref_[jog_axis_] = jog_target_mm_;
      jogging_ = false;
    }
  } else if (!motion) {
    ref_ = act_;
  }

  // 5-6. Contour-error model and controllers.
  AxisCommands out;
  out.mode = DriveMode::kDisabled;
  double eps_norm = 0.0;
  const Eigen::Vector3d v_ref = (ref_ - ref_prev_) / period_s_;
  if (motion) {
    const control::Vec3 p_hat = ctrl_.predict(act_);
    model_.push_reference(ref_);
    const control::ContourErrorResult ce = model_.update(p_hat);
    eps_ = ce.eps;
    eps_norm = ce.eps.norm();
    control::Vec3 u = control::Vec3::Zero();
    ctrl_.update(ref_, p_hat, ce, v_ref, u);
    for (int i = 0; i < axes_; ++i) {
      const auto a = static_cast<std::size_t>(i);
      double v = gain_per_s_[a] * u[i];
      if (!std::isfinite(v)) v = 0.0;
      const double vmax = limits_.max_velocity_mm_s[a];
      if (std::abs(v) > vmax) {
        v = std::copysign(vmax, v);
        ++clamps_;
      }
      // Acceleration clamp. A velocity-mode drive follows its target with the lag tau of its
      // velocity loop, so the acceleration it will produce is (v_target - v_actual) / tau: the
      // target is kept within v_actual +- a_max * tau. Why not |v(k) - v(k-1)| <= a_max T on the
      // target: the coupling controller's derivative term makes the target step by ~18 mm/s per
      // 0.5 um encoder count (Cd K BLU / T), which the drive's lag filters; a per-cycle rate
      // limit at 2000 mm/s^2 turned that into phase lag and made the Table 2 run unstable
      // (contour error 1.1 mm, FAULT). Like the velocity clamp it is a last-line limit the
      // controller is not told about; it does not engage on Table 2 (status accel_clamps).
      if (fb_.axis[a].fresh && tau_s_[a] > 0.0) {
        const double dv = limits_.max_accel_mm_s2[a] * tau_s_[a];
        const double va = fb_.axis[a].velocity_mm_s;
        if (v > va + dv || v < va - dv) {
          v = std::clamp(v, va - dv, va + dv);
          ++accel_clamps_;
        }
      }
      v_cmd_[a] = v;
    }
    out.mode = DriveMode::kEnabled;
  } else if (st == MachineState::kFault) {
    // Controlled stop: ramp the commanded velocity vector down at stop_decel, then disable.
    double speed = 0.0;
    for (int i = 0; i < axes_; ++i) speed += v_cmd_[static_cast<std::size_t>(i)] * v_cmd_[static_cast<std::size_t>(i)];
    speed = std::sqrt(speed);
    const double next = std::max(0.0, speed - limits_.stop_decel_mm_s2 * period_s_);
    const double scale = speed > 0.0 ? next / speed : 0.0;
    for (auto& v : v_cmd_) v *= scale;
    out.mode = next > 0.0 ? DriveMode::kEnabled : DriveMode::kDisabled;
    eps_.setZero();
  } else if (st == MachineState::kEstop) {
    v_cmd_.fill(0.0);
    out.mode = DriveMode::kQuickStop;
    eps_.setZero();
  } else {
    v_cmd_.fill(0.0);
    out.mode = st == MachineState::kEnabling ? DriveMode::kEnabled : DriveMode::kDisabled;
    eps_.setZero();
  }
  for (int i = 0; i < axes_; ++i) out.velocity_mm_s[static_cast<std::size_t>(i)] = v_cmd_[static_cast<std::size_t>(i)];

  // 7. Force controller -> feed override (applied from the next interpolator step) and spindle.
  force_step(st);
  spindle_step(out.mode);
  out.spindle_rpm = out.mode == DriveMode::kEnabled ? spindle_out_rpm_ : 0.0;
  out_ = out;

  // 8. RPDOs.
  bus_.write(out);

  // 9. Safety checks.
  if (st != MachineState::kDisabled && st != MachineState::kFault && st != MachineState::kEstop) {
    for (int i = 0; i < axes_; ++i) {
      const auto a = static_cast<std::size_t>(i);
      if (fb_.axis[a].fault) {
        raise_fault(FaultCause::kDriveFault, i, 1.0, 0.0);
        break;
      }
      // A drive that leaves operation enabled without a fault (its enable input or STO opened, a
      // local operator, a stray controlword) no longer follows the commands: stop everything.
      // The master would otherwise walk it back to operation enabled on its own.
      if (motion && fb_.axis[a].fresh && !fb_.axis[a].enabled) {
        raise_fault(FaultCause::kDriveDisabled, i, 1.0, 0.0);
        break;
      }
      if (missed_streak_[a] >= cfg_.safety.missed_tpdo_streak) {
        raise_fault(FaultCause::kMissedTpdo, i, missed_streak_[a], cfg_.safety.missed_tpdo_streak);
        break;
      }
    }
    if (fb_.spindle.fault) raise_fault(FaultCause::kSpindleFault, -1, fb_.spindle.actual_rpm, 0.0);
    if (fb_.heartbeat_lost) raise_fault(FaultCause::kHeartbeatLost, fb_.heartbeat_lost_node, 1.0, 0.0);
    if (fb_.bus_error) raise_fault(FaultCause::kBusError, -1, 1.0, 0.0);
  }
  if (motion && sm_.state() != MachineState::kFault) {
    const double fe = limits_.ferror_mm, mfe = limits_.min_ferror_mm;
    for (int i = 0; i < axes_; ++i) {
      const auto a = static_cast<std::size_t>(i);
      // LinuxCNC: the allowed following error grows linearly with the commanded speed from
      // MIN_FERROR at standstill to FERROR at the axis' maximum velocity.
      const double band =
          std::min(fe, mfe + (fe - mfe) * std::abs(v_ref[i]) / limits_.max_velocity_mm_s[a]);
      const double err = std::abs(ref_[i] - act_[i]);
      if (err > band) {
        raise_fault(FaultCause::kFollowingError, i, err, band);
        break;
      }
      if (ref_[i] < min_mm_[a] - 1e-9 || ref_[i] > max_mm_[a] + 1e-9) {
        raise_fault(FaultCause::kSoftLimit, i, ref_[i], ref_[i] < min_mm_[a] ? min_mm_[a] : max_mm_[a]);
        break;
      }
    }
    if (eps_norm > limits_.contour_error_limit_mm) {
      raise_fault(FaultCause::kContourError, -1, eps_norm, limits_.contour_error_limit_mm);
    }
  }

  // Program end: once the reference has stopped, wait for the tool to arrive (in position).
  if (settling_ && job_ != nullptr && sm_.state() == MachineState::kRunning) {
    ++settle_cycles_;
    double err = 0.0;
    for (int i = 0; i < axes_; ++i) err = std::max(err, std::abs(ref_[i] - act_[i]));
    if (err < kInPositionMm ||
        static_cast<double>(settle_cycles_) * period_s_ > kSettleTimeoutS) {
      detach_job(true);
      transition(sm_.apply(Request::kDone), FaultCause::kNone);
    }
  }

  // 10. Telemetry.
  const int dec = std::max(1, cfg_.telemetry.decimation);
  if (cycle_ % static_cast<std::uint64_t>(dec) == 0) {
    TelemetrySample s;
    s.cycle = cycle_;
    s.t_s = static_cast<double>(cycle_) * period_s_;
    s.job = job_ != nullptr ? job_->id : 0;
    for (std::size_t i = 0; i < 3; ++i) {
      s.ref_mm[i] = ref_[static_cast<Eigen::Index>(i)];
      s.act_mm[i] = act_[static_cast<Eigen::Index>(i)];
      s.eps_mm[i] = eps_[static_cast<Eigen::Index>(i)];
      s.cmd_mm_s[i] = v_cmd_[i];
    }
    s.progress_mm = iout_.path_progress_mm;
    s.override_applied = iout_.override_applied;
    s.line = iout_.line;
    s.state = sm_.state();
    s.recording = recording_;
    s.in_program = job_ != nullptr && (s.state == MachineState::kRunning || s.state == MachineState::kHold);
    s.force_N = force_N_;
    s.force_override = force_override_;
    s.spindle_rpm = spindle_rpm_cmd_;
    telemetry_.push(s);
  }
  publish();
  ++cycle_;
}

void ServoLoop::force_step(MachineState st) noexcept {
  const bool in_prog =
      job_ != nullptr && (st == MachineState::kRunning || st == MachineState::kHold);
  const double programmed_rpm = in_prog ? programmed_spindle_rpm() : 0.0;
  if (!force_configured_) {
    force_override_ = 1.0;
    spindle_rpm_cmd_ = programmed_rpm;
    return;
  }
  const control::ForceLimits& lim = cfg_.force.limits;
  // Not while a feed move waits for the spindle: the path stands, the controller would wind up.
  const bool running = in_prog && st == MachineState::kRunning && !stopping_ && !spindle_waiting_;
  // Planned progress (the position reference of the 2-DOF controller): a ramp at the design's
  // path speed k_v (force.plant.k_v_mm_s, speed at 100 % override) times the user's override.
  // The design assumes the program's feed equals k_v; another feed is a model gain error in the
  // position channel (seed 001 §3: the controller is designed for one operating point).
  if (running) planned_progress_mm_ += cfg_.force.design.plant.k_v_mm_s * feed_override_ * period_s_;
  if (force_requested_ && !force_fallback_ && running && !force_.active()) {
    // Engage bumplessly from the current state (an invalid sample latches the fallback at once).
    planned_progress_mm_ = iout_.path_progress_mm;
    const double rpm0 = spindle_rpm_cmd_ != 0.0 ? std::abs(spindle_rpm_cmd_) : lim.spindle_nominal_rpm;
    force_.enable({force_override_, rpm0, force_N_, iout_.path_progress_mm});
    emit(EventKind::kForceOn, FaultCause::kNone, -1, force_ref_N_);
  }
  if (!running && force_.active()) {
    // Program ended, HOLD or stopping: the path does not follow the override, so the controller
    // would wind up against a standing tool. Off now, re-engaged bumplessly on resume / the next
    // run (force_requested_ stays).
    force_.disable();
    emit(EventKind::kForceOff);
  }
  const bool ok = reading_.state == drivers::modbus::ForceState::kOk;
  control::ForceInput in;
  in.force_ref_N = force_ref_N_;
  in.planned_progress_mm = planned_progress_mm_;
  in.force_N = force_N_;
  in.progress_mm = iout_.path_progress_mm;
  in.force_valid = ok;
  in.force_age_s = force_age_s_;
  const control::ForceStatus prev = fout_.status;
  fout_ = force_.step(in);
  const bool stale_now = fout_.status == control::ForceStatus::kStaleHold ||
                         fout_.status == control::ForceStatus::kStaleProgrammed;
  if (stale_now && !force_fallback_ && force_requested_) {
    force_fallback_ = true;
    ++force_fallbacks_;
    emit(EventKind::kForceFallback, FaultCause::kForceStale, static_cast<int>(fout_.status),
         force_age_s_, lim.stale_age_s);
    if (opt_.force_stale_faults) raise_fault(FaultCause::kForceStale, -1, force_age_s_, lim.stale_age_s);
  }
  if (fout_.status == control::ForceStatus::kCeilingHold && prev != control::ForceStatus::kCeilingHold) {
    emit(EventKind::kForceCeiling, FaultCause::kForceCeiling, -1, force_N_, lim.force_ceiling_N);
  }
  if (force_fallback_ && ok && !force_ok_prev_) emit(EventKind::kForceRecovered);
  force_ok_prev_ = ok;
  const bool controlling = force_.active() || fout_.status == control::ForceStatus::kStaleHold ||
                           fout_.status == control::ForceStatus::kCeilingHold;
  if (force_requested_) {
    force_override_ = fout_.feed_override;
  } else {
    // Off: back to the programmed feed at the override rate limit (no step in the path speed).
    const double d = lim.override_rate_per_s * period_s_;
    force_override_ = std::clamp(1.0, force_override_ - d, force_override_ + d);
  }
  spindle_rpm_cmd_ = (force_requested_ && controlling && in_prog)
                         ? std::copysign(fout_.spindle_rpm, programmed_rpm != 0.0 ? programmed_rpm : 1.0)
                         : programmed_rpm;
  if (io_ != nullptr) io_->set_spindle_rpm(std::abs(spindle_rpm_cmd_));
}

double ServoLoop::programmed_spindle_rpm() const noexcept {
  switch (iout_.spindle) {
    case control::SpindleDir::kCw: return iout_.spindle_rpm;
    case control::SpindleDir::kCcw: return -iout_.spindle_rpm;
    case control::SpindleDir::kOff: break;
  }
  return 0.0;
}

bool ServoLoop::all_axes_enabled() const noexcept {
  bool all = axes_ > 0;
  for (int i = 0; i < axes_; ++i) all = all && fb_.axis[static_cast<std::size_t>(i)].enabled;
  return all;
}

void ServoLoop::spindle_step(DriveMode mode) noexcept {
  if (!spindle_present_) {  // no spindle: the programmed speed is only information (filter, GPIO)
    spindle_target_rpm_ = spindle_out_rpm_ = spindle_rpm_cmd_;
    spindle_at_speed_ = false;
    return;
  }
  const drivers::SpindleLimits& l = cfg_.spindle.limits;
  spindle_target_rpm_ = drivers::clamp_spindle_rpm(spindle_rpm_cmd_, l);
  if (mode == DriveMode::kEnabled) {
    spindle_out_rpm_ = spindle_ramp_.step(spindle_target_rpm_, period_s_);
  } else {
    spindle_ramp_.reset(0.0);  // the drive is off: a restart ramps up from standstill
    spindle_out_rpm_ = 0.0;
  }
  // A VFD spindle (RtIo): it gets the same rate-limited command and reports its speed; the loop
  // judges at-speed on the same rule as for a bus spindle.
  if (io_ != nullptr && io_->has_spindle()) {
    io_->command_spindle(spindle_out_rpm_);
    const drivers::SpindleStatus s = io_->spindle_status();
    fb_.spindle.present = true;
    fb_.spindle.fresh = s.comm_ok;
    fb_.spindle.actual_rpm = s.actual_rpm;
    fb_.spindle.enabled = s.comm_ok;
    fb_.spindle.fault = s.fault == drivers::SpindleFault::kDrive;
  }
  // At speed: the ramp has arrived and the spindle follows (with feedback), or the ramp alone
  // (a spindle without speed feedback).
  const bool ramp_done = spindle_out_rpm_ == spindle_target_rpm_;
  if (fb_.spindle.present) {
    spindle_at_speed_ = ramp_done && mode == DriveMode::kEnabled && fb_.spindle.enabled &&
                        drivers::spindle_at_speed(fb_.spindle.actual_rpm, spindle_target_rpm_, l);
  } else {
    spindle_at_speed_ = ramp_done && mode == DriveMode::kEnabled;
  }
}

void ServoLoop::publish() noexcept {
  const std::uint64_t s0 = seq_.load(std::memory_order_relaxed);
  seq_.store(s0 + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  pub_.cycle = cycle_;
  pub_.state = sm_.state();
  pub_.cause = sm_.cause();
  pub_.fault_axis = fault_axis_;
  pub_.fault_value = fault_value_;
  pub_.fault_limit = fault_limit_;
  for (std::size_t i = 0; i < 3; ++i) {
    pub_.ref_mm[i] = ref_[static_cast<Eigen::Index>(i)];
    pub_.act_mm[i] = act_[static_cast<Eigen::Index>(i)];
    pub_.cmd_mm_s[i] = v_cmd_[i];
  }
  pub_.eps_norm_mm = eps_.norm();
  pub_.progress_mm = iout_.path_progress_mm;
  pub_.line = iout_.line;
  pub_.override_applied = iout_.override_applied;
  pub_.feed_override = feed_override_;
  pub_.attached_job = job_ != nullptr ? job_->id : 0;
  pub_.finished_job = finished_job_;
  pub_.finished_ok = finished_ok_;
  pub_.finished_cycle = finished_cycle_;
  pub_.released_job = released_job_;
  pub_.underruns = underruns_;
  pub_.missed_tpdos = missed_tpdos_;
  pub_.velocity_clamps = clamps_;
  pub_.gains_generation = gains_generation_;
  pub_.gains_cycle = gains_cycle_;
  pub_.jogging = jogging_;
  pub_.interp_holding = iout_.status == control::InterpStatus::kHolding;
  pub_.recording = recording_;
  pub_.drives_enabled = all_axes_enabled();
  pub_.accel_clamps = accel_clamps_;
  pub_.limits_generation = limits_generation_;
  pub_.force_available = force_configured_;
  pub_.force_state = reading_.state;
  pub_.force_xyz_N = force_xyz_N_;
  pub_.force_N = force_N_;
  pub_.force_age_s = force_age_s_;
  pub_.force_seq = reading_.sample.seq;
  pub_.force_requested = force_requested_;
  pub_.force_active = force_.active();
  pub_.force_status = fout_.status;
  pub_.force_ref_N = force_ref_N_;
  pub_.force_override = force_override_;
  pub_.force_fallback = force_fallback_;
  pub_.force_fallbacks = force_fallbacks_;
  pub_.spindle_rpm_cmd = out_.spindle_rpm;
  pub_.fault_counts = fault_counts_;
  pub_.resets = resets_;
  pub_.emcy_frames = fb_.emcy_count;
  pub_.spindle_present = spindle_present_;
  pub_.spindle_feedback = fb_.spindle.present;
  pub_.spindle_target_rpm = spindle_target_rpm_;
  pub_.spindle_actual_rpm = fb_.spindle.actual_rpm;
  pub_.spindle_at_speed = spindle_at_speed_;
  pub_.spindle_waiting = spindle_waiting_;
  pub_.spindle_waits = spindle_waits_;
  pub_.spindle_last_wait_s = spindle_last_wait_s_;
  pub_.out_drive_enable = out_.mode == DriveMode::kEnabled && sm_.state() != MachineState::kEstop;
  // On while a speed is requested (M3/M4 with S): M5 drops it at once, the drive decelerates
  // (the rate-limited command ramps down with it).
  pub_.out_spindle_enable = out_.mode == DriveMode::kEnabled && spindle_target_rpm_ != 0.0;
  const bool in_prog = job_ != nullptr;
  pub_.out_mist = in_prog && iout_.mist && sm_.state() != MachineState::kEstop;
  pub_.out_flood = in_prog && iout_.flood && sm_.state() != MachineState::kEstop;
  pub_.estop_input = estop_input_;
  std::atomic_thread_fence(std::memory_order_release);
  seq_.store(s0 + 2, std::memory_order_release);
}

LoopStatus ServoLoop::status() const noexcept {
  LoopStatus out;
  for (;;) {
    const std::uint64_t s0 = seq_.load(std::memory_order_acquire);
    if ((s0 & 1U) != 0) {
      std::this_thread::yield();
      continue;
    }
    out = pub_;
    std::atomic_thread_fence(std::memory_order_acquire);
    if (seq_.load(std::memory_order_relaxed) == s0) return out;
  }
}

void ServoLoop::run(const std::atomic<bool>& stop) noexcept {
  CycleClock clock(static_cast<std::int64_t>(cfg_.loop.period_us) * 1000);
  clock.start();
  while (!stop.load(std::memory_order_acquire)) {
    const std::int64_t wake = clock.wait_next(stats_);
    cycle();
    clock.end_cycle(stats_, wake);
  }
}

}  // namespace contour::daemon
