#pragma once
// Spindle interface shared by the CiA 402 velocity-mode drive on CAN (drivers/canopen) and the
// VFD over Modbus RTU (drivers/modbus/vfd_spindle). Speeds in rpm, positive = M3 (clockwise),
// negative = M4. Limits: |speed| in [min_rpm, max_rpm] when running (0 = stop), setpoint slewed at
// rate_rpm_s; "at speed" when |actual - target| <= max(tolerance_rpm, tolerance_fraction*|target|)
// — the force controller requires it before feed moves with force control.
// set_speed()/stop()/status() are noexcept, non-blocking and allocation-free (implementations
// hand the target to their own I/O thread or PDO through atomics), so they are callable from the
// RT loop.
#include <algorithm>
#include <cmath>
#include <cstdint>

namespace contour::drivers {

struct SpindleLimits {
  double min_rpm = 0.0;
  double max_rpm = 24000.0;
  double rate_rpm_s = 2000.0;
  double at_speed_tolerance_rpm = 50.0;
  double at_speed_tolerance_fraction = 0.02;
};

enum class SpindleFault : std::uint8_t { kNone, kCommunication, kDrive, kNotConfigured };

struct SpindleStatus {
  double target_rpm = 0.0;    // requested, after clamping
  double setpoint_rpm = 0.0;  // ramped value sent to the drive
  double actual_rpm = 0.0;    // reported by the drive
  bool running = false;
  bool at_speed = false;
  bool comm_ok = false;
  SpindleFault fault = SpindleFault::kNone;
};

// Clamps a request to the limits: |rpm| < min_rpm (and != 0) -> min_rpm with the request's sign.
[[nodiscard]] inline double clamp_spindle_rpm(double rpm, const SpindleLimits& l) noexcept {
  if (!std::isfinite(rpm) || rpm == 0.0) return 0.0;
  const double mag = std::clamp(std::abs(rpm), l.min_rpm, l.max_rpm);
  return rpm < 0.0 ? -mag : mag;
}

[[nodiscard]] inline bool spindle_at_speed(double actual_rpm, double target_rpm,
                                           const SpindleLimits& l) noexcept {
  const double tol =
      std::max(l.at_speed_tolerance_rpm, l.at_speed_tolerance_fraction * std::abs(target_rpm));
  return std::abs(actual_rpm - target_rpm) <= tol;
}

// Slew-rate limiter: setpoint moves towards target at most rate_rpm_s * dt_s per step.
class SpindleRamp {
 public:
  explicit SpindleRamp(const SpindleLimits& l) noexcept : l_(l) {}
  double step(double target_rpm, double dt_s) noexcept {
    const double max_step = l_.rate_rpm_s * dt_s;
    setpoint_ += std::clamp(target_rpm - setpoint_, -max_step, max_step);
    return setpoint_;
  }
  [[nodiscard]] double setpoint() const noexcept { return setpoint_; }
  void reset(double rpm = 0.0) noexcept { setpoint_ = rpm; }

 private:
  SpindleLimits l_;
  double setpoint_ = 0.0;
};

class Spindle {
 public:
  virtual ~Spindle() = default;
  // Requests a speed (clamped to the limits; 0 stops); returns the clamped target.
  virtual double set_speed(double rpm) noexcept = 0;
  virtual void stop() noexcept = 0;
  [[nodiscard]] virtual SpindleStatus status() const noexcept = 0;
  [[nodiscard]] virtual const SpindleLimits& limits() const noexcept = 0;
};

}  // namespace contour::drivers
