#pragma once
// 2-DOF cutting-force / position controller, RUNTIME part (seed 001). See force_2dof.hpp for the
// design and the paper's equations.
//
// Per cycle (step()): inputs averaged force (N, from the dynamometer channel, with a validity flag
// and the sample age), path progress (mm), force reference (N) and planned progress (mm); outputs
// the feed override (the interpolator's path-speed scale, fraction: 1.0 = 100 %) and the spindle
// speed command (rpm).
//   u = u_ff + u_fb + bias;  u_ff, y_M from the one stable feed-forward filter of the reference r;
//   u_fb = F x^ from the observer-based C2 acting on m = zeta + T (y - y_M).
// - Both outputs are clamped to their ranges and rate limits. Anti-windup: the observer is driven
//   by the input that was actually applied, and the integrator part (zeta and its estimate) is
//   moved back by F_z^-1 (u_applied - u_wanted) so the controller never asks for more than the
//   actuator gave (without it a 20 ms force pulse winds the integrators far past the limits).
// - Bumpless enable: the reference model starts at the measured force/progress and the current
//   feed rate; the remaining output mismatch is a bias that decays with bumpless_tau_s. Disable:
//   the outputs slew from where they are to the programmed feed (override 1.0) and nominal
//   spindle speed at the rate limits.
// - Force ceiling: a valid sample >= force_ceiling_N requests feed hold at once (override 0,
//   spindle held), regardless of the controller; latched until enable() is called again.
// - Stale/invalid force (flag false, non-finite, or age > stale_age_s): fallback kHold = feed
//   hold (override 0, spindle held), kProgrammedFeed = force control off, override slews to 1.0
//   and spindle to nominal. Latched until enable().
// RT: step() is noexcept, allocation-free (fixed-size Eigen), O(1): ~50 multiply-adds of 5x5.
// configure() may allocate nothing but is setup-time (it copies the design). Time budget: < 2 us.
#include <Eigen/Dense>
#include <cstdint>
#include <vector>

#include "control/force_2dof.hpp"

namespace contour::control {

enum class ForceFallback { kHold, kProgrammedFeed };

enum class ForceStatus : std::uint8_t {
  kNotConfigured,   // configure() never called: outputs programmed feed / nominal spindle
  kDisabled,        // force control off (outputs slewing to / at programmed values)
  kActive,          // controlling, no limit active
  kSaturated,       // controlling, an output is at a range or rate limit
  kCeilingHold,     // force >= ceiling: feed hold requested (latched)
  kStaleHold,       // force sample stale/invalid, fallback = hold (latched)
  kStaleProgrammed, // force sample stale/invalid, fallback = programmed feed (latched)
};

const char* to_string(ForceStatus s) noexcept;

struct ForceLimits {
  double override_min = 0.0;           // fraction (0.0 = 0 %)
  double override_max = 1.5;           // fraction
  double override_rate_per_s = 10.0;   // max |d override/dt|, fraction per second
  double spindle_nominal_rpm = 3000.0; // u2 = 0
  double spindle_rpm_per_unit = 1000.0;  // rpm per unit of the plant's spindle command u2
  double spindle_min_rpm = 500.0;
  double spindle_max_rpm = 6000.0;
  double spindle_rate_rpm_s = 6000.0;  // 0 -> 6000 rpm in 1 s (vector/servo spindle drive)
  double force_ceiling_N = 3.0;
  double stale_age_s = 0.02;
  ForceFallback fallback = ForceFallback::kHold;
  double bumpless_tau_s = 0.1;
  bool anti_windup = true;  // off only to demonstrate wind-up (tests, contour-sim)
};

struct ForceInput {
  double force_ref_N = 0.0;
  double planned_progress_mm = 0.0;
  double force_N = 0.0;
  double progress_mm = 0.0;
  bool force_valid = true;
  double force_age_s = 0.0;
};

struct ForceOutput {
  double feed_override = 1.0;
  double spindle_rpm = 0.0;
  bool feed_hold_request = false;
  ForceStatus status = ForceStatus::kNotConfigured;
};

struct ForceEnableState {
  double feed_override = 1.0;   // override being applied now
  double spindle_rpm = 0.0;     // spindle speed commanded now
  double force_N = 0.0;         // measured averaged force now
  double progress_mm = 0.0;     // progress now
};

class ForceController {
 public:
  ForceController() = default;
  // Setup time. Throws std::invalid_argument on inconsistent limits.
  void configure(const ForceDesign& design, const ForceLimits& limits);
  // Switch force control on from the current machine state (bumpless). Clears latched holds.
  void enable(const ForceEnableState& s) noexcept;
  // Switch off: outputs slew to programmed feed / nominal spindle.
  void disable() noexcept;
  [[nodiscard]] ForceOutput step(const ForceInput& in) noexcept;

