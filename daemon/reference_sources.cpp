#include "daemon/reference_sources.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace contour::daemon {

const char* to_string(SourceKind k) noexcept {
  switch (k) {
    case SourceKind::kProgram: return "program";
    case SourceKind::kJog: return "jog";
    case SourceKind::kHold: return "hold";
    case SourceKind::kStop: return "stop";
    case SourceKind::kHoming: return "homing";
  }
  return "?";
}

// ---------------------------------------------------------------------------------------------
// ProgramSource

void ProgramSource::attach(ProgramJob* job) noexcept {
  job_ = job;
  settling_ = stopping_ = underrun_ = false;
}

ProgramJob* ProgramSource::detach(bool ok) noexcept {
  ProgramJob* j = job_;
  if (j == nullptr) return nullptr;
  if (!ok) j->abort.store(true, std::memory_order_release);
  job_ = nullptr;
  stopping_ = false;
  settling_ = false;
  underrun_ = false;
  return j;
}

void ProgramSource::start() noexcept { iout_ = control::InterpOutput{}; }

void ProgramSource::request_stop() noexcept {
  if (job_ == nullptr) return;
  stopping_ = true;
  job_->abort.store(true, std::memory_order_release);
}

void ProgramSource::resume() noexcept {
  if (job_ != nullptr) job_->interp.resume();
}

void ProgramSource::drain() noexcept {
  if (job_ == nullptr) return;
  for (int n = 0; n < kMaxSegmentsPerCycle && job_->interp.free_slots() > 0 && job_->queue.pop(rec_);
       ++n) {
    from_record(rec_, seg_);
    job_->interp.push(seg_);
  }
}

double ProgramSource::programmed_spindle_rpm() const noexcept {
  switch (iout_.spindle) {
    case control::SpindleDir::kCw: return iout_.spindle_rpm * spindle_override_;
    case control::SpindleDir::kCcw: return -iout_.spindle_rpm * spindle_override_;
    case control::SpindleDir::kOff: break;
  }
  return 0.0;
}

RefPoint ProgramSource::step(const Inputs& in, ProgramStep& out) noexcept {
  using control::InterpStatus;
  out = ProgramStep{};
  // HOLD and stop decelerate along the path: the interpolator ramps its override to 0.
  const bool moving = in.running && !stopping_;
  job_->interp.set_optional_stop(in.optional_stop);
  job_->interp.set_single_block(in.single_block);
  spindle_override_ = in.spindle_override;  // clamped to its live range by the loop's command stage
  const InterpStatus ist = job_->interp.step(moving ? in.override_ratio : 0.0,
                                             moving ? in.rapid_override_ratio : 0.0, iout_);
  out.status = ist;
  RefPoint r;
  r.source = SourceKind::kProgram;
  r.position_mm = iout_.position_mm;
  r.track = true;
  r.drives_on = true;

  const bool planner_done = job_->planner_done.load(std::memory_order_acquire);
  if (ist == InterpStatus::kStarved && !planner_done) {
    if (!underrun_) {
      underrun_ = true;
      ++underruns_;
      out.underrun_begin = true;
    }
  } else if (underrun_ && ist == InterpStatus::kRunning) {
    underrun_ = false;
    out.underrun_end = true;
  }
  if (job_->planner_failed.load(std::memory_order_acquire) && !stopping_) {
    stopping_ = true;
    out.planner_failed = true;
  }
  // M0/M1/M6, a single-block stop
  if (ist == InterpStatus::kHolding && in.running) out.program_hold = true;

  // A feed move after a spindle start / speed change (the planner's kSpindleSync marker): the
  // path waits at its exact stop while the marker's speed is commanded until the spindle is at
  // speed; the supervisor ends a wait that lasts too long (check_spindle_wait).
  const bool was_waiting = spindle_waiting_;
  spindle_waiting_ = false;
  if (ist == InterpStatus::kSpindleWait && !stopping_) {
    if (!in.wait_for_spindle) {
      job_->interp.resume();
    } else if (in.running) {
      if (!was_waiting) spindle_wait_cycles_ = 0;
      spindle_waiting_ = true;
      // Judged on the target of the marker (the ramp and the feedback of the previous cycle must
      // both be there): at-speed of an older target does not count.
      spindle_wait_target_rpm_ =
          drivers::clamp_spindle_rpm(programmed_spindle_rpm(), spindle_limits_);
      if (in.spindle_at_speed && spindle_wait_target_rpm_ == in.spindle_target_rpm) {
        spindle_waiting_ = false;
        ++spindle_waits_;
        spindle_last_wait_s_ = static_cast<double>(spindle_wait_cycles_) * period_s_;
        job_->interp.resume();
        out.spindle_at_speed = true;
      } else {
        ++spindle_wait_cycles_;
        out.spindle_waiting = true;
      }
    }
  }

  const bool stationary = iout_.override_applied <= 0.0 || ist == InterpStatus::kSpindleWait ||
                          ist == InterpStatus::kHolding || ist == InterpStatus::kStarved ||
                          ist == InterpStatus::kDone;
  if (stopping_ && stationary) {
    out.stopped = true;
  } else if (ist == InterpStatus::kDone ||
             (ist == InterpStatus::kStarved && planner_done && job_->queue.size() == 0)) {
    if (!settling_) {
      settling_ = true;
      settle_cycles_ = 0;
    }
  }
  return r;
}

