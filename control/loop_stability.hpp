#pragma once
// Stability check of a gain set against the loop the daemon really runs (issue 16 "Gains that
// cannot make the machine oscillate"). Round 1 checked only loop_margin(): the linear loop in the
// direction normal to the path, where axis and coupling controllers add up. `gains set
// axis.x.kp=50` passed it (spectral radius 0.995) and the axis then limit-cycled at standstill
// (+-15 um, command -60..+61 mm/s, ~660 acceleration clamps per second): along the path only the
// axis gain acts, and P alone at Kp K = 6000 1/s with tau = 30 ms is unstable; the clamps then
// turn the growing oscillation into a limit cycle.
//
// The check has two parts; a gain set passes only if both pass for every axis, for the nominal
// plant and for each corner of the plant mismatch margin (the controller keeps its nominal model):
//
// 1. Linear: the closed-loop state matrix of one axis in each of the two directions the loop has:
//    across the path (axis law + coupling C(z)) and along it (axis law alone; the coupling
//    integrator has no along-path part). It holds the true plant K/(s(tau s+1)) with its own
//    transport delay, the controller's Smith predictor with the nominal model and delay, the
//    derivative filters (model blend, low-pass) and the integrators. Spectral radius < 1 -
//    kRadiusMargin.
// 2. Closed-loop simulation with the real code: ServoController, ContourErrorModel, FeedDrive
//    plants quantised to the BLU, and the daemon's control stage (daemon/servo_loop.cpp
//    control_step: v = K u, |v| <= v_max, v within v_actual +- a_max tau). Scenarios: holding an
//    off-grid position, a 0.2 mm move along each axis then rest (the window stays on the path:
//    along-path regime for that axis), and a move along the space diagonal. After the settling
//    time, over the last 0.3 s, an axis that still moves more than 4 BLU peak to peak, clamps, or
//    whose command changes by more than 2 mm/s RMS is oscillating.
//
// Mismatch margin (StabilityOptions): the plant's gain x(1 +- 10 %) and time constant
// x(1 +- 20 %) one at a time, with the configured model in the controller. Why these: the
// identification (system_identification.hpp) gives K and tau to 2 %; drive tuning and load
// change them further; Table 1 gains with the predictor stay stable to 1.6x on K alone. The
// transport delay is NOT varied: a one-cycle error of the predictor's delay makes the Table 1
// CCC limit-cycle (+-28 um at rest), so the check takes the delay it is given: the configured
// one, or the measured one (`contourctl identify`) to expose a mismatch.
//
// Cost: ~25 short simulations of 0.9 s and ~20 eigenvalue problems of size <= 40; well under
// 100 ms (measured: control/CHATTER.md). Setup-time (allocates); never on the RT thread.
#include <array>
#include <string>

#include "control/servo_controller.hpp"

namespace contour::control {

// One axis as the loop drives it.
struct AxisPlant {
  double gain_per_s = 120.0;       // K of the real drive (velocity gain x the loop's K_cmd)
  double tau_s = 0.030;            // real velocity-loop time constant
  int delay_cycles = 1;            // real transport delay, FeedDrive convention
  double blu_mm = 0.0005;          // encoder resolution
  double max_velocity_mm_s = 10000.0 / 60.0;
  double max_accel_mm_s2 = 2000.0;
  double clamp_tau_s = 0.030;      // the tau the daemon's acceleration clamp uses (configured)
};

struct LoopPlant {
  int axes = 3;
  std::array<AxisPlant, kMaxServoAxes> axis{};
  // True when the caller feeds the clamped command back (ServoController::command_applied).
  bool controller_sees_clamps = false;
};

struct StabilityOptions {
  double gain_margin = 0.10;      // plant K x (1 +- gain_margin)
  double tau_margin = 0.20;       // plant tau x (1 +- tau_margin)
  bool simulate = true;           // part 2 (part 1 always runs)
  std::array<char, kMaxServoAxes> axis_names{'X', 'Y', 'Z'};
};

struct StabilityVerdict {
  bool stable = true;
  std::string reason;             // empty when stable; else names the axis, case and figure
  int axis = -1;                  // the axis the reason names
  // Worst figures over every axis, direction, scenario and mismatch corner.
  double spectral_radius = 0.0;   // linear part
  double rest_peak_to_peak_um = 0.0;
  double rest_chatter_mm_s = 0.0; // RMS command change over the judged window
  double rest_clamps_per_s = 0.0;
  int linear_cases = 0;           // how many matrices / simulations were checked
  int simulations = 0;
};

inline constexpr double kRadiusMargin = 1e-6;

// `p` as ServoController::validate accepts it (else std::invalid_argument is thrown); `plant`
// with 1..3 axes, positive gains and time constants >= 0 (else std::invalid_argument).
StabilityVerdict check_loop_stability(const ServoParams& p, const LoopPlant& plant,
                                      const StabilityOptions& opt = {});

// The linear part alone for one axis and direction (along = true: the along-path loop) with the
// plant scaled by gain_scale / tau_scale: the closed-loop spectral radius.
double loop_spectral_radius(const ServoParams& p, int axis, const AxisPlant& plant, bool along,
                            double gain_scale = 1.0, double tau_scale = 1.0);

}  // namespace contour::control