  [[nodiscard]] bool active() const noexcept { return active_; }
  [[nodiscard]] const ForceLimits& limits() const noexcept { return lim_; }
  // Reference model output of the last step (force N, progress mm), for logging/telemetry.
  [[nodiscard]] Eigen::Vector2d model_output() const noexcept { return y_model_; }

 private:
  enum class Latch : std::uint8_t { kNone, kCeiling, kStaleHold, kStaleProgrammed };
  [[nodiscard]] ForceOutput passive_step() noexcept;
  void apply_limits(double want_override, double want_rpm, double& got_override,
                    double& got_rpm) const noexcept;

  bool configured_ = false;
  bool active_ = false;
  bool need_bias_ = false;
  Latch latch_ = Latch::kNone;
  double t_ = 0.001;
  double bias_decay_ = 0.0;
  ForceLimits lim_{};
  double tau_m_s_ = 0.2;
  PositionModel position_model_ = PositionModel::kType2;
  double k_f_N_ = 1.0, k_v_mm_s_ = 1.0;
  Eigen::Matrix<double, 5, 5> ff_a_, aug_a_;
  Eigen::Matrix<double, 5, 2> ff_b_, aug_b_, h_;
  Eigen::Matrix<double, 2, 5> ff_cu_, ff_cy_, aug_c_, f_;
  Eigen::Matrix2d ff_du_, fz_inv_;
  // State.
  Eigen::Matrix<double, 5, 1> w_ = Eigen::Matrix<double, 5, 1>::Zero();
  Eigen::Matrix<double, 5, 1> xh_ = Eigen::Matrix<double, 5, 1>::Zero();
  Eigen::Vector2d zeta_ = Eigen::Vector2d::Zero();
  Eigen::Vector2d bias_ = Eigen::Vector2d::Zero();
  Eigen::Vector2d y_model_ = Eigen::Vector2d::Zero();
  double override_ = 1.0;   // last applied
  double rpm_ = 0.0;        // last applied
};

}  // namespace contour::control

namespace contour::control {

// ---- Closed-loop scenarios of the paper's section 4 (Figs 4.1-4.5), for contour-sim and tests.
// Setup-time tool (allocates the traces). Deterministic for a given seed.
enum class ForceScenarioKind { kTrack, kImpulse, kStep, kModelError, kNoise };

struct ForceScenario {
  ForceScenarioKind kind = ForceScenarioKind::kStep;
  double duration_s = 10.0;
  double force_ref_N = 1.0;        // first force reference level
  double feed_mm_s = 4.5;          // planned path speed (ramp slope)
  double disturbance_N = 0.5;      // step (kStep) / pulse amplitude (kImpulse) at disturbance_at_s
  double disturbance_at_s = 5.0;
  double pulse_s = 0.02;           // kImpulse pulse width
  double noise_sigma_N = 0.02;     // kNoise (and kTrack when > 0 and add_noise)
  bool add_noise = false;
  std::uint32_t seed = 1;
  ForcePlantParams true_plant{};   // the simulated process (kModelError: perturbed by the caller)
  ForceLimits limits{};
};

struct ForceTrace {
  std::vector<double> t_s, force_N, force_ref_N, force_model_N, progress_mm, plan_mm, feed_override,
      spindle_rpm;
};

struct ForceMetrics {
  bool stable = false;
  double force_settling_s = 0.0;     // first step of the reference, 2 % band of the step
  double force_overshoot_pct = 0.0;  // first step, relative to the step
  double force_rms_error = 0.0;      // vs the force reference, whole run
  double force_rms_error_vs_model = 0.0;
  double position_rms_error_mm = 0.0;  // vs the planned ramp, whole run
  double position_ramp_lag_mm = 0.0;   // mean (plan - progress) over the last second before the
                                       // disturbance (or the end of the run)
  double disturbance_recovery_s = 0.0; // from the disturbance until |F - ref| <= 2 % of ref for good
  // kStep only: a lower bound on disturbance_recovery_s for ANY controller under sc.limits: the
  // first time the force can enter the 2 % band at all, with the override driven to its extreme
  // and the spindle to its extreme at their rate limits from the disturbance on (the plant's step
  // responses are monotone, so no other admissible input gets there earlier). 0 when the
  // disturbance is within the band; 1e9 when the band is unreachable within the limits.
  double disturbance_recovery_bound_s = 0.0;
  double steady_force_error = 0.0;     // max |F - ref| over that last second
};

ForceMetrics run_force_scenario(const ForceDesign& d, const ForceScenario& sc,
                                ForceTrace* trace = nullptr);

}  // namespace contour::control
