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
  l.standstill_velocity_mm_s = cfg.safety.standstill_velocity_mm_s;
  l.standstill_time_s = cfg.safety.standstill_time_s;
  l.standstill_timeout_s = cfg.safety.standstill_timeout_s;
  l.feed_override_max = cfg.interpolator.feed_override_max_percent / 100.0;
  l.rapid_override_max = cfg.interpolator.rapid_override_max_percent / 100.0;
  l.spindle_override_min = cfg.spindle.override_min_percent / 100.0;
  l.spindle_override_max = cfg.spindle.override_max_percent / 100.0;
  l.jog_max_velocity_mm_s = cfg.safety.jog_max_velocity_mm_min / 60.0;
  for (std::size_t i = 0; i < 3; ++i) {
    if (i < cfg.machine.axes.size()) {
      l.max_velocity_mm_s[i] = cfg.machine.axes[i].max_velocity_mm_min / 60.0;
      l.max_accel_mm_s2[i] = cfg.machine.axes[i].max_accel_mm_s2;
      l.min_mm[i] = cfg.machine.axes[i].min_mm;
      l.max_mm[i] = cfg.machine.axes[i].max_mm;
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
  positive(l.standstill_velocity_mm_s, "safety.standstill_velocity_mm_s");
  positive(l.standstill_timeout_s, "safety.standstill_timeout_s");
  positive(l.feed_override_max, "interpolator.feed_override_max_percent");
  positive(l.rapid_override_max, "interpolator.rapid_override_max_percent");
  if (!(l.rapid_override_max <= 1.0)) {
    throw std::invalid_argument("limits: interpolator.rapid_override_max_percent must be <= 100");
  }
  if (!(l.spindle_override_min >= 0.0 && l.spindle_override_min <= 1.0 &&
        l.spindle_override_max >= 1.0 && std::isfinite(l.spindle_override_max))) {
    throw std::invalid_argument(
        "limits: spindle.override_min_percent must be 0..100 and override_max_percent >= 100");
  }
  positive(l.jog_max_velocity_mm_s, "safety.jog_max_velocity_mm_min");
  if (!std::isfinite(l.standstill_time_s) || l.standstill_time_s < 0.0 ||
      l.standstill_time_s >= l.standstill_timeout_s) {
    throw std::invalid_argument(
        "limits: safety.standstill_time_s must be >= 0 and < safety.standstill_timeout_s");
  }
  if (l.min_ferror_mm > l.ferror_mm) {
    throw std::invalid_argument("limits: safety.min_ferror_mm must be <= safety.ferror_mm");
  }
  for (int i = 0; i < axes && i < 3; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const std::string ax = "machine.axes[" + std::to_string(i) + "]";
    positive(l.max_velocity_mm_s[a], ax + ".max_velocity");
    positive(l.max_accel_mm_s2[a], ax + ".max_accel_mm_s2");
    if (std::isnan(l.min_mm[a]) || std::isnan(l.max_mm[a]) || !(l.min_mm[a] < l.max_mm[a])) {
      throw std::invalid_argument("limits: " + ax + ".min_mm must be < max_mm");
    }
  }
}

double following_band_mm(const LiveLimits& l, int axis, double v_ref_mm_s) noexcept {
  const auto a = static_cast<std::size_t>(axis);
  return std::min(l.ferror_mm, l.min_ferror_mm + (l.ferror_mm - l.min_ferror_mm) *
                                                     std::abs(v_ref_mm_s) / l.max_velocity_mm_s[a]);
}

std::string describe(const ResetBlock& b) {
  const std::string who = b.node > 0 ? "node " + std::to_string(b.node)
                          : b.axis >= 0 ? "axis " + std::to_string(b.axis)
                                        : std::string();
  switch (b.cause) {
    case FaultCause::kNone: return "nothing";
    case FaultCause::kHeartbeatLost:
      return "no heartbeat from " + who + " since it was lost (the drive must be heard again)";
    case FaultCause::kDriveFault:
      return "the drive of " + who + " still reports a fault (CiA 402 fault bit set after the fault-reset edge)";
    case FaultCause::kNmtStateChange:
      return "the drive of " + who + " is not NMT operational";
    case FaultCause::kSpindleFault: return "the spindle drive still reports a fault";
    case FaultCause::kBusError: return "the CAN bus is still in error (bus-off / error passive)";
    case FaultCause::kIoModule:
      return "the CiA 401 I/O module " + who + " is not NMT operational";
    case FaultCause::kEstopInput: return "the E-stop input is still asserted";
    case FaultCause::kMissedTpdo:
      return "the drive of " + who + " still does not send its 0x60FD digital inputs (TPDO2)";
    case FaultCause::kPlcFault:
    case FaultCause::kPlcEstop:
      return "the machine logic still requests an E-stop, a fault or an axis fault, or a latched "
             "PLC fault's cause remains (contourctl plc status)";
    default: return std::string(to_string(b.cause)) + (who.empty() ? "" : " (" + who + ")");
  }
}

SafetySupervisor::SafetySupervisor(const config::Config& cfg, bool force_stale_faults)
    : axes_(static_cast<int>(cfg.machine.axes.size())),
      period_s_(cfg.machine.period_s),
      missed_tpdo_streak_(cfg.safety.missed_tpdo_streak),
      spindle_timeout_s_(cfg.spindle.at_speed_timeout_s),
      force_stale_faults_(force_stale_faults) {
  if (axes_ < 1 || axes_ > 3) throw std::invalid_argument("safety supervisor: 1 to 3 axes");
}

FaultReport SafetySupervisor::check_estop(const Feedback& fb) const noexcept {
  if (fb.estop_input) return {FaultCause::kEstopInput, -1, 1.0, 0.0};
  return {};
}

FaultReport SafetySupervisor::check_bus(const Feedback& fb, bool servo) const noexcept {
  // First what a drive SAID (fault bit, NMT change) on any axis, then what the master only
  // inferred (left operation enabled, missed TPDOs): a drive that reboots also stops sending its
  // TPDOs, and the FAULT's cause must be the event, not the silence that follows it. An EMCY
  // alone is a warning (drives report temperature or voltage warnings that way): it becomes the
  // cause when the drive then stops following (fault bit, disabled, TPDOs missing).
  // The common case first, in one pass: nothing below can fire (the order of the causes only
  // matters when one does).
  bool any = fb.bus.spindle.fault || fb.bus.heartbeat_lost || fb.bus.bus_error;
  for (int k = 0; k < fb.bus.io_modules; ++k) {
    const IoModuleFeedback& m = fb.bus.io[static_cast<std::size_t>(k)];
    any = any || m.nmt_lost || m.emcy_code != 0 ||
          m.missed_streak >= static_cast<std::uint32_t>(missed_tpdo_streak_);
  }
  for (int i = 0; i < axes_; ++i) {
    const AxisFeedback& ax = fb.bus.axis[static_cast<std::size_t>(i)];
    any = any || ax.fault || ax.nmt_lost || (servo && ax.fresh && !ax.enabled) ||
          fb.missed_streak[static_cast<std::size_t>(i)] >= missed_tpdo_streak_ ||
          fb.inputs_missed_streak[static_cast<std::size_t>(i)] >= missed_tpdo_streak_;
  }
  if (!any) return {};
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const AxisFeedback& ax = fb.bus.axis[a];
    if (ax.fault) return {FaultCause::kDriveFault, i, static_cast<double>(ax.emcy_code), 0.0};
    if (ax.nmt_lost) return {FaultCause::kNmtStateChange, i, static_cast<double>(ax.node_id), 0.0};
  }
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const AxisFeedback& ax = fb.bus.axis[a];
    // A drive that leaves operation enabled without a fault (its enable input or STO opened, a
    // local operator, a stray controlword) no longer follows the commands: stop everything.
    // The master would otherwise walk it back to operation enabled on its own.
    const bool disabled = servo && ax.fresh && !ax.enabled;
    const bool silent = fb.missed_streak[a] >= missed_tpdo_streak_;
    if ((disabled || silent) && ax.emcy_code != 0) {
      return {FaultCause::kDriveEmcy, i, static_cast<double>(ax.emcy_code), 0.0};
    }
    if (disabled) return {FaultCause::kDriveDisabled, i, 1.0, 0.0};
  }
  if (fb.bus.spindle.fault) return {FaultCause::kSpindleFault, -1, fb.bus.spindle.actual_rpm, 0.0};
  // A CiA 401 module of the PLC (its inputs would go stale, its outputs unheard): what it said
  // (NMT change, EMCY) before what the master inferred (TPDOs missing), as for the drives. The
  // report's axis is the node-id, as for a heartbeat loss.
  for (int k = 0; k < fb.bus.io_modules; ++k) {
    const IoModuleFeedback& m = fb.bus.io[static_cast<std::size_t>(k)];
    if (m.nmt_lost)
      return {FaultCause::kIoModule, m.node_id, 0.0, 0.0,
              static_cast<std::uint8_t>(IoModuleFault::kNmt)};
    if (m.emcy_code != 0)
      return {FaultCause::kIoModule, m.node_id, static_cast<double>(m.emcy_code), 0.0,
              static_cast<std::uint8_t>(IoModuleFault::kEmcy)};
  }
  if (fb.bus.heartbeat_lost) return {FaultCause::kHeartbeatLost, fb.bus.heartbeat_lost_node, 1.0, 0.0};
  for (int k = 0; k < fb.bus.io_modules; ++k) {
    const IoModuleFeedback& m = fb.bus.io[static_cast<std::size_t>(k)];
    if (m.missed_streak >= static_cast<std::uint32_t>(missed_tpdo_streak_))
      return {FaultCause::kIoModule, m.node_id, static_cast<double>(m.missed_streak),
              static_cast<double>(missed_tpdo_streak_),
              static_cast<std::uint8_t>(IoModuleFault::kTpdoMissed)};
  }
  if (fb.bus.bus_error) return {FaultCause::kBusError, -1, 1.0, 0.0};
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (fb.missed_streak[a] >= missed_tpdo_streak_) {
      return {FaultCause::kMissedTpdo, i, static_cast<double>(fb.missed_streak[a]),
              static_cast<double>(missed_tpdo_streak_)};
    }
  }
  // The position came but the digital inputs did not (a drive that lost or never sends its
  // TPDO2): the same streak, its own detail.
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (fb.inputs_missed_streak[a] >= missed_tpdo_streak_) {
      return {FaultCause::kMissedTpdo, i, static_cast<double>(fb.inputs_missed_streak[a]),
              static_cast<double>(missed_tpdo_streak_),
              static_cast<std::uint8_t>(MissedPdo::kDigitalInputs)};
    }
  }
  return {};
}