bool ProgramSource::settled(const Eigen::Vector3d& ref_mm, const Eigen::Vector3d& act_mm,
                            int axes) noexcept {
  ++settle_cycles_;
  double err = 0.0;
  for (int i = 0; i < axes; ++i) err = std::max(err, std::abs(ref_mm[i] - act_mm[i]));
  return err < kInPositionMm || static_cast<double>(settle_cycles_) * period_s_ > kSettleTimeoutS;
}

// ---------------------------------------------------------------------------------------------
// JogSource

void JogSource::start(int axis, double velocity_mm_s, double target_mm) noexcept {
  active_ = true;
  axis_ = axis;
  v_mm_s_ = velocity_mm_s;
  speed_mm_s_ = 0.0;
  target_mm_ = target_mm;
}

void JogSource::brake(double ref_axis_mm, double decel_mm_s2) noexcept {
  if (!active_) return;
  const double dir = target_mm_ >= ref_axis_mm ? 1.0 : -1.0;
  target_mm_ = ref_axis_mm + dir * speed_mm_s_ * speed_mm_s_ / (2.0 * decel_mm_s2);
}

RefPoint JogSource::step(const Eigen::Vector3d& ref_mm, const LiveLimits& lim, double period_s) noexcept {
  RefPoint r;
  r.source = SourceKind::kJog;
  r.position_mm = ref_mm;
  r.track = true;
  r.drives_on = true;
  if (!active_) return r;
  const auto a = static_cast<std::size_t>(axis_);
  const double acc = lim.max_accel_mm_s2[a];
  // A jog stays inside the live soft limits: it stops at a limit (which may have moved since the
  // jog was accepted: SIGHUP). Outside a limit it may only move back in, never further out, and
  // the clamp never turns a jog around.
  const double here = ref_mm[axis_];
  if (target_mm_ > here) target_mm_ = std::min(target_mm_, std::max(lim.max_mm[a], here));
  if (target_mm_ < here) target_mm_ = std::max(target_mm_, std::min(lim.min_mm[a], here));
  const double rem = target_mm_ - ref_mm[axis_];
  const double dir = rem >= 0.0 ? 1.0 : -1.0;
  const double v_brake = std::sqrt(2.0 * acc * std::abs(rem));
  const double v_des = std::min({v_mm_s_, v_brake, lim.max_velocity_mm_s[a]});
  speed_mm_s_ = std::min(v_des, speed_mm_s_ + acc * period_s);
  const double step = std::min(speed_mm_s_ * period_s, std::abs(rem));
  r.position_mm[axis_] += dir * step;
  if (std::abs(target_mm_ - r.position_mm[axis_]) < 1e-9) {
    r.position_mm[axis_] = target_mm_;
    active_ = false;
  }
  return r;
}

// ---------------------------------------------------------------------------------------------
// HomingSource

