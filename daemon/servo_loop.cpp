#include "daemon/servo_loop.hpp"

#include "control/system_identification.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace contour::daemon {

namespace {

constexpr int kMaxCommandsPerCycle = 16;

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

}  // namespace

ServoLoop::ServoLoop(const config::Config& cfg, AxisBus& bus, std::size_t event_capacity,
                     RtIo* io, LoopOptions opt)
    : cfg_(cfg),
      bus_(bus),
      io_(io),
      opt_(opt),
      supervisor_(cfg, opt.force_stale_faults),
      program_(cfg.spindle.limits, cfg.machine.period_s),
      force_(cfg, io != nullptr && io->has_force()),
      spindle_(cfg.spindle, cfg.spindle.type != "none" || cfg.bus.spindle.has_value()),
      commands_(256),
      events_(event_capacity),
      telemetry_(static_cast<std::size_t>(cfg.telemetry.ring_capacity)) {
  axes_ = static_cast<int>(cfg.machine.axes.size());
  if (axes_ < 1 || axes_ > 3) throw std::invalid_argument("servo loop: 1 to 3 axes");
  // The PLC engine reads CiA 401 modules from the loop's feedback (BusFeedback::io), which the
  // CANopen bus fills. The in-process sim bus has no CAN I/O modules: such a signal would sit at
  // its default forever, so it is refused at start-up instead of ignored.
  if (cfg.plc.present && cfg.bus.type == "sim") {
    for (const auto& sig : cfg.plc.signals) {
      if (sig.binding.kind != config::PlcBindingKind::kCia401) continue;
      throw std::invalid_argument(
          sig.where + ": plc signal '" + sig.name +
          "': cia401 (CAN I/O module) bindings need the CANopen bus (bus.type socketcan): the "
          "sim bus has no CiA 401 modules; bind the signal to sim, gpio, modbus or cia402");
    }
  }
  io_age_.fill(kDriveInputsNever);
  drive_inputs_max_age_ = cfg.safety.missed_tpdo_streak > 0 ? cfg.safety.missed_tpdo_streak : 1;
  period_s_ = cfg.machine.period_s;
  for (std::size_t i = 0; i < 3 && i < cfg.machine.axes.size(); ++i) {
    gain_per_s_[i] = cfg.machine.axes[i].drive.gain_per_s;
    tau_s_[i] = cfg.machine.axes[i].drive.tau_s;
    // Velocity-loop lag over one period: the estimate of the axis velocity while its feedback is
    // stale (v_est += (v_cmd - v_est) * lag_alpha), the acceleration clamp's reference then.
    lag_alpha_[i] = tau_s_[i] > 0.0 ? 1.0 - std::exp(-period_s_ / tau_s_[i]) : 1.0;
  }
  for (std::size_t i = 0; i < 3 && i < cfg.machine.axes.size(); ++i) {
    // An absolute encoder knows the machine position from the start.
    const config::HomeConfig& h = cfg.machine.axes[i].home;
    if (h.method == config::HomeConfig::Method::kAbsolute) {
      home_shift_mm_[i] = h.home_offset_mm;
      homed_[i] = true;
    }
  }
  limits_ = live_limits_from(cfg);
  optional_stop_ = cfg.interpolator.optional_stop;
  validate(limits_, axes_);
  limits_eff_ = limits_;
  applied_limits_ = staged_limits_ = limits_;
  base_params_ = servo_params_from(cfg);
  ctrl_.configure(base_params_);
  applied_params_ = staged_params_ = base_params_;
  model_.configure(config::make_model_params(cfg.control));
  {
    control::ExcitationParams ep;
    ep.period_s = period_s_;
    ident_exc_ = control::make_excitation(ep);
    ident_v_.assign(ident_exc_.size(), 0.0);
    ident_x_.assign(ident_exc_.size(), 0.0);
  }
  {
    const auto& w = cfg.safety.chatter;
    control::ChatterMonitorParams cp;
    cp.period_s = period_s_;
    cp.window_s = std::max(w.window_s, control::ChatterMonitor::kBlocks * period_s_);
    cp.warn_chatter_mm_s = w.warn_mm_s;
    cp.warn_clamps_per_s = w.warn_clamps_per_s;
    cp.warn_time_s = w.warn_s;
    cp.fault_chatter_mm_s = w.fault_mm_s;
    cp.fault_clamps_per_s = w.fault_clamps_per_s;
    cp.fault_time_s = w.fault_s;
    chatter_mon_.configure(cp, axes_);
    chatter_enabled_ = w.enable;
    job_chatter_.reset(axes_);
  }
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

void ServoLoop::emit(EventKind k, FaultCause c, int axis, double value, double limit,
                     std::uint8_t detail) noexcept {
  RtEvent e;
  e.detail = detail;
  e.cycle = cycle_;
  e.kind = k;
  e.from = sm_.state();
  e.to = sm_.state();
  e.cause = c;
  e.axis = axis;
  e.value = value;
  e.limit = limit;
  e.job = program_.attached() ? program_.job()->id : 0;
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
  e.job = program_.attached() ? program_.job()->id : 0;
  events_.push(e);
}

void ServoLoop::raise_fault(const FaultReport& f) noexcept {
  const Transition t = sm_.fault(f.cause);
  if (!t.accepted) return;
  ++fault_counts_[static_cast<std::size_t>(f.cause)];
  fault_axis_ = f.axis;
  fault_value_ = f.value;
  fault_limit_ = f.limit;
  fault_detail_ = f.detail;
  emit(EventKind::kFault, f.cause, f.axis, f.value, f.limit, f.detail);
  transition(t, f.cause);
  detach_job(false);
  jog_.cancel();
  cancel_homing();
  stop_.start(stop_velocity(), axes_);
}

void ServoLoop::detach_job(bool ok) noexcept {
  const double progress = program_.output().path_progress_mm;
  ProgramJob* job = program_.detach(ok);
  if (job == nullptr) return;
  if (plc_ != nullptr) {  // a sequence of this program still running is abandoned
    plc_->release_mcode();
    plc_->release_tool_change();
  }
  finished_job_ = job->id;
  finished_ok_ = ok;
  finished_cycle_ = cycle_;
  released_job_ = job->id;
  events_.push(RtEvent{cycle_, ok ? EventKind::kProgramDone : EventKind::kProgramAborted,
                       sm_.state(), sm_.state(), FaultCause::kNone, CommandKind::kStop, -1,
                       progress, 0.0, job->id});
}

bool ServoLoop::soft_limits_apply(int axis) const noexcept {
  const auto a = static_cast<std::size_t>(axis);
  if (homing_.active() && (homing_.homing_mask() >> axis & 1u) != 0) return false;
  return homed_[a] || cfg_.machine.allow_unhomed;
}

bool ServoLoop::program_may_run() const noexcept {
  if (cfg_.machine.allow_unhomed) return true;
  for (int i = 0; i < axes_; ++i) {
    if (!homed_[static_cast<std::size_t>(i)]) return false;
  }
  return true;
}

void ServoLoop::update_effective_limits() noexcept {
  limits_eff_dirty_ = false;
  limits_eff_ = limits_;
  for (int i = 0; i < axes_; ++i) {
    if (soft_limits_apply(i)) continue;
    const auto a = static_cast<std::size_t>(i);
    limits_eff_.min_mm[a] = -1e300;
    limits_eff_.max_mm[a] = 1e300;
  }
}

void ServoLoop::cancel_homing() noexcept {
  if (!homing_.active()) return;
  homing_.cancel();
  limits_eff_dirty_ = true;
  homing_failure_ = 5;
  homing_failure_axis_ = -1;
  emit(EventKind::kHomingFailed, FaultCause::kNone, -1, 0.0, 0.0, 5);
  homing_was_active_ = false;
}

RefPoint ServoLoop::homing_step() noexcept {
  RefPoint r = homing_.step(fb_, limits_, period_s_);
  homing_drive_ = homing_drive_ || homing_.drive_group();
  for (int i = 0; i < axes_; ++i) {
    // The drive moves the axis itself and the reference follows the measurement: the reference
    // speed is the measured one, also across the jump of the drive's position at "attained" (the
    // following-error band and a stop's start velocity see the real motion, never a spike).
    if (homing_.drive_moves(i)) ref_prev_[i] = r.position_mm[i] - v_est_[static_cast<std::size_t>(i)] * period_s_;
  }
  if (homing_.shift_pending()) {
    // The group latched and stands: its machine coordinates move so that each latch point reads
    // home_offset_mm. Reference, measurement and the previous reference move together (no
    // velocity step); the controllers and the model restart from rest in the new coordinates.
    const std::uint32_t g = homing_.group_mask();
    for (int i = 0; i < axes_; ++i) {
      if ((g >> i & 1u) == 0) continue;
      const auto a = static_cast<std::size_t>(i);
      const double shift = homing_.offset_mm(i) - homing_.latch_mm(i);
      home_shift_mm_[a] += shift;
      fb_.act_mm[i] += shift;
      r.position_mm[i] += shift;
      ref_prev_[i] += shift;
      homed_[a] = true;
      emit(EventKind::kHomed, FaultCause::kNone, i, homing_.latch_mm(i), homing_.offset_mm(i));
    }
    ctrl_.reset();
    model_.reset();
    v_cmd_.fill(0.0);
    homing_.shifted(r.position_mm);
    homing_drive_ = false;  // restarted from rest just now
    limits_eff_dirty_ = true;
  }
  if (!homing_.active()) {
    if (homing_drive_) {
      // A drive homed an axis without the loop's command and the homing ended without a shift
      // (failure, stop): the controllers' drive models missed that travel; restart from rest
      // where the axes stand (every axis of the group does by now).
      ctrl_.reset();
      model_.reset();
      v_cmd_.fill(0.0);
      homing_drive_ = false;
    }
    if (homing_.failed()) {
      homing_failure_ = homing_.failure_code();
      homing_failure_axis_ = homing_.failed_axis();
      homing_failure_value_ = homing_.failure_value();
      emit(EventKind::kHomingFailed, FaultCause::kNone, homing_.failed_axis(), homing_.failure_value(),
           0.0, homing_.failure_code());
    } else if (homing_was_active_ && homing_.homing_mask() != 0) {
      bool aborted = false;
      for (int i = 0; i < axes_; ++i) {
        if ((homing_.homing_mask() >> i & 1u) != 0 && !homed_[static_cast<std::size_t>(i)]) aborted = true;
      }
      if (aborted) {
        homing_failure_ = 5;
        emit(EventKind::kHomingFailed, FaultCause::kNone, -1, 0.0, 0.0, 5);
      }
    }
    homing_was_active_ = false;
    limits_eff_dirty_ = true;
  }
  return r;
}

void ServoLoop::hold_here() noexcept {
  ref_ = fb_.act_mm;
  ref_prev_ = fb_.act_mm;
  hold_.start(fb_.act_mm);
  ctrl_.reset();
  model_.reset();
  v_cmd_.fill(0.0);
  jog_.cancel();
}

// The velocity each axis really has, for the start of a controlled stop (issue 16: the ramp
// used to start from the last COMMAND, which carries the coupling derivative's chatter: on a drive
// fault Z went from 3.3 to 21 mm/s). While the axis tracked its reference (servo, feedback fresh,
// following error inside its band) the reference velocity is both real and smooth; otherwise the
// measured velocity when fresh, else the drive-model estimate. Never more than, nor opposite to,
// what the drive was last told: from the fault on no axis' |command| increases.
std::array<double, kMaxAxes> ServoLoop::stop_velocity() const noexcept {
  std::array<double, kMaxAxes> v{};
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const AxisFeedback& ax = fb_.bus.axis[a];
    const bool tracking = last_servo_ && ax.fresh &&
                          std::abs(ref_[i] - fb_.act_mm[i]) <= following_band_mm(limits_, i, v_ref_[i]);
    double vi = tracking ? v_ref_[i] : ax.fresh ? ax.velocity_mm_s : v_est_[a];
    if (!std::isfinite(vi)) vi = 0.0;
    const double c = v_cmd_[a];
    if (vi * c <= 0.0) {
      vi = 0.0;
    } else if (std::abs(vi) > std::abs(c)) {
      vi = c;
    }
    v[a] = vi;
  }
  return v;
}