FaultReport SafetySupervisor::check_motion(const Eigen::Vector3d& ref_mm, const Eigen::Vector3d& act_mm,
                                           const Eigen::Vector3d& v_ref_mm_s, double eps_norm_mm,
                                           const LiveLimits& lim) const noexcept {
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const double band = following_band_mm(lim, i, v_ref_mm_s[i]);
    const double err = std::abs(ref_mm[i] - act_mm[i]);
    if (err > band) return {FaultCause::kFollowingError, i, err, band};
    // The live soft limits (machine coordinates), as swapped in at the last cycle boundary.
    if (ref_mm[i] < lim.min_mm[a] - 1e-9 || ref_mm[i] > lim.max_mm[a] + 1e-9) {
      return {FaultCause::kSoftLimit, i, ref_mm[i], ref_mm[i] < lim.min_mm[a] ? lim.min_mm[a] : lim.max_mm[a]};
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

ResetBlock SafetySupervisor::reset_block(const Feedback& fb, bool estop_tripped) const noexcept {
  if (estop_tripped) return {FaultCause::kEstopInput, -1, 0};
  for (int i = 0; i < axes_; ++i) {
    const AxisFeedback& ax = fb.bus.axis[static_cast<std::size_t>(i)];
    if (ax.fault) return {FaultCause::kDriveFault, i, ax.node_id};
    if (ax.nmt_lost) return {FaultCause::kNmtStateChange, i, ax.node_id};
  }
  if (fb.bus.spindle.fault) return {FaultCause::kSpindleFault, -1, 0};
  if (fb.bus.heartbeat_lost) return {FaultCause::kHeartbeatLost, -1, fb.bus.heartbeat_lost_node};
  for (int k = 0; k < fb.bus.io_modules; ++k) {
    const IoModuleFeedback& m = fb.bus.io[static_cast<std::size_t>(k)];
    if (m.nmt_lost) return {FaultCause::kIoModule, -1, m.node_id};
  }
  if (fb.bus.bus_error) return {FaultCause::kBusError, -1, 0};
  // Digital inputs that stopped while the position kept coming: back only when they come again
  // (a lost position is judged afresh after the reset, as before).
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    if (fb.inputs_missed_streak[a] >= missed_tpdo_streak_ && fb.missed_streak[a] == 0)
      return {FaultCause::kMissedTpdo, i, fb.bus.axis[a].node_id};
  }
  return {};
}

}  // namespace contour::daemon