const char* to_string(HomingSource::Phase p) noexcept {
  switch (p) {
    case HomingSource::Phase::kIdle: return "idle";
    case HomingSource::Phase::kSearch: return "search";
    case HomingSource::Phase::kBrakeSearch: return "search_brake";
    case HomingSource::Phase::kBackoff: return "backoff";
    case HomingSource::Phase::kBrakeBackoff: return "backoff_brake";
    case HomingSource::Phase::kApproach: return "latch";
    case HomingSource::Phase::kBrakeLatch: return "latch_brake";
    case HomingSource::Phase::kLatched: return "latched";
    case HomingSource::Phase::kFinal: return "final_move";
    case HomingSource::Phase::kDone: return "done";
    case HomingSource::Phase::kBraking: return "braking";
    case HomingSource::Phase::kIndex: return "index";
    case HomingSource::Phase::kDrive: return "drive";
    case HomingSource::Phase::kDriveStop: return "drive_stop";
  }
  return "?";
}

const char* to_string(DriveHoming h) noexcept {
  switch (h) {
    case DriveHoming::kIdle: return "idle";
    case DriveHoming::kRunning: return "running";
    case DriveHoming::kAttained: return "attained";
    case DriveHoming::kError: return "error";
    case DriveHoming::kUnsupported: return "unsupported";
  }
  return "?";
}

const char* homing_failure_text(std::uint8_t code) noexcept {
  switch (code) {
    case 1: return "the drive reports no digital inputs (0x60FD): no home switch";
    case 2: return "the home switch did not close within search_distance_mm";
    case 3: return "the home switch did not open again within search_distance_mm";
    case 4: return "the home switch did not close again on the latch approach";
    case 6:
      return "home.use_index, but this bus cannot latch the axis' encoder index (simulated "
             "machine: no sim.index_pitch_mm; CANopen maps the drive's touch probe 0x60B8-0x60BA "
             "at start-up and refuses a drive that lacks those objects or has one PDO)";
    case 7: return "no encoder index within search_distance_mm after the home switch";
    case 8:
      return "home.method drive, but this bus cannot ask the drive to home itself (CiA 402 homing "
             "mode 6)";
    case 9: return "the drive did not report homing attained within home.drive_timeout_s";
    case 10: return "the drive reported a homing error (CiA 402 statusword bit 13)";
    case 11:
      return "the drive refused a homing object (SDO abort): it does not support CiA 402 homing "
             "mode 6 (use home.method switch)";
    default: return "aborted (stop, or the machine left READY) before every axis latched";
  }
}

void HomingSource::start(const std::array<AxisPlan, kMaxAxes>& plan, int axes,
                         const Eigen::Vector3d& ref_mm) noexcept {
  plan_ = plan;
  axes_ = axes;
  pos_mm_ = ref_mm;
  v_.fill(0.0);
  phase_.fill(Phase::kIdle);
  homing_mask_ = 0;
  for (int i = 0; i < axes_; ++i) {
    if (plan_[static_cast<std::size_t>(i)].home) homing_mask_ |= 1u << i;
  }
  failed_axis_ = -1;
  failure_code_ = 0;
  shift_pending_ = false;
  group_ = -1;
  active_ = homing_mask_ != 0;
  if (active_) start_group();
}

void HomingSource::start_group() noexcept {
  // The lowest sequence number among the axes still to home.
  int next = -1;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if ((homing_mask_ >> i & 1u) == 0 || phase_[a] == Phase::kDone) continue;
    if (next < 0 || plan_[a].sequence < next) next = plan_[a].sequence;
  }
  group_mask_ = 0;
  if (next < 0) {
    active_ = false;
    return;
  }
  group_ = next;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if ((homing_mask_ >> i & 1u) == 0 || phase_[a] == Phase::kDone || plan_[a].sequence != next) continue;
    group_mask_ |= 1u << i;
    phase_[a] = plan_[a].drive ? Phase::kDrive : Phase::kSearch;
    start_mm_[a] = pos_mm_[i];
    v_[a] = 0.0;
    drive_s_[a] = 0.0;
  }
}

void HomingSource::fail(int axis, std::uint8_t code, double value) noexcept {
  if (failed_axis_ < 0) {
    failed_axis_ = axis;
    failure_code_ = code;
    failure_value_ = value;
  }
  abort();
}

void HomingSource::abort() noexcept {
  if (!active_) return;
  shift_pending_ = false;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (phase_[a] == Phase::kDrive || phase_[a] == Phase::kDriveStop) {
      phase_[a] = Phase::kDriveStop;  // the drive stops on its own: follow it to rest
    } else if (phase_[a] != Phase::kIdle && phase_[a] != Phase::kDone) {
      phase_[a] = Phase::kBraking;
    }
  }
}

