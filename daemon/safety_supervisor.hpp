#pragma once
// Every safety rule of the servo loop in one place (the `supervise` stage, and the rules other
// stages consult at the instant they apply: the E-stop input, the spindle at-speed timeout, the
// stale force sample). A rule returns a FaultReport (cause, axis, value, limit); the loop latches
// the first one into the state machine (StateMachine::fault / estop keep the first cause) and
// starts the controlled stop. The reset rule lives here too: a reset is accepted only when every
// cause is gone.
//
// Pure logic over the Feedback snapshot: noexcept, no allocation, no lock, no I/O. Units in the
// names (mm, mm/s, s, rpm).
#include <array>
#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "config/config.hpp"
#include "daemon/loop_stages.hpp"
#include "daemon/machine_state.hpp"

namespace contour::daemon {

// Safety limits that may change live (SIGHUP, swapped like the gains at a cycle boundary and
// enforced from that cycle on: the loop, its sources and the supervisor read only this copy).
// Units in the names; positions in machine coordinates.
struct LiveLimits {
  double ferror_mm = 1.0;
  double min_ferror_mm = 0.1;
  double contour_error_limit_mm = 0.5;
  double stop_decel_mm_s2 = 1000.0;
  std::array<double, 3> max_velocity_mm_s{};
  std::array<double, 3> max_accel_mm_s2{};
  std::array<double, 3> min_mm{-1e300, -1e300, -1e300};  // soft limits
  std::array<double, 3> max_mm{1e300, 1e300, 1e300};
  double standstill_velocity_mm_s = 1.0;
  double standstill_time_s = 0.05;
  double standstill_timeout_s = 2.0;
  double feed_override_max = 1.5;          // ratio (interpolator.feed_override_max_percent / 100)
  double rapid_override_max = 1.0;         // ratio (interpolator.rapid_override_max_percent / 100)
  double spindle_override_min = 0.5;       // ratios (spindle.override_min/max_percent / 100)
  double spindle_override_max = 1.0;
  double jog_max_velocity_mm_s = 50.0;     // safety.jog_max_velocity_mm_min / 60
  bool operator==(const LiveLimits&) const = default;
};
LiveLimits live_limits_from(const config::Config& cfg);
// Throws std::invalid_argument naming the field (non-finite, <= 0, min_ferror > ferror,
// min_mm >= max_mm).
void validate(const LiveLimits& l, int axes);

// LinuxCNC's following-error band for an axis at reference speed |v|: MIN_FERROR at standstill
// growing linearly to FERROR at the axis' maximum velocity.
double following_band_mm(const LiveLimits& l, int axis, double v_ref_mm_s) noexcept;

// FaultCause::kIoModule: what the CiA 401 module did (FaultReport::detail).
enum class IoModuleFault : std::uint8_t { kNone, kTpdoMissed, kEmcy, kNmt };
// FaultCause::kMissedTpdo: which of the drive's inputs stopped coming (FaultReport::detail): its
// position (TPDO1), or only its 0x60FD digital inputs (TPDO2: limit and home switches, probes
// the PLC reads), whose loss would otherwise leave the PLC on the signals' defaults unannounced.
enum class MissedPdo : std::uint8_t { kPosition, kDigitalInputs };

struct FaultReport {
  FaultCause cause = FaultCause::kNone;
  int axis = -1;  // -1: not an axis (spindle, bus, contour); heartbeat: the node-id
  double value = 0.0;
  double limit = 0.0;
  std::uint8_t detail = 0;  // kLimitCycle: control::ChatterFigureKind (which figure); kPlcFault:
                            // the PLC engine's PlcFaultKind (0: the PLC's own request)
  explicit operator bool() const noexcept { return cause != FaultCause::kNone; }
};

// Why a reset cannot be accepted yet (ServoLoop publishes it; `reset` names it in its refusal).
struct ResetBlock {
  FaultCause cause = FaultCause::kNone;  // kNone: nothing blocks
  int axis = -1;                          // axis index, or -1
  int node = 0;                           // CANopen node-id when known (heartbeat: the silent node)
  explicit operator bool() const noexcept { return cause != FaultCause::kNone; }
};
// "the heartbeat of node 2 has not been seen since it was lost" (non-RT text).
std::string describe(const ResetBlock& b);

class SafetySupervisor {
 public:
  SafetySupervisor() = default;
  // Setup: axes, soft limits, missed-TPDO streak, timeouts. force_stale_faults: a stale force
  // sample is a FAULT (LoopOptions, from `force.fallback: fault`).
  SafetySupervisor(const config::Config& cfg, bool force_stale_faults);

  // E-stop input latch (RtIo): ESTOP in the cycle it is seen.
  [[nodiscard]] FaultReport check_estop(const Feedback& fb) const noexcept;

  // Bus and drive rules, in every state but DISABLED/FAULT/ESTOP, first match wins, per axis in
  // order: drive fault bit; a drive that left operation enabled without a fault while the axes
  // servo (`servo`); a missed-TPDO streak >= safety.missed_tpdo_streak. Then the spindle drive's
  // fault, heartbeat loss (axis = node-id), bus error.
  [[nodiscard]] FaultReport check_bus(const Feedback& fb, bool servo) const noexcept;

  // Motion rules while the axes servo, first match wins: per axis the following error against
  // LinuxCNC's band (MIN_FERROR at standstill growing linearly to FERROR at max velocity with the
  // reference speed |v_ref|) and the soft limits on the reference; then the model contour error.
  [[nodiscard]] FaultReport check_motion(const Eigen::Vector3d& ref_mm, const Eigen::Vector3d& act_mm,
                                         const Eigen::Vector3d& v_ref_mm_s, double eps_norm_mm,
                                         const LiveLimits& lim) const noexcept;

  // A feed move that waited `waited_cycles` for the spindle: FAULT "spindle not at speed" past
  // spindle.at_speed_timeout_s (value: actual rpm, limit: target rpm).
  [[nodiscard]] FaultReport check_spindle_wait(std::int64_t waited_cycles, double actual_rpm,
                                               double target_rpm) const noexcept;

  // A stale/invalid force sample while force control is on: a FAULT only with
  // `force.fallback: fault` (otherwise the force channel's fallback handles it).
  [[nodiscard]] FaultReport check_force_stale(bool fallback_now, double age_s,
                                              double stale_age_s) const noexcept;

  // Reset rule: every cause that latched a FAULT/ESTOP is gone in this snapshot (no heartbeat
  // loss — the bus keeps that latched until a heartbeat arrived after the loss —, no bus error,
  // E-stop input released, no drive or spindle fault bit, no unacknowledged EMCY / NMT change).
  // Otherwise the first condition still missing: cause, axis (-1: spindle/bus/E-stop) or node.
  [[nodiscard]] ResetBlock reset_block(const Feedback& fb, bool estop_tripped) const noexcept;
  [[nodiscard]] bool causes_gone(const Feedback& fb, bool estop_tripped) const noexcept {
    return !reset_block(fb, estop_tripped);
  }

  [[nodiscard]] int axes() const noexcept { return axes_; }

 private:
  int axes_ = 3;
  double period_s_ = 0.001;
  int missed_tpdo_streak_ = 5;
  double spindle_timeout_s_ = 10.0;
  bool force_stale_faults_ = false;
};

}  // namespace contour::daemon