void ServoLoop::enter_estop(FaultCause cause) noexcept {
  const Transition t = sm_.estop(cause);
  if (!t.accepted) return;
  ++fault_counts_[static_cast<std::size_t>(cause)];
  emit(EventKind::kFault, cause);
  transition(t, cause);
  detach_job(false);
  jog_.cancel();
  cancel_homing();
  v_cmd_.fill(0.0);
}

void ServoLoop::apply_command(const LoopCommand& c) noexcept {
  const MachineState st = sm_.state();
  auto refuse = [&]() { refuse_command(c.kind); };
  switch (c.kind) {
    case CommandKind::kEnable:
      transition(sm_.apply(Request::kEnable), FaultCause::kNone);
      break;
    case CommandKind::kDisable: {
      const Transition t = sm_.apply(Request::kDisable);
      if (t.accepted && t.from != t.to) {
        // The drives are switched off only at standstill: a moving axis (a jog) is ramped down
        // first, like a fault's controlled stop.
        jog_.cancel();
        cancel_homing();
        stop_.start(stop_velocity(), axes_);
      }
      transition(t, FaultCause::kNone);
      break;
    }
    case CommandKind::kAttachJob:
      if (st == MachineState::kRunning || st == MachineState::kHold || c.job == nullptr) {
        refuse();
        if (c.job != nullptr) released_job_ = c.job->id;
        break;
      }
      detach_job(false);
      program_.attach(c.job);
      break;
    case CommandKind::kRun:
      if (st != MachineState::kReady || !program_.attached() || jog_.active() || homing_.active() ||
          !program_may_run() || plc_req_.inhibit_start) {  // soft PLC: NC.inhibit_start
        refuse();
        break;
      }
      model_.reset();
      ctrl_.reset();
      program_.start();
      force_.restart_progress();
      transition(sm_.apply(Request::kRun), FaultCause::kNone);
      break;
    case CommandKind::kHold:
      transition(sm_.apply(Request::kHold), FaultCause::kNone);
      break;
    case CommandKind::kResume:
      // Soft PLC: no resume while it holds (NC.feed_hold_req) or inhibits start.
      if (program_.stopping() || plc_req_.feed_hold || plc_req_.inhibit_start) {
        refuse();
        break;
      }
      if (st == MachineState::kHold) program_.resume();
      transition(sm_.apply(Request::kResume), FaultCause::kNone);
      break;
    case CommandKind::kStop:
      if ((st == MachineState::kRunning || st == MachineState::kHold) && program_.attached()) {
        program_.request_stop();
        transition(sm_.apply(Request::kStop), FaultCause::kNone);
      } else if (jog_.active()) {
        // Brake the jog at the axis deceleration.
        jog_.brake(ref_[jog_.axis()], limits_.max_accel_mm_s2[static_cast<std::size_t>(jog_.axis())]);
      } else if (homing_.active()) {
        homing_.abort();  // the homing axes brake at their acceleration; not homed
      } else if (program_.attached() && st == MachineState::kReady) {
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
        ++reset_verdicts_;
        break;
      }
      if (try_reset()) {
        ++reset_verdicts_;
      } else {
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
          !std::isfinite(c.b) || plc_req_.inhibit_start || homing_.active()) {
        refuse();
        break;
      }
      // Not homed (and homing required): the slow jog speed of home.unhomed_jog_mm_min.
      const auto ja = static_cast<std::size_t>(c.axis);
      const double v = soft_limits_apply(c.axis) ? c.a : std::min(c.a, cfg_.machine.axes[ja].home.unhomed_jog_mm_s);
      jog_.start(c.axis, v, ref_[c.axis] + c.b);
      break;
    }
    case CommandKind::kHome: {
      if (st != MachineState::kReady || program_.attached() || jog_.active() || homing_.active() ||
          c.axis < -1 || c.axis >= axes_ || plc_req_.inhibit_start ||
          ident_state_.load(std::memory_order_relaxed) == IdentifyState::kRunning) {
        refuse();
        break;
      }
      std::array<HomingSource::AxisPlan, kMaxAxes> plan{};
      bool any = false;
      for (int i = 0; i < axes_; ++i) {
        const auto a = static_cast<std::size_t>(i);
        const config::HomeConfig& h = cfg_.machine.axes[a].home;
        using M = config::HomeConfig::Method;
        if ((h.method != M::kSwitch && h.method != M::kDrive) || (c.axis >= 0 && c.axis != i)) continue;
        plan[a] = {true, h.sequence, h.search_vel_mm_s, h.latch_vel_mm_s, h.home_offset_mm,
                   h.home_position_mm, h.search_distance_mm, h.use_index,
                   h.method == M::kDrive, h.drive_timeout_s};
        // The final move of a drive-homed axis runs at its search speed (as method switch).
        if (h.method == M::kDrive && !(plan[a].search_mm_s > 0.0)) plan[a].search_mm_s = limits_.max_velocity_mm_s[a];
        any = true;
      }
      if (!any) {
        refuse();
        break;
      }
      for (int i = 0; i < axes_; ++i) {
        if (plan[static_cast<std::size_t>(i)].home) homed_[static_cast<std::size_t>(i)] = false;
      }
      homing_.start(plan, axes_, ref_);
      homing_was_active_ = true;
      limits_eff_dirty_ = true;
      ++homing_runs_;
      homing_failure_ = 0;
      homing_failure_axis_ = -1;
      break;
    }
    case CommandKind::kJogBrake:
      if (jog_.active()) {
        jog_.brake(ref_[jog_.axis()], limits_.max_accel_mm_s2[static_cast<std::size_t>(jog_.axis())]);
      }
      break;
    case CommandKind::kSetOptionalStop:
      optional_stop_ = c.a != 0.0;
      break;
    case CommandKind::kSetSingleBlock:
      single_block_ = c.a != 0.0;
      break;
    case CommandKind::kSetOverride: {
      const double v = std::isfinite(c.a) ? c.a : 0.0;
      if (c.axis == kOverrideRapid) {
        rapid_override_ = std::clamp(v, 0.0, limits_.rapid_override_max);
      } else if (c.axis == kOverrideSpindle) {
        spindle_override_ = std::clamp(v, limits_.spindle_override_min, limits_.spindle_override_max);
      } else {
        feed_override_ = std::clamp(v, 0.0, limits_.feed_override_max);
      }
      break;
    }
    case CommandKind::kRecordFlag:
      recording_ = c.a != 0.0;
      break;
    case CommandKind::kSetPosition:
      // SimBus::set_position only resets a plant state (no allocation); a CANopen bus would do it
      // with SDOs and must not be called here (its adapter refuses: returns false).
      if ((st != MachineState::kReady && st != MachineState::kDisabled) || program_.attached() ||
          jog_.active() || homing_.active() || c.axis < 0 || c.axis >= axes_ ||
          !bus_.set_position(c.axis, c.a - home_shift_mm_[static_cast<std::size_t>(c.axis)])) {
        refuse();
        break;
      }
      fb_.act_mm[c.axis] = c.a;
      hold_here();
      break;
    case CommandKind::kIdentify:
      if (st != MachineState::kReady || program_.attached() || jog_.active() || homing_.active() ||
          c.axis < 0 || c.axis >= axes_ ||
          ident_state_.load(std::memory_order_relaxed) == IdentifyState::kRunning) {
        refuse();
        break;
      }
      hold_here();
      ident_axis_ = c.axis;
      ident_k_ = 0;
      ident_state_.store(IdentifyState::kRunning, std::memory_order_relaxed);
      break;
    case CommandKind::kForce:
      if (!force_.configured()) {
        refuse();
        break;
      }
      if (force_.command(c.axis, c.a)) emit(EventKind::kForceOff);
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
  reset_block_ = supervisor_.reset_block(fb_, io_ != nullptr && io_->estop_tripped());
  // Soft PLC: refused while it still requests E-stop / fault / an axis fault or a latched engine
  // fault's cause remains.
  if (!reset_block_ && plc_ != nullptr && !plc_->causes_gone()) {
    reset_block_ = ResetBlock{FaultCause::kPlcFault, -1, 0};
  }
  const Transition t = sm_.reset(!reset_block_);
  if (!t.accepted) return false;
  if (plc_ != nullptr) plc_->reset();
  ++resets_;
  transition(t, FaultCause::kNone);
  force_.clear_fallback();
  fault_axis_ = -1;
  fault_value_ = fault_limit_ = 0.0;
  fault_detail_ = 0;
  fb_.missed_streak.fill(0);
  transition(sm_.apply(Request::kEnable), FaultCause::kNone);
  return true;
}

