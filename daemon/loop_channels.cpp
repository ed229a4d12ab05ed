#include "daemon/loop_channels.hpp"

#include <algorithm>
#include <cmath>

namespace contour::daemon {

// ---------------------------------------------------------------------------------------------
// ForceChannel

ForceChannel::ForceChannel(const config::Config& cfg, bool configured)
    : configured_(configured),
      lim_(cfg.force.limits),
      k_v_mm_s_(cfg.force.design.plant.k_v_mm_s),
      ref_N_(cfg.force.reference_N) {
  // Configured whenever there is a force source (force control can then be switched on by
  // command even when force.enable is false at start-up). The design uses the loop period.
  if (configured_) {
    control::ForceDesignParams dp = cfg.force.design;
    dp.period_s = cfg.machine.period_s;
    force_.configure(control::design_force_2dof(dp), cfg.force.limits);
    requested_ = cfg.force.enable;
  }
}

bool ForceChannel::command(int on, double reference_N) noexcept {
  if (std::isfinite(reference_N)) ref_N_ = reference_N;
  bool off_event = false;
  if (on == 1) {
    requested_ = true;
    fallback_ = false;  // `force on` clears a latched fallback (ForceController::enable)
  } else if (on == 0) {
    requested_ = false;
    fallback_ = false;
    off_event = force_.active();
    force_.disable();
  }
  return off_event;
}

ForceChannel::Events ForceChannel::step(const Inputs& in, const Feedback& fb, double period_s) noexcept {
  Events ev;
  const double programmed_rpm = in.in_program ? in.programmed_rpm : 0.0;
  if (!configured_) {
    override_ = 1.0;
    spindle_rpm_cmd_ = programmed_rpm;
    return ev;
  }
  // Planned progress (the position reference of the 2-DOF controller): a ramp at the design's
  // path speed k_v (force.plant.k_v_mm_s, speed at 100 % override) times the user's override.
  // The design assumes the program's feed equals k_v; another feed is a model gain error in the
  // position channel (seed 001 §3: the controller is designed for one operating point).
  if (in.running) planned_progress_mm_ += k_v_mm_s_ * in.feed_override * period_s;
  if (requested_ && !fallback_ && in.running && !force_.active()) {
    // Engage bumplessly from the current state (an invalid sample latches the fallback at once).
    planned_progress_mm_ = in.progress_mm;
    const double rpm0 = spindle_rpm_cmd_ != 0.0 ? std::abs(spindle_rpm_cmd_) : lim_.spindle_nominal_rpm;
    force_.enable({override_, rpm0, fb.force_N, in.progress_mm});
    ev.on = true;
  }
  if (!in.running && force_.active()) {
    // Program ended, HOLD or stopping: the path does not follow the override, so the controller
    // would wind up against a standing tool. Off now, re-engaged bumplessly on resume / the next
    // run (requested_ stays).
    force_.disable();
    ev.off = true;
  }
  const bool ok = fb.force.state == drivers::modbus::ForceState::kOk;
  control::ForceInput fin;
  fin.force_ref_N = ref_N_;
  fin.planned_progress_mm = planned_progress_mm_;
  fin.force_N = fb.force_N;
  fin.progress_mm = in.progress_mm;
  fin.force_valid = ok;
  fin.force_age_s = fb.force_age_s;
  const control::ForceStatus prev = fout_.status;
  fout_ = force_.step(fin);
  const bool stale_now = fout_.status == control::ForceStatus::kStaleHold ||
                         fout_.status == control::ForceStatus::kStaleProgrammed;
  if (stale_now && !fallback_ && requested_) {
    fallback_ = true;
    ++fallbacks_;
    ev.fallback = true;
  }
  if (fout_.status == control::ForceStatus::kCeilingHold && prev != control::ForceStatus::kCeilingHold) {
    ev.ceiling = true;
  }
  if (fallback_ && ok && !ok_prev_) ev.recovered = true;
  ok_prev_ = ok;
  const bool controlling = force_.active() || fout_.status == control::ForceStatus::kStaleHold ||
                           fout_.status == control::ForceStatus::kCeilingHold;
  if (requested_) {
    override_ = fout_.feed_override;
  } else {
    // Off: back to the programmed feed at the override rate limit (no step in the path speed).
    const double d = lim_.override_rate_per_s * period_s;
    override_ = std::clamp(1.0, override_ - d, override_ + d);
  }
  spindle_rpm_cmd_ = (requested_ && controlling && in.in_program)
                         ? std::copysign(fout_.spindle_rpm, programmed_rpm != 0.0 ? programmed_rpm : 1.0)
                         : programmed_rpm;
  return ev;
}

// ---------------------------------------------------------------------------------------------
// SpindleChannel

double SpindleChannel::step(double rpm_cmd, DriveMode mode, SpindleFeedback& fb, RtIo* io,
                            double period_s) noexcept {
  if (!present_) {  // no spindle: the programmed speed is only information (filter, GPIO)
    target_rpm_ = out_rpm_ = rpm_cmd;
    at_speed_ = false;
    return out_rpm_;
  }
  target_rpm_ = drivers::clamp_spindle_rpm(rpm_cmd, limits_);
  if (mode == DriveMode::kEnabled) {
    out_rpm_ = ramp_.step(target_rpm_, period_s);
  } else {
    ramp_.reset(0.0);  // the drive is off: a restart ramps up from standstill
    out_rpm_ = 0.0;
  }
  // A VFD spindle (RtIo): it gets the same rate-limited command and reports its speed; the loop
  // judges at-speed on the same rule as for a bus spindle.
  if (io != nullptr && io->has_spindle()) {
    io->command_spindle(out_rpm_);
    const drivers::SpindleStatus s = io->spindle_status();
    fb.present = true;
    fb.fresh = s.comm_ok;
    fb.actual_rpm = s.actual_rpm;
    fb.enabled = s.comm_ok;
    fb.fault = s.fault == drivers::SpindleFault::kDrive;
  }
  // At speed: the ramp has arrived and the spindle follows (with feedback), or the ramp alone
  // (a spindle without speed feedback).
  const bool ramp_done = out_rpm_ == target_rpm_;
  if (fb.present) {
    at_speed_ = ramp_done && mode == DriveMode::kEnabled && fb.enabled &&
                drivers::spindle_at_speed(fb.actual_rpm, target_rpm_, limits_);
  } else {
    at_speed_ = ramp_done && mode == DriveMode::kEnabled;
  }
  return out_rpm_;
}

}  // namespace contour::daemon
