#pragma once
// The servo loop's `channels` stage: the spindle and the cutting-force channel, each a unit with
// its own state and one step() per cycle (daemon/servo_loop.hpp). noexcept, allocation-free.
//
// ForceChannel (seed 001): while a program runs with force control requested, the 2-DOF
// controller (control/force_controller.hpp) turns the dynamometer's force into a feed override
// (applied by the interpolator from the NEXT cycle) and a spindle speed; a stale or invalid
// sample latches the configured fallback. SpindleChannel (issue 8): the requested speed clamped to
// spindle: min/max_rpm, slewed at rate_rpm_s while the drives are on, and the at-speed judgement
// from the fed-back speed. Units: N, rpm, mm, s.
#include <cstdint>

#include "config/config.hpp"
#include "control/force_controller.hpp"
#include "daemon/axis_bus.hpp"
#include "daemon/io_channels.hpp"
#include "daemon/loop_stages.hpp"
#include "drivers/spindle.hpp"

namespace contour::daemon {

class ForceChannel {
 public:
  struct Inputs {
    bool in_program = false;      // RUNNING/HOLD with a program attached
    bool running = false;         // RUNNING, not stopping, not waiting for the spindle
    double programmed_rpm = 0.0;  // signed, from the program (0 outside a program)
    double feed_override = 1.0;   // the user's override (planned progress ramp)
    double progress_mm = 0.0;     // interpolator path progress
  };
  // What happened in a step (the loop turns it into events, in this order).
  struct Events {
    bool on = false;          // engaged (value: reference N)
    bool off = false;
    bool fallback = false;    // stale/invalid sample: the fallback latched
    bool ceiling = false;     // entered the ceiling hold
    bool recovered = false;   // a valid sample again after a fallback
  };

  ForceChannel() = default;
  // configured: there is a force source (RtIo with a dynamometer). Throws std::invalid_argument
  // on a bad force design.
  ForceChannel(const config::Config& cfg, bool configured);

  Events step(const Inputs& in, const Feedback& fb, double period_s) noexcept;
  // `force` command: on = 1 / 0 / -1 (unchanged), reference N (NaN = unchanged). Returns true when
  // the controller was switched off by it (a kForceOff event).
  bool command(int on, double reference_N) noexcept;
  // `reset`: a latched fallback is cleared.
  void clear_fallback() noexcept { fallback_ = false; }

  [[nodiscard]] bool configured() const noexcept { return configured_; }
  [[nodiscard]] bool requested() const noexcept { return requested_; }
  [[nodiscard]] bool active() const noexcept { return force_.active(); }
  [[nodiscard]] bool fallback() const noexcept { return fallback_; }
  [[nodiscard]] std::uint64_t fallbacks() const noexcept { return fallbacks_; }
  [[nodiscard]] double reference_N() const noexcept { return ref_N_; }
  [[nodiscard]] double feed_override() const noexcept { return override_; }
  [[nodiscard]] control::ForceStatus status() const noexcept { return fout_.status; }
  // Signed spindle speed requested by the program or the controller, before the spindle limits.
  [[nodiscard]] double spindle_rpm_cmd() const noexcept { return spindle_rpm_cmd_; }
  // A fresh run: the planned progress restarts.
  void restart_progress() noexcept { planned_progress_mm_ = 0.0; }
  [[nodiscard]] const control::ForceLimits& limits() const noexcept { return lim_; }

 private:
  bool configured_ = false;
  control::ForceController force_;
  control::ForceLimits lim_{};
  double k_v_mm_s_ = 0.0;  // design path speed at 100 % override (force.plant.k_v_mm_s)
  bool requested_ = false;
  double ref_N_ = 0.0;
  double planned_progress_mm_ = 0.0;
  control::ForceOutput fout_{};
  double override_ = 1.0;
  bool fallback_ = false;
  bool ok_prev_ = true;
  std::uint64_t fallbacks_ = 0;
  double spindle_rpm_cmd_ = 0.0;
};

class SpindleChannel {
 public:
  SpindleChannel() = default;
  SpindleChannel(const config::SpindleConfig& cfg, bool present) noexcept
      : present_(present), limits_(cfg.limits), ramp_(cfg.limits) {}

  // rpm_cmd: signed request before the limits; mode: the drives' mode this cycle. A VFD spindle
  // (io->has_spindle()) gets the ramped command and its status is written into `fb` (the
  // snapshot's spindle feedback). Returns the ramped command for the bus (0 when disabled).
  double step(double rpm_cmd, DriveMode mode, SpindleFeedback& fb, RtIo* io, double period_s) noexcept;

  [[nodiscard]] bool present() const noexcept { return present_; }
  [[nodiscard]] double target_rpm() const noexcept { return target_rpm_; }
  [[nodiscard]] double out_rpm() const noexcept { return out_rpm_; }
  [[nodiscard]] bool at_speed() const noexcept { return at_speed_; }
  [[nodiscard]] const drivers::SpindleLimits& limits() const noexcept { return limits_; }

 private:
  bool present_ = false;
  drivers::SpindleLimits limits_{};
  drivers::SpindleRamp ramp_{drivers::SpindleLimits{}};
  double target_rpm_ = 0.0;
  double out_rpm_ = 0.0;
  bool at_speed_ = false;
};

}  // namespace contour::daemon