void HomingSource::shifted(const Eigen::Vector3d& ref_mm) noexcept {
  pos_mm_ = ref_mm;
  shift_pending_ = false;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if ((group_mask_ >> i & 1u) == 0) continue;
    phase_[a] = Phase::kFinal;
    v_[a] = 0.0;
  }
}

void HomingSource::ramp(std::size_t a, double v_target, double acc, double period_s) noexcept {
  const double dv = acc * period_s;
  v_[a] = v_target > v_[a] ? std::min(v_target, v_[a] + dv) : std::max(v_target, v_[a] - dv);
  pos_mm_[static_cast<Eigen::Index>(a)] += v_[a] * period_s;
}

RefPoint HomingSource::step(const Feedback& fb, const LiveLimits& lim, double period_s) noexcept {
  RefPoint r;
  r.source = SourceKind::kHoming;
  r.track = true;
  r.drives_on = true;
  if (!active_) {
    r.position_mm = pos_mm_;
    return r;
  }
  bool group_latched = group_mask_ != 0;
  bool group_done = group_mask_ != 0;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const Phase ph = phase_[a];
    if (ph == Phase::kIdle || ph == Phase::kDone) continue;
    const AxisPlan& p = plan_[a];
    const double acc = lim.max_accel_mm_s2[a];
    const AxisFeedback& ax = fb.bus.axis[a];
    const bool edge_ok = ax.digital_inputs_present && ax.digital_inputs_fresh;
    const bool sw = (ax.digital_inputs & kHomeSwitchBit) != 0;
    const double search_dir = p.search_mm_s > 0.0 ? 1.0 : -1.0;
    const bool release_latch = (p.latch_mm_s > 0.0) != (p.search_mm_s > 0.0);
    const double travelled = std::abs(pos_mm_[i] - start_mm_[a]);
    switch (ph) {
      case Phase::kSearch:
        if (!ax.digital_inputs_present) {
          fail(i, 1, 0.0);
        } else if (p.use_index && !ax.index_present) {
          fail(i, 6, 0.0);
        } else if (edge_ok && sw) {
          phase_[a] = Phase::kBrakeSearch;
        } else if (travelled > p.search_distance_mm) {
          fail(i, 2, travelled);
        }
        ramp(a, phase_[a] == Phase::kSearch ? p.search_mm_s : 0.0, acc, period_s);
        break;
      case Phase::kBrakeSearch:
        ramp(a, 0.0, acc, period_s);
        if (v_[a] == 0.0) {
          phase_[a] = Phase::kBackoff;
          start_mm_[a] = pos_mm_[i];
        }
        break;
      case Phase::kBackoff: {
        // Away from the switch at the latch speed; the release edge is the latch for an
        // opposite-sign latch_vel.
        if (edge_ok && !sw) {
          if (release_latch && p.use_index) {
            // On at the same speed to the encoder's next index.
            phase_[a] = Phase::kIndex;
            index_v_[a] = -search_dir * std::abs(p.latch_mm_s);
            start_mm_[a] = pos_mm_[i];
          } else {
            if (release_latch) latch_mm_[a] = fb.act_mm[i];
            phase_[a] = Phase::kBrakeBackoff;
          }
        } else if (travelled > p.search_distance_mm) {
          fail(i, 3, travelled);
        }
        ramp(a, phase_[a] == Phase::kBackoff || phase_[a] == Phase::kIndex ? -search_dir * std::abs(p.latch_mm_s) : 0.0,
             acc, period_s);
        break;
      }
      case Phase::kBrakeBackoff:
        ramp(a, 0.0, acc, period_s);
        if (v_[a] == 0.0) {
          phase_[a] = release_latch ? Phase::kLatched : Phase::kApproach;
          start_mm_[a] = pos_mm_[i];
        }
        break;
      case Phase::kApproach:
        if (edge_ok && sw && p.use_index) {
          phase_[a] = Phase::kIndex;
          index_v_[a] = p.latch_mm_s;
          start_mm_[a] = pos_mm_[i];
        } else if (edge_ok && sw) {
          latch_mm_[a] = fb.act_mm[i];
          phase_[a] = Phase::kBrakeLatch;
        } else if (travelled > p.search_distance_mm) {
          fail(i, 4, travelled);
        }
        ramp(a, phase_[a] == Phase::kApproach || phase_[a] == Phase::kIndex ? p.latch_mm_s : 0.0, acc, period_s);
        break;
      case Phase::kIndex:
        // The drive latched the index (armed since the switch edge): its position, exact to the
        // count, in the loop's coordinates (act - bus position is the present home shift).
        if (ax.index_latched) {
          latch_mm_[a] = ax.index_position_mm + (fb.act_mm[i] - ax.position_mm);
          phase_[a] = Phase::kBrakeLatch;
        } else if (travelled > p.search_distance_mm) {
          fail(i, 7, travelled);
        }
        ramp(a, phase_[a] == Phase::kIndex ? index_v_[a] : 0.0, acc, period_s);
        break;
      case Phase::kBrakeLatch:
        ramp(a, 0.0, acc, period_s);
        if (v_[a] == 0.0) phase_[a] = Phase::kLatched;
        break;
      case Phase::kLatched:
        if (p.drive) pos_mm_[i] = fb.act_mm[i];  // not servoed until the shift (drive_moves)
        break;
      case Phase::kFinal: {
        // Trapezoid to home_position_mm at the search speed and the axis' acceleration.
        const double rem = p.position_mm - pos_mm_[i];
        const double vmax = std::min(std::abs(p.search_mm_s), lim.max_velocity_mm_s[a]);
        // The speed from which braking at `acc` in whole cycles ends at the target.
        const double half = 0.5 * acc * period_s;
        const double v_brake = std::sqrt(half * half + 2.0 * acc * std::abs(rem)) - half;
        const double v_t = (rem >= 0.0 ? 1.0 : -1.0) * std::min(vmax, v_brake);
        ramp(a, v_t, acc, period_s);
        const double after = p.position_mm - pos_mm_[i];
        if ((rem >= 0.0) != (after >= 0.0) || std::abs(after) < 1e-9) {
          pos_mm_[i] = p.position_mm;
          v_[a] = 0.0;
          phase_[a] = Phase::kDone;
        }
        break;
      }
      case Phase::kDrive:
        // The drive homes itself (the bus drives mode 6 while drive_home_request()): the
        // reference is where the axis is, so the controllers and the following-error rule see no
        // error for motion the loop does not command (ServoLoop commands 0 on this axis).
        pos_mm_[i] = fb.act_mm[i];
        v_[a] = 0.0;
        drive_s_[a] += period_s;
        if (!ax.drive_homing_present) {
          fail(i, 8, 0.0);
        } else if (ax.drive_homing == DriveHoming::kUnsupported) {
          fail(i, 11, static_cast<double>(ax.drive_homing_detail));
        } else if (ax.drive_homing == DriveHoming::kError) {
          fail(i, 10, static_cast<double>(ax.drive_homing_detail));
        } else if (ax.drive_homing == DriveHoming::kAttained) {
          // The drive stands and reads 0 at its home point: that point in the loop's coordinates
          // (act - bus position is the present home shift) is the latch.
          latch_mm_[a] = fb.act_mm[i] - ax.position_mm;
          phase_[a] = Phase::kLatched;
        } else if (drive_s_[a] > p.drive_timeout_s) {
          fail(i, 9, drive_s_[a]);
        }
        break;
      case Phase::kDriveStop:
        // Abandoned: the request is gone, the bus takes the drive back to the cyclic mode and the
        // zero velocity command stops it; the reference follows until it stands.
        pos_mm_[i] = fb.act_mm[i];
        v_[a] = 0.0;
        if (ax.drive_homing != DriveHoming::kRunning && ax.fresh && std::abs(ax.velocity_mm_s) < kDriveRestMmS) {
          phase_[a] = Phase::kIdle;
        }
        break;
      case Phase::kBraking:
        ramp(a, 0.0, acc, period_s);
        if (v_[a] == 0.0) phase_[a] = Phase::kIdle;
        break;
      case Phase::kIdle:
      case Phase::kDone:
        break;
    }
    if ((group_mask_ >> i & 1u) != 0) {
      group_latched = group_latched && phase_[a] == Phase::kLatched;
      group_done = group_done && phase_[a] == Phase::kDone;
    }
  }
  bool braking = false;
  bool group_idle = false;  // an axis of the group braked to rest: aborted or failed
  for (int i = 0; i < axes_; ++i) {
    const Phase ph = phase_[static_cast<std::size_t>(i)];
    braking = braking || ph == Phase::kBraking || ph == Phase::kDriveStop;
    group_idle = group_idle || ((group_mask_ >> i & 1u) != 0 && ph == Phase::kIdle);
  }
  if (braking) {
    // abort / failure: the source ends once every axis stands
  } else if (failed_axis_ >= 0 || group_idle) {
    active_ = false;
  } else if (group_latched) {
    shift_pending_ = true;
  } else if (group_done) {
    start_group();  // the next sequence group, or the end
  }
  r.position_mm = pos_mm_;
  return r;
}