bool ServoLoop::all_axes_enabled() const noexcept {
  bool all = axes_ > 0;
  for (int i = 0; i < axes_; ++i) all = all && fb_.bus.axis[static_cast<std::size_t>(i)].enabled;
  return all;
}

const char* to_string(PlcAction a) noexcept {
  switch (a) {
    case PlcAction::kNone: return "none";
    case PlcAction::kEstop: return "estop_req";
    case PlcAction::kFault: return "fault_req";
    case PlcAction::kAxisFault: return "axis_fault";
    case PlcAction::kEngineFault: return "engine_fault";
    case PlcAction::kStop: return "stop_req";
    case PlcAction::kHold: return "feed_hold_req";
  }
  return "?";
}

// The `logic` stage: one soft PLC scan over this cycle's snapshot, then its requests, through the
// state machine like an operator's (never around it: the PLC cannot enable, reset or release).
void ServoLoop::logic() noexcept {
  if (plc_ == nullptr) return;
  const MachineState st = sm_.state();
  const control::InterpOutput& io = program_.output();
  PlcNcInput in;
  in.cycle = cycle_;
  in.state = st;
  in.program_running = in_program(st) && st == MachineState::kRunning;
  in.spindle_on = spindle_.target_rpm() != 0.0;
  in.spindle_at_speed = spindle_.at_speed();
  in.spindle_rpm = fb_.bus.spindle.present ? fb_.bus.spindle.actual_rpm : spindle_.target_rpm();
  in.coolant_mist = program_.attached() && io.mist;
  in.coolant_flood = program_.attached() && io.flood;
  in.axes = axes_;
  for (int i = 0; i < axes_; ++i) in.pos_mm[static_cast<std::size_t>(i)] = fb_.act_mm[i];
  in.tool = io.tool;
  in.estop_input = fb_.estop_input;
  in.drive_enable = pub_.out_drive_enable;  // last cycle's outputs (this cycle's come later)
  in.spindle_enable = pub_.out_spindle_enable;
  in.alive = true;
  // CiA 402 0x60FD: this cycle's snapshot (read stage). A value the bus did not refresh is held
  // while it is younger than the missed-TPDO streak the supervisor faults on, as the position
  // is; older, or never received, it is not valid and the PLC uses the signal's default.
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    in.homed[a] = homed_[a];  // NC.homed / NC.homed_<axis>
    in.drive_inputs[a] = fb_.bus.axis[a].digital_inputs;
    in.drive_inputs_valid[a] = fb_.bus.axis[a].digital_inputs_present &&
                               drive_inputs_age_[a] < drive_inputs_max_age_;
  }
  // CiA 401 modules: the same rule as 0x60FD (held below the missed-TPDO streak, then stale).
  for (int k = 0; k < fb_.bus.io_modules && k < static_cast<int>(kMaxIoModules); ++k) {
    const auto m = static_cast<std::size_t>(k);
    Cia401Inputs& c = cia401_in_[m];
    c.node_id = static_cast<std::uint8_t>(fb_.bus.io[m].node_id);
    c.valid = io_age_[m] < drive_inputs_max_age_;
    c.digital = fb_.bus.io[m].digital;
    c.analog = fb_.bus.io[m].analog;
  }
  in.cia401 = std::span<const Cia401Inputs>(
      cia401_in_.data(),
      static_cast<std::size_t>(std::clamp(fb_.bus.io_modules, 0, static_cast<int>(kMaxIoModules))));
  plc_->scan(in, plc_out_);
  const PlcRequests& rq = plc_out_.requests;
  plc_req_ = rq;

  auto note = [&](PlcAction a, int axis, std::int32_t code, PlcFaultKind k) {
    plc_cause_ = PlcStopCause{a, cycle_, axis, code, k};
  };
  if (plc_out_.fault) plc_engine_fault_ = plc_out_.fault;
  if (rq.estop) {
    if (st != MachineState::kEstop) {
      note(PlcAction::kEstop, -1, 0, PlcFaultKind::kNone);
      enter_estop(FaultCause::kPlcEstop);
    }
  } else if (st != MachineState::kFault && st != MachineState::kEstop) {
    if (plc_out_.fault) {
      // The fault's index is a coupler or a program, not an axis: the status and the log name
      // it from plc_cause_ / the event's detail (the engine fault's kind), never as "axis N".
      note(PlcAction::kEngineFault, plc_out_.fault.index, plc_out_.fault.code, plc_out_.fault.kind);
      raise_fault(FaultReport{FaultCause::kPlcFault, -1, plc_out_.fault.value, plc_out_.fault.limit,
                              static_cast<std::uint8_t>(plc_out_.fault.kind)});
    } else if (rq.fault) {
      note(PlcAction::kFault, -1, rq.fault_code, PlcFaultKind::kNone);
      raise_fault(FaultReport{FaultCause::kPlcFault, -1, static_cast<double>(rq.fault_code), 0.0});
    } else {
      for (int i = 0; i < axes_; ++i) {
        if (!rq.axis_fault[static_cast<std::size_t>(i)]) continue;
        note(PlcAction::kAxisFault, i, 0, PlcFaultKind::kNone);
        raise_fault(FaultReport{FaultCause::kPlcFault, i, 1.0, 0.0});
        break;
      }
    }
  }
  const MachineState now = sm_.state();
  if (rq.stop) {
    if ((now == MachineState::kRunning || now == MachineState::kHold) && program_.attached()) {
      note(PlcAction::kStop, -1, 0, PlcFaultKind::kNone);
      program_.request_stop();
      transition(sm_.apply(Request::kStop), FaultCause::kNone);
    } else if (jog_.active()) {
      jog_.brake(ref_[jog_.axis()], limits_.max_accel_mm_s2[static_cast<std::size_t>(jog_.axis())]);
    } else if (homing_.active()) {
      homing_.abort();
    }
  }
  if (rq.feed_hold && now == MachineState::kRunning) {
    note(PlcAction::kHold, -1, 0, PlcFaultKind::kNone);
    transition(sm_.apply(Request::kHold), FaultCause::kNone);
  }
}

