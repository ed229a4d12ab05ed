#include "daemon/safety_supervisor.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace contour::daemon {

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

SafetySupervisor::SafetySupervisor(const config::Config& cfg, bool force_stale_faults)
    : axes_(static_cast<int>(cfg.machine.axes.size())),
      period_s_(cfg.machine.period_s),
      missed_tpdo_streak_(cfg.safety.missed_tpdo_streak),
      spindle_timeout_s_(cfg.spindle.at_speed_timeout_s),
      force_stale_faults_(force_stale_faults) {
  if (axes_ < 1 || axes_ > 3) throw std::invalid_argument("safety supervisor: 1 to 3 axes");
  for (std::size_t i = 0; i < cfg.machine.axes.size(); ++i) {
    min_mm_[i] = cfg.machine.axes[i].min_mm;
    max_mm_[i] = cfg.machine.axes[i].max_mm;
  }
}

FaultReport SafetySupervisor::check_estop(const Feedback& fb) const noexcept {
  if (fb.estop_input) return {FaultCause::kEstopInput, -1, 1.0, 0.0};
  return {};
}

FaultReport SafetySupervisor::check_bus(const Feedback& fb, bool servo) const noexcept {
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const AxisFeedback& ax = fb.bus.axis[a];
    if (ax.fault) return {FaultCause::kDriveFault, i, 1.0, 0.0};
    // A drive that leaves operation enabled without a fault (its enable input or STO opened, a
    // local operator, a stray controlword) no longer follows the commands: stop everything.
    // The master would otherwise walk it back to operation enabled on its own.
    if (servo && ax.fresh && !ax.enabled) return {FaultCause::kDriveDisabled, i, 1.0, 0.0};
    if (fb.missed_streak[a] >= missed_tpdo_streak_) {
      return {FaultCause::kMissedTpdo, i, static_cast<double>(fb.missed_streak[a]),
              static_cast<double>(missed_tpdo_streak_)};
    }
  }
  if (fb.bus.spindle.fault) return {FaultCause::kSpindleFault, -1, fb.bus.spindle.actual_rpm, 0.0};
  if (fb.bus.heartbeat_lost) return {FaultCause::kHeartbeatLost, fb.bus.heartbeat_lost_node, 1.0, 0.0};
  if (fb.bus.bus_error) return {FaultCause::kBusError, -1, 1.0, 0.0};
  return {};
}

FaultReport SafetySupervisor::check_motion(const Eigen::Vector3d& ref_mm, const Eigen::Vector3d& act_mm,
                                           const Eigen::Vector3d& v_ref_mm_s, double eps_norm_mm,
                                           const LiveLimits& lim) const noexcept {
  const double fe = lim.ferror_mm, mfe = lim.min_ferror_mm;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    // LinuxCNC: the allowed following error grows linearly with the commanded speed from
    // MIN_FERROR at standstill to FERROR at the axis' maximum velocity.
    const double band =
        std::min(fe, mfe + (fe - mfe) * std::abs(v_ref_mm_s[i]) / lim.max_velocity_mm_s[a]);
    const double err = std::abs(ref_mm[i] - act_mm[i]);
    if (err > band) return {FaultCause::kFollowingError, i, err, band};
    if (ref_mm[i] < min_mm_[a] - 1e-9 || ref_mm[i] > max_mm_[a] + 1e-9) {
      return {FaultCause::kSoftLimit, i, ref_mm[i], ref_mm[i] < min_mm_[a] ? min_mm_[a] : max_mm_[a]};
    }
  }
  if (eps_norm_mm > lim.contour_error_limit_mm) {
    return {FaultCause::kContourError, -1, eps_norm_mm, lim.contour_error_limit_mm};
  }
  return {};
}

FaultReport SafetySupervisor::check_spindle_wait(std::int64_t waited_cycles, double actual_rpm,
                                                 double target_rpm) const noexcept {
  if (static_cast<double>(waited_cycles) * period_s_ > spindle_timeout_s_) {
    return {FaultCause::kSpindleNotAtSpeed, -1, actual_rpm, target_rpm};
  }
  return {};
}

FaultReport SafetySupervisor::check_force_stale(bool fallback_now, double age_s,
                                                double stale_age_s) const noexcept {
  if (fallback_now && force_stale_faults_) return {FaultCause::kForceStale, -1, age_s, stale_age_s};
  return {};
}

bool SafetySupervisor::causes_gone(const Feedback& fb, bool estop_tripped) const noexcept {
  bool gone = !fb.bus.heartbeat_lost && !fb.bus.bus_error && !estop_tripped;
  for (int i = 0; i < axes_; ++i) gone = gone && !fb.bus.axis[static_cast<std::size_t>(i)].fault;
  return gone && !fb.bus.spindle.fault;
}

}  // namespace contour::daemon