// ---------------------------------------------------------------------------------------------
// HoldSource

RefPoint HoldSource::step(const Feedback& fb, bool servo) noexcept {
  RefPoint r;
  r.source = SourceKind::kHold;
  if (!servo) held_mm_ = fb.act_mm;
  r.position_mm = held_mm_;
  r.track = servo;
  r.drives_on = servo;
  return r;
}

// ---------------------------------------------------------------------------------------------
// StopSource

void StopSource::start(const std::array<double, kMaxAxes>& v0_mm_s, int axes) noexcept {
  axes_ = axes;
  v0_.fill(0.0);
  double sq = 0.0;
  for (int i = 0; i < axes && i < kMaxAxes; ++i) {
    const auto a = static_cast<std::size_t>(i);
    v0_[a] = std::isfinite(v0_mm_s[a]) ? v0_mm_s[a] : 0.0;
    sq += v0_[a] * v0_[a];
  }
  speed0_ = std::sqrt(sq);
  ramp_speed_ = speed0_;
  settle_s_ = still_s_ = 0.0;
  moving_axis_ = -1;
  moving_speed_ = 0.0;
  timed_out_ = false;
  phase_ = speed0_ > 0.0 ? Phase::kRamp : Phase::kSettle;
}

RefPoint StopSource::step(const Feedback& fb, const LiveLimits& lim, double period_s) noexcept {
  RefPoint r;
  r.source = SourceKind::kStop;
  r.position_mm = fb.act_mm;
  r.track = false;
  timed_out_ = false;
  if (phase_ == Phase::kRamp) {
    ramp_speed_ = std::max(0.0, ramp_speed_ - lim.stop_decel_mm_s2 * period_s);
    const double scale = speed0_ > 0.0 ? ramp_speed_ / speed0_ : 0.0;
    for (int i = 0; i < axes_; ++i) {
      const auto a = static_cast<std::size_t>(i);
      r.velocity_mm_s[a] = v0_[a] * scale;
    }
    if (ramp_speed_ <= 0.0) phase_ = Phase::kSettle;
    r.drives_on = true;
    return r;
  }
  if (phase_ == Phase::kSettle) {
    settle_s_ += period_s;
    bool still = true;
    moving_axis_ = -1;
    moving_speed_ = 0.0;
    for (int i = 0; i < axes_; ++i) {
      const AxisFeedback& ax = fb.bus.axis[static_cast<std::size_t>(i)];
      const double v = std::abs(ax.velocity_mm_s);
      // Stale feedback proves nothing: the axis counts as moving until a fresh reading says not.
      if (!ax.fresh || !(v < lim.standstill_velocity_mm_s)) {
        still = false;
        if (!ax.fresh || v >= moving_speed_) {
          moving_axis_ = i;
          moving_speed_ = ax.fresh ? v : std::numeric_limits<double>::quiet_NaN();
        }
      }
    }
    still_s_ = still ? still_s_ + period_s : 0.0;
    if (still && still_s_ >= lim.standstill_time_s - 1e-12) {
      phase_ = Phase::kOff;
    } else if (settle_s_ > lim.standstill_timeout_s) {
      phase_ = Phase::kQuickStop;
      timed_out_ = true;
    } else {
      r.drives_on = true;  // zero command, the drives' velocity loops brake
      return r;
    }
  }
  r.quick_stop = phase_ == Phase::kQuickStop;
  r.drives_on = false;
  return r;
}

const char* to_string(StopSource::Phase p) noexcept {
  switch (p) {
    case StopSource::Phase::kRamp: return "ramp";
    case StopSource::Phase::kSettle: return "settle";
    case StopSource::Phase::kOff: return "off";
    case StopSource::Phase::kQuickStop: return "quick_stop";
  }
  return "?";
}

}  // namespace contour::daemon