// ---------------------------------------------------------------------------------------------
// The cycle

void ServoLoop::cycle() noexcept {
  take_staged();
  read();
  run_commands();
  if (const FaultReport e = supervisor_.check_estop(fb_)) enter_estop(e.cause);
  logic();
  const MachineState st = advance_state();
  // Judged after the ENABLING -> READY step: the cycle that reaches READY already commands the
  // drives enabled (judged before it, that cycle sent "disable voltage" and the drives dropped out
  // of operation enabled for ~8 cycles right after READY).
  const bool servo = st == MachineState::kReady || st == MachineState::kRunning ||
                     st == MachineState::kHold;
  const RefPoint r = reference(st, servo);
  identify_step(st);
  v_ref_ = (ref_ - ref_prev_) / period_s_;  // control, following error, a stop's start
  eps_norm_ = 0.0;
  AxisCommands out = control_step(r, st, servo, v_ref_, eps_norm_);
  channels(st, out);
  write(out);
  last_servo_ = servo;
  supervise(st, servo, v_ref_, eps_norm_);
  publish_cycle();
  ++cycle_;
}

void ServoLoop::take_staged() noexcept {
  if (staged_ready_.load(std::memory_order_acquire)) {
    ctrl_.set_gains(staged_params_);
    gains_generation_ = staged_generation_.load(std::memory_order_relaxed);
    gains_cycle_ = cycle_;
    staged_ready_.store(false, std::memory_order_release);
    emit(EventKind::kGainsSwapped, FaultCause::kNone, -1, static_cast<double>(gains_generation_));
    chatter_mon_.reset();  // judged afresh with the new gains
  }
  if (staged_limits_ready_.load(std::memory_order_acquire)) {
    limits_ = staged_limits_;
    limits_eff_dirty_ = true;
    // Overrides stay inside the new ranges (status shows what applies).
    feed_override_ = std::min(feed_override_, limits_.feed_override_max);
    rapid_override_ = std::min(rapid_override_, limits_.rapid_override_max);
    spindle_override_ =
        std::clamp(spindle_override_, limits_.spindle_override_min, limits_.spindle_override_max);
    limits_generation_ = staged_limits_generation_.load(std::memory_order_relaxed);
    staged_limits_ready_.store(false, std::memory_order_release);
    emit(EventKind::kLimitsSwapped, FaultCause::kNone, -1, static_cast<double>(limits_generation_));
  }
}

void ServoLoop::read() noexcept {
  bus_.begin_cycle();
  bus_.read(fb_.bus);
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (fb_.bus.axis[a].fresh) {
      fb_.act_mm[i] = fb_.bus.axis[a].position_mm + home_shift_mm_[a];
      fb_.missed_streak[a] = 0;
      v_est_[a] = fb_.bus.axis[a].velocity_mm_s;
    } else {
      ++fb_.missed_streak[a];
      ++missed_tpdos_;
      // The drive still follows the last command it got, through its velocity-loop lag.
      const double commanded = out_.mode == DriveMode::kEnabled ? out_.velocity_mm_s[a] : 0.0;
      v_est_[a] += (commanded - v_est_[a]) * lag_alpha_[a];
    }
    if (!std::isfinite(v_est_[a])) v_est_[a] = 0.0;
    if (fb_.bus.axis[a].digital_inputs_fresh) {
      drive_inputs_age_[a] = 0;
    } else if (drive_inputs_age_[a] < kDriveInputsNever) {
      ++drive_inputs_age_[a];
    }
    if (!fb_.bus.axis[a].digital_inputs_present || fb_.bus.axis[a].digital_inputs_fresh) {
      fb_.inputs_missed_streak[a] = 0;
    } else if (fb_.inputs_missed_streak[a] < kDriveInputsNever) {
      ++fb_.inputs_missed_streak[a];
    }
  }
  for (int k = 0; k < fb_.bus.io_modules && k < static_cast<int>(kMaxIoModules); ++k) {
    const auto m = static_cast<std::size_t>(k);
    if (fb_.bus.io[m].fresh) {
      io_age_[m] = 0;
    } else if (io_age_[m] < kDriveInputsNever) {
      ++io_age_[m];
    }
  }
  if (io_ != nullptr) {
    fb_.force = io_->read_force();
    fb_.force_xyz_N = fb_.force.sample.filtered_N;
    double sq = 0.0;
    for (std::size_t i = 0; i < 3; ++i) {
      if (fb_.force.sample.present[i]) sq += fb_.force_xyz_N[i] * fb_.force_xyz_N[i];
    }
    fb_.force_N = std::sqrt(sq);
    fb_.force_age_s = static_cast<double>(fb_.force.age_ns) * 1e-9;
    fb_.estop_input = io_->estop_tripped();
  }
}

void ServoLoop::run_commands() noexcept {
  if (reset_pending_cycles_ > 0) {
    --reset_pending_cycles_;
    const MachineState st = sm_.state();
    if (st != MachineState::kFault && st != MachineState::kEstop) {
      reset_pending_cycles_ = 0;
      ++reset_verdicts_;
    } else if (try_reset()) {
      reset_pending_cycles_ = 0;
      ++reset_verdicts_;
    } else if (reset_pending_cycles_ == 0) {
      refuse_command(CommandKind::kReset);  // the causes did not clear within the window
      ++reset_verdicts_;
    }
  }
  LoopCommand c;
  for (int n = 0; n < kMaxCommandsPerCycle && commands_.pop(c); ++n) apply_command(c);
}

MachineState ServoLoop::advance_state() noexcept {
  if (sm_.state() == MachineState::kEnabling && all_axes_enabled()) {
    hold_here();
    transition(sm_.apply(Request::kEnabled), FaultCause::kNone);
  }
  return sm_.state();
}

SourceKind ServoLoop::select_source(MachineState st) const noexcept {
  if (in_program(st)) return SourceKind::kProgram;
  if (jog_.active() && st == MachineState::kReady) return SourceKind::kJog;
  if (homing_.active() && st == MachineState::kReady) return SourceKind::kHoming;
  if (st == MachineState::kFault) return SourceKind::kStop;
  // `disable`: the drives are still on until the axes stand still.
  if (st == MachineState::kDisabled && !stop_.done()) return SourceKind::kStop;
  return SourceKind::kHold;
}

RefPoint ServoLoop::reference(MachineState st, bool servo) noexcept {
  ref_prev_ = ref_;
  program_.drain();  // READY too: the interpolator is pre-filled before `run`
  if (homing_.active() && st != MachineState::kReady) cancel_homing();
  if (limits_eff_dirty_) update_effective_limits();
  const SourceKind next = select_source(st);
  if (next != source_ && next == SourceKind::kHold) hold_.start(ref_);  // switch at the boundary
  source_ = next;
  RefPoint r;
  switch (next) {
    case SourceKind::kProgram: program_step(st, r); break;
    case SourceKind::kJog: r = jog_.step(ref_, limits_eff_, period_s_); break;
    case SourceKind::kHoming: r = homing_step(); break;
    case SourceKind::kHold: r = hold_.step(fb_, servo); break;
    case SourceKind::kStop:
      r = stop_.step(fb_, limits_, period_s_);
      if (stop_.timed_out()) {
        // The axes did not come to rest: the drives' own quick stop takes over (a second cause
        // while FAULT keeps the first; counted and logged with the axis still moving).
        ++fault_counts_[static_cast<std::size_t>(FaultCause::kStandstillTimeout)];
        emit(EventKind::kStandstillTimeout, FaultCause::kStandstillTimeout, stop_.moving_axis(),
             stop_.moving_speed_mm_s(), limits_.standstill_timeout_s);
      }
      break;
  }
  ref_ = r.position_mm;
  return r;
}

void ServoLoop::program_step(MachineState st, RefPoint& r) noexcept {
  ProgramSource::Inputs in;
  in.running = st == MachineState::kRunning;
  // The force controller's override (channels stage of the previous cycle) scales the user's.
  in.override_ratio = feed_override_ * force_.feed_override();
  in.rapid_override_ratio = rapid_override_;  // no cutting on a rapid: neither feed nor force
  in.spindle_override = spindle_override_;
  in.optional_stop = optional_stop_;
  in.single_block = single_block_;
  using Wait = config::SpindleConfig::Wait;
  const Wait policy = cfg_.spindle.at_speed_wait;
  in.wait_for_spindle = spindle_.present() && (policy == Wait::kAlways ||
                                               (policy == Wait::kForce && force_.requested()));
  in.spindle_at_speed = spindle_.at_speed();
  in.spindle_target_rpm = spindle_.target_rpm();
  ProgramStep s;
  r = program_.step(in, s);
  if (s.underrun_begin) {
    emit(EventKind::kUnderrun, FaultCause::kQueueUnderrun, -1, program_.output().path_progress_mm);
  }
  if (s.underrun_end) emit(EventKind::kUnderrunEnd);
  if (s.planner_failed) transition(sm_.apply(Request::kStop), FaultCause::kNone);
  if (s.program_hold && !logic_takes_hold()) {  // M0/M1/M6 for the operator
    const control::InterpOutput& o = program_.output();
    emit(EventKind::kProgramPause, FaultCause::kNone, o.message_id);
    transition(sm_.apply(Request::kHold), FaultCause::kNone);
  }
  if (s.spindle_at_speed) {
    emit(EventKind::kSpindleAtSpeed, FaultCause::kNone, -1, program_.last_wait_s(),
         fb_.bus.spindle.actual_rpm);
  }
  if (s.spindle_waiting) {
    if (const FaultReport f = supervisor_.check_spindle_wait(
            program_.waited_cycles(), fb_.bus.spindle.actual_rpm, program_.wait_target_rpm())) {
      program_.cancel_spindle_wait();
      raise_fault(f);
    }
  }
  if (s.stopped) {
    detach_job(false);
    transition(sm_.apply(Request::kStopped), FaultCause::kNone);
  }
}

// Issue 20: M6 and the user M-codes M100..M199 reach the loop as hold markers (the path has
// stopped exactly). Where the machine logic runs them (plc.tool_change / plc.mcodes), the program
// stays RUNNING while the PLC's sequence runs: the request goes up with the tool / M number and
// P, Q; the PLC's done signal resumes the path; no done within the configured timeout is a PLC
// fault the engine latches (the logic stage then faults the machine). A user M-code no PLC
// program handles passes at once (an exact stop, as before). True: the hold is taken here.
bool ServoLoop::logic_takes_hold() noexcept {
  const control::InterpOutput& o = program_.output();
  using control::SegmentKind;
  if (o.hold_kind == SegmentKind::kUserMcode) {
    if (plc_ == nullptr || !plc_->handles_mcode(o.user_m)) {
      program_.resume();
      return true;
    }
    switch (plc_->mcode_state()) {
      case Handshake::kIdle: plc_->start_mcode(o.user_m, o.user_p, o.user_q); break;
      case Handshake::kDone:
        plc_->release_mcode();
        program_.resume();
        break;
      case Handshake::kTimedOut: plc_->release_mcode(); break;  // the engine's fault stops us
      case Handshake::kPending:
      case Handshake::kWaiting: break;
    }
    return true;
  }
  if (o.hold_kind == SegmentKind::kToolChange && plc_ != nullptr && plc_->handles_tool_change()) {
    switch (plc_->tool_change_state()) {
      case Handshake::kIdle: plc_->start_tool_change(o.hold_tool); break;
      case Handshake::kDone:
        plc_->release_tool_change();
        program_.resume();
        break;
      case Handshake::kTimedOut: plc_->release_tool_change(); break;
      case Handshake::kPending:
      case Handshake::kWaiting: break;
    }
    return true;
  }
  return false;
}

AxisCommands ServoLoop::control_step(const RefPoint& r, MachineState st, bool servo,
                                     const Eigen::Vector3d& v_ref, double& eps_norm) noexcept {
  AxisCommands out;
  out.mode = DriveMode::kDisabled;
  if (servo) {
    const control::Vec3 p_hat = ctrl_.predict(fb_.act_mm);
    model_.push_reference(ref_);
    control::ContourErrorResult ce = model_.update(p_hat);
    if (r.source == SourceKind::kHoming) {
      // Homing moves each axis on its own (LinuxCNC homes joints): there is no contour to hold,
      // and the cross-coupling would push one axis with the other's lag (a stop of the diagonal
      // final move made the soft Table 1 loop ring into a following-error fault). The axis
      // controllers alone track the homing reference.
      ce.eps.setZero();
      if (homing_.drive_group()) {
        // An axis homed by its drive moves without the loop's command, so its drive model (the
        // Smith predictor, the derivative's model blend) is off by the whole travel until the
        // shift restarts the controllers. The coupling derivative differences positions on the
        // path's geometry, which mixes the axes: that error reached the other axis of the group
        // and made its switch search ring into a following-error fault (Y, 1.5 mm, on the sim
        // machine). A point geometry at P_hat keeps every axis to its own terms.
        const control::Vec3 k = p_hat;
        ce = control::ContourErrorResult{};
        ce.k_point = k;
        ce.branch = control::ContourBranch::kPoint;
        ce.lag_points = 1 << 20;
      }
    }
    eps_ = ce.eps;
    eps_norm = ce.eps.norm();
    control::Vec3 u = control::Vec3::Zero();
    ctrl_.update(ref_, p_hat, ce, v_ref, u);
    clamped_.fill(false);
    for (int i = 0; i < axes_; ++i) {
      const auto a = static_cast<std::size_t>(i);
      if (r.source == SourceKind::kHoming && homing_.drive_moves(i)) {
        // The drive homes itself (mode 6 ignores the velocity target): command rest, so that the
        // drive stands when the bus returns it to the cyclic mode, and the clamps, the chatter
        // watchdog and the missed-TPDO model see no command the loop did not mean.
        v_cmd_[a] = 0.0;
        continue;
      }
      double v = gain_per_s_[a] * u[i];
      if (!std::isfinite(v)) v = 0.0;
      const double vmax = limits_.max_velocity_mm_s[a];
      if (std::abs(v) > vmax) {
        v = std::copysign(vmax, v);
        ++clamps_;
        clamped_[a] = true;
      }
      // Acceleration clamp. A velocity-mode drive follows its target with the lag tau of its
      // velocity loop, so the acceleration it will produce is (v_target - v_actual) / tau: the
      // target is kept within v_actual +- a_max * tau. Why not |v(k) - v(k-1)| <= a_max T on the
      // target: the coupling controller's derivative term makes the target step by ~18 mm/s per
      // 0.5 um encoder count (Cd K BLU / T), which the drive's lag filters; a per-cycle rate
      // limit at 2000 mm/s^2 turned that into phase lag and made the Table 2 run unstable
      // (contour error 1.1 mm, FAULT). Like the velocity clamp it is a last-line limit the
      // controller is not told about; it does not engage on Table 2 (status accel_clamps).
      // Whatever the feedback's freshness (issue 16: with stale feedback the clamp was skipped and
      // X got its velocity limit for 2 cycles): a stale axis is clamped around the drive-model
      // estimate of its velocity.
      if (tau_s_[a] > 0.0) {
        const double dv = limits_.max_accel_mm_s2[a] * tau_s_[a];
        const double va = v_est_[a];
        if (v > va + dv || v < va - dv) {
          v = std::clamp(v, va - dv, va + dv);
          ++accel_clamps_;
          clamped_[a] = true;
        }
      }
      v_cmd_[a] = v;
    }
    out.mode = DriveMode::kEnabled;
  } else if (r.source == SourceKind::kStop) {
    // Controlled stop (StopSource): the ramped velocity, zero until standstill, then the drives
    // disabled (or, after the standstill timeout, their quick stop).
    v_cmd_ = r.velocity_mm_s;
    out.mode = r.quick_stop ? DriveMode::kQuickStop
               : r.drives_on ? DriveMode::kEnabled
                             : DriveMode::kDisabled;
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
  if (servo && ident_state_.load(std::memory_order_relaxed) == IdentifyState::kRunning) {
    // Identification: the axis under test gets the excitation, open loop; sample k = the
    // position read and the target written in this cycle (control/system_identification.hpp).
    const auto a = static_cast<std::size_t>(ident_axis_);
    v_cmd_[a] = ident_exc_[ident_k_];
    ident_v_[ident_k_] = v_cmd_[a];
    ident_x_[ident_k_] = fb_.act_mm[ident_axis_];
    clamped_[a] = false;
    if (++ident_k_ == ident_exc_.size()) {
      ++ident_seq_;
      ident_state_.store(IdentifyState::kDone, std::memory_order_release);
    }
  }
  for (int i = 0; i < axes_; ++i) out.velocity_mm_s[static_cast<std::size_t>(i)] = v_cmd_[static_cast<std::size_t>(i)];
  return out;
}

// Identification, reference side: the axis under test is not servoed (its reference follows
// the position it has, so neither the controller nor the following-error rule fights the
// excitation); the others hold. The experiment ends (aborted) when the machine leaves READY or a
// program/jog starts; once done the axis holds where it stands.
void ServoLoop::identify_step(MachineState st) noexcept {
  const IdentifyState is = ident_state_.load(std::memory_order_relaxed);
  if (is == IdentifyState::kDone && ident_k_ == ident_exc_.size()) {
    ident_k_ = 0;  // first cycle after the last sample: hold here (controller restarted)
    hold_here();
    return;
  }
  if (is != IdentifyState::kRunning) return;
  if (st != MachineState::kReady || program_.attached() || jog_.active()) {
    ++ident_seq_;
    ident_state_.store(IdentifyState::kAborted, std::memory_order_release);
    hold_here();
    return;
  }
  ref_[ident_axis_] = fb_.act_mm[ident_axis_];
}

bool ServoLoop::identify_record(int& axis, std::vector<double>& v_cmd_mm_s,
                                std::vector<double>& position_mm) const {
  if (ident_state_.load(std::memory_order_acquire) != IdentifyState::kDone) return false;
  axis = ident_axis_;
  v_cmd_mm_s = ident_v_;
  position_mm = ident_x_;
  return true;
}

const char* to_string(IdentifyState s) noexcept {
  switch (s) {
    case IdentifyState::kIdle: return "idle";
    case IdentifyState::kRunning: return "running";
    case IdentifyState::kDone: return "done";
    case IdentifyState::kAborted: return "aborted";
  }
  return "?";
}

void ServoLoop::channels(MachineState st, AxisCommands& out) noexcept {
  ForceChannel::Inputs fi;
  fi.in_program = in_program(st);
  fi.running = fi.in_program && st == MachineState::kRunning && !program_.stopping() &&
               !program_.spindle_waiting();
  fi.programmed_rpm = program_.programmed_spindle_rpm();
  fi.feed_override = feed_override_;
  fi.progress_mm = program_.output().path_progress_mm;
  const ForceChannel::Events ev = force_.step(fi, fb_, period_s_);
  const control::ForceLimits& lim = force_.limits();
  if (ev.on) emit(EventKind::kForceOn, FaultCause::kNone, -1, force_.reference_N());
  if (ev.off) emit(EventKind::kForceOff);
  if (ev.fallback) {
    emit(EventKind::kForceFallback, FaultCause::kForceStale, static_cast<int>(force_.status()),
         fb_.force_age_s, lim.stale_age_s);
    if (const FaultReport f = supervisor_.check_force_stale(true, fb_.force_age_s, lim.stale_age_s)) {
      raise_fault(f);
    }
  }
  if (ev.ceiling) {
    emit(EventKind::kForceCeiling, FaultCause::kForceCeiling, -1, fb_.force_N, lim.force_ceiling_N);
  }
  if (ev.recovered) emit(EventKind::kForceRecovered);
  if (force_.configured() && io_ != nullptr) io_->set_spindle_rpm(std::abs(force_.spindle_rpm_cmd()));
  // Soft PLC: NC.spindle_inhibit holds the spindle at 0 (the ramp brings it down).
  const double rpm_req = plc_req_.spindle_inhibit ? 0.0 : force_.spindle_rpm_cmd();
  const double rpm = spindle_.step(rpm_req, out.mode, fb_.bus.spindle, io_, period_s_);
  out.spindle_rpm = out.mode == DriveMode::kEnabled ? rpm : 0.0;
}

void ServoLoop::write(const AxisCommands& out) noexcept {
  out_ = out;
  for (int i = 0; i < axes_; ++i) {
    out_.index_arm[static_cast<std::size_t>(i)] = homing_.index_armed(i);
    out_.drive_home[static_cast<std::size_t>(i)] = homing_.drive_home_request(i);
  }
  // The PLC's CiA 402 outputs (0x60FE:01), computed in this cycle's scan, written with the
  // commands: the field sees the scan's end value only.
  if (plc_ != nullptr) {
    out_.digital_outputs = plc_out_.drive_outputs;
    out_.digital_output_mask = plc_out_.drive_output_mask;
    // CiA 401 outputs (0x6200, 0x6411), matched by node-id in the bus.
    for (std::size_t k = 0; k < kMaxIoModules; ++k) {
      IoModuleCommands& c = out_.io[k];
      if (k < plc_out_.cia401_count && k < kMaxCia401Nodes) {
        c.node_id = plc_out_.cia401[k].node_id;
        c.digital = plc_out_.cia401[k].digital;
        c.analog = plc_out_.cia401[k].analog;
      } else {
        c.node_id = 0;
      }
    }
  }
  bus_.write(out_);
}

void ServoLoop::supervise(MachineState st, bool servo, const Eigen::Vector3d& v_ref,
                          double eps_norm) noexcept {
  if (st != MachineState::kDisabled && st != MachineState::kFault && st != MachineState::kEstop) {
    if (const FaultReport f = supervisor_.check_bus(fb_, servo)) raise_fault(f);
  }
  if (servo && sm_.state() != MachineState::kFault) {
    if (const FaultReport f = supervisor_.check_motion(ref_, fb_.act_mm, v_ref, eps_norm, limits_eff_)) {
      raise_fault(f);
    }
  }
  watch_chatter(servo);
  // Program end: once the reference has stopped, wait for the tool to arrive (in position).
  if (program_.settling() && program_.attached() && sm_.state() == MachineState::kRunning &&
      program_.settled(ref_, fb_.act_mm, axes_)) {
    detach_job(true);
    transition(sm_.apply(Request::kDone), FaultCause::kNone);
  }
}

// Issue 16: a limit cycle or chattering command while the axes servo (READY, RUNNING, HOLD) is
// first a warning event, then a FAULT (controlled stop) naming the axis and the figure
// (control::ChatterMonitor; thresholds safety.chatter). Outside servo the watchdog starts afresh.
// Also accumulates the running program's chatter figure (status, `result`). RT: no allocation.
void ServoLoop::watch_chatter(bool servo) noexcept {
  if (program_.attached()) {
    const std::uint64_t id = program_.job()->id;
    if (id != job_chatter_id_) {
      job_chatter_id_ = id;
      job_chatter_.reset(axes_);
    }
    job_chatter_.add(v_cmd_);
  }
  if (!servo || !chatter_enabled_ || sm_.state() == MachineState::kFault ||
      sm_.state() == MachineState::kEstop) {
    if (chatter_armed_) chatter_mon_.reset();
    chatter_armed_ = false;
    return;
  }
  chatter_armed_ = true;
  const control::ChatterReport rep = chatter_mon_.update(v_cmd_, clamped_);
  if (!rep.raised) return;
  const auto detail = static_cast<std::uint8_t>(rep.figure);
  if (rep.level == control::ChatterLevel::kFault) {
    FaultReport f;
    f.cause = FaultCause::kLimitCycle;
    f.axis = rep.axis;
    f.value = rep.value;
    f.limit = rep.limit;
    f.detail = detail;
    raise_fault(f);
  } else if (rep.level == control::ChatterLevel::kWarning) {
    emit(EventKind::kLimitCycleWarning, FaultCause::kLimitCycle, rep.axis, rep.value, rep.limit, detail);
  }
}

void ServoLoop::publish_cycle() noexcept {
  // Every `decimation`-th cycle, from cycle 0 (a countdown: no division per cycle).
  const bool sample = telemetry_phase_ == 0;
  if (++telemetry_phase_ >= std::max(1, cfg_.telemetry.decimation)) telemetry_phase_ = 0;
  if (sample) {
    const control::InterpOutput& io = program_.output();
    TelemetrySample s;
    s.cycle = cycle_;
    s.t_s = static_cast<double>(cycle_) * period_s_;
    s.job = program_.attached() ? program_.job()->id : 0;
    for (std::size_t i = 0; i < 3; ++i) {
      s.ref_mm[i] = ref_[static_cast<Eigen::Index>(i)];
      s.act_mm[i] = fb_.act_mm[static_cast<Eigen::Index>(i)];
      s.eps_mm[i] = eps_[static_cast<Eigen::Index>(i)];
      s.cmd_mm_s[i] = v_cmd_[i];
    }
    s.progress_mm = io.path_progress_mm;
    s.override_applied = io.override_applied;
    s.line = io.line;
    s.state = sm_.state();
    s.recording = recording_;
    s.in_program = in_program(s.state);
    s.force_N = fb_.force_N;
    s.force_override = force_.feed_override();
    s.spindle_rpm = force_.spindle_rpm_cmd();
    s.lateness_us = lateness_us_;
    telemetry_.push(s);
  }
  publish();
}

void ServoLoop::publish() noexcept {
  const control::InterpOutput& io = program_.output();
  const std::uint64_t s0 = seq_.load(std::memory_order_relaxed);
  seq_.store(s0 + 1, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  pub_.cycle = cycle_;
  pub_.state = sm_.state();
  pub_.source = source_;
  pub_.cause = sm_.cause();
  pub_.fault_axis = fault_axis_;
  pub_.fault_value = fault_value_;
  pub_.fault_limit = fault_limit_;
  pub_.fault_detail = fault_detail_;
  for (std::size_t i = 0; i < 3; ++i) {
    pub_.ref_mm[i] = ref_[static_cast<Eigen::Index>(i)];
    pub_.act_mm[i] = fb_.act_mm[static_cast<Eigen::Index>(i)];
    pub_.cmd_mm_s[i] = v_cmd_[i];
  }
  pub_.eps_norm_mm = eps_norm_;
  pub_.progress_mm = io.path_progress_mm;
  pub_.line = io.line;
  pub_.override_applied = io.override_applied;
  pub_.feed_override = feed_override_;
  pub_.rapid_override = rapid_override_;
  pub_.spindle_override = spindle_override_;
  pub_.on_rapid = io.rapid;
  pub_.optional_stop = optional_stop_;
  pub_.single_block = single_block_;
  pub_.attached_job = program_.attached() ? program_.job()->id : 0;
  pub_.finished_job = finished_job_;
  pub_.finished_ok = finished_ok_;
  pub_.finished_cycle = finished_cycle_;
  pub_.released_job = released_job_;
  pub_.underruns = program_.underruns();
  pub_.missed_tpdos = missed_tpdos_;
  pub_.velocity_clamps = clamps_;
  pub_.gains_generation = gains_generation_;
  pub_.gains_cycle = gains_cycle_;
  pub_.jogging = jog_.active();
  pub_.homing = homing_.active();
  pub_.homing_runs = homing_runs_;
  pub_.homing_failure = homing_failure_;
  pub_.homing_failure_axis = homing_failure_axis_;
  pub_.homing_failure_value = homing_failure_value_;
  pub_.homed_mask = 0;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (homed_[a]) pub_.homed_mask |= 1u << i;
    pub_.home_phase[a] = static_cast<std::uint8_t>(homing_.phase(i));
    pub_.home_shift_mm[a] = home_shift_mm_[a];
  }
  // An M6 / M1xx the machine logic runs is not the operator's pause (status shows the PLC's
  // handshake under `plc status`).
  pub_.interp_holding = io.status == control::InterpStatus::kHolding &&
                        io.hold_kind != control::SegmentKind::kUserMcode &&
                        !(io.hold_kind == control::SegmentKind::kToolChange && plc_ != nullptr &&
                          plc_->handles_tool_change());
  pub_.hold_single_block = pub_.interp_holding && io.single_block_stop;
  pub_.hold_line = pub_.interp_holding ? io.line : 0;
  pub_.hold_tool = pub_.interp_holding ? io.tool : 0;
  pub_.hold_message_id = pub_.interp_holding ? io.message_id : -1;
  pub_.recording = recording_;
  pub_.drives_enabled = all_axes_enabled();
  pub_.accel_clamps = accel_clamps_;
  // The watchdog's window and level change only while it is armed; once more in the cycle after
  // it disarms (its reset: an empty window, level OK), then they stand (issue 15: the cycle's cost).
  if (chatter_armed_ || chatter_published_armed_) {
    std::uint8_t lvl = 0;
    pub_.chatter_window_sums = chatter_mon_.window_sums();
    for (int i = 0; i < axes_; ++i) {
      lvl = std::max(lvl, static_cast<std::uint8_t>(chatter_mon_.level(i)));
    }
    pub_.chatter_level = lvl;
    chatter_published_armed_ = chatter_armed_;
  }
  {
    pub_.chatter_job = job_chatter_id_;
    pub_.job_chatter_meter = job_chatter_;
  }
  pub_.limits_generation = limits_generation_;
  pub_.force_available = force_.configured();
  pub_.force_state = fb_.force.state;
  pub_.force_xyz_N = fb_.force_xyz_N;
  pub_.force_N = fb_.force_N;
  pub_.force_age_s = fb_.force_age_s;
  pub_.force_seq = fb_.force.sample.seq;
  pub_.force_requested = force_.requested();
  pub_.force_active = force_.active();
  pub_.force_status = force_.status();
  pub_.force_ref_N = force_.reference_N();
  pub_.force_override = force_.feed_override();
  pub_.force_fallback = force_.fallback();
  pub_.force_fallbacks = force_.fallbacks();
  pub_.spindle_rpm_cmd = out_.spindle_rpm;
  pub_.fault_counts = fault_counts_;
  pub_.resets = resets_;
  pub_.emcy_frames = fb_.bus.emcy_count;
  pub_.spindle_present = spindle_.present();
  pub_.spindle_feedback = fb_.bus.spindle.present;
  pub_.spindle_target_rpm = spindle_.target_rpm();
  pub_.spindle_actual_rpm = fb_.bus.spindle.actual_rpm;
  pub_.spindle_at_speed = spindle_.at_speed();
  pub_.spindle_waiting = program_.spindle_waiting();
  pub_.spindle_waits = program_.spindle_waits();
  pub_.spindle_last_wait_s = program_.last_wait_s();
  pub_.out_drive_enable = out_.mode == DriveMode::kEnabled && sm_.state() != MachineState::kEstop;
  // On while a speed is requested (M3/M4 with S): M5 drops it at once, the drive decelerates
  // (the rate-limited command ramps down with it).
  pub_.out_spindle_enable = out_.mode == DriveMode::kEnabled && spindle_.target_rpm() != 0.0;
  const bool attached = program_.attached();
  // With the soft PLC the coolant lines are its outputs (M7/M8/M9 unless a program owns them).
  const bool mist = plc_ != nullptr ? plc_out_.coolant_mist : attached && io.mist;
  const bool flood = plc_ != nullptr ? plc_out_.coolant_flood : attached && io.flood;
  pub_.out_mist = mist && sm_.state() != MachineState::kEstop;
  pub_.out_flood = flood && sm_.state() != MachineState::kEstop;
  pub_.estop_input = fb_.estop_input;
  pub_.stop_phase = stop_.phase();
  pub_.reset_block = reset_block_;
  pub_.reset_verdicts = reset_verdicts_;
  pub_.reset_pending = reset_pending_cycles_ > 0;
  pub_.soft_min_mm = limits_.min_mm;
  pub_.soft_max_mm = limits_.max_mm;
  pub_.plc_present = plc_ != nullptr;
  pub_.plc_requests = plc_req_;
  pub_.plc_engine_fault = plc_engine_fault_;
  pub_.plc_cause = plc_cause_;
  pub_.identify_state = ident_state_.load(std::memory_order_relaxed);
  pub_.identify_axis = ident_axis_;
  pub_.identify_seq = ident_seq_;
  pub_.identify_samples = ident_state_.load(std::memory_order_relaxed) == IdentifyState::kRunning
                              ? ident_k_
                              : ident_exc_.size();
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
    if (seq_.load(std::memory_order_relaxed) == s0) break;
  }
  control::window_figures(out.chatter_window_sums, out.chatter_window_mm_s,
                          out.chatter_window_clamps_per_s);
  const control::ChatterFigure jf = out.job_chatter_meter.figure();
  out.job_chatter_rms_mm_s = jf.rms_mm_s;
  out.job_chatter_max_mm_s = jf.max_mm_s;
  return out;
}

void ServoLoop::run(const std::atomic<bool>& stop) noexcept {
  CycleClock clock(static_cast<std::int64_t>(cfg_.loop.period_us) * 1000);
  clock.start();
  while (!stop.load(std::memory_order_acquire)) {
    const std::int64_t wake = clock.wait_next(stats_);
    lateness_us_ = static_cast<float>(static_cast<double>(wake - clock.deadline_ns()) * 1e-3);
    cycle();
    clock.end_cycle(stats_, wake);
  }
}

}  // namespace contour::daemon
