#pragma once
// `control:` section: axis controllers, coupling controller and contour-error model (seed 000).
// Schema (every key optional; defaults are the paper's Table 1 / §3 values):
//   control:
//     controller: ccc            # p | pid | ccc   (ccc = per-axis P + coupling C(z), Fig 2)
//     kp: [0.6, 0.6, 0.6]        # axial gains of the P and CCC controllers, one per axis
//     pid:                       # uncoupled PID baseline; paper's literal order P, D, I
//       kp: [0.69, 0.69, 0.6]
//       kd_s: [0.06, 0.06, 0.05]
//       ki_per_s: [0.03, 0.03, 0.02]
//     feed_forward: 0.0          # velocity feed-forward fraction 0..1 (paper: none)
//     velocity_limit_mm_min: []  # per-axis command limit as a velocity (K*u); empty = none
//     coupling:
//       cp: 15
//       ci_per_s: 300
//       cd_s: 0.3
//       remove_tangential_integral: true   # the fix for the paper's along-path integral
//     model: circle              # circle | nearest | linear (baselines for comparison)
//     window_rule: multi_step    # multi_step | literal (eq 8 taken literally: demo only)
//     window_capacity: 256       # stored reference points (>= max lag in points + 3)
//     delay_compensation: true   # Smith predictor for the bus transport delay
//     derivative:                # filtering of the derivative terms (kd_s, cd_s): CHATTER.md
//       model_blend_ms: 5        # D acts on model + F(encoder - model), F 2nd order; 0 = off
//       same_geometry: ahead     # never | ahead | always: coupling D on one circle/line
//       lowpass_ms: 0            # first-order low-pass on the D terms' outputs; 0 = off
#include <array>
#include <string>

#include "config/machine_config.hpp"
#include "config/yaml_reader.hpp"
#include "control/contour_error.hpp"
#include "control/loop_stability.hpp"
#include "control/servo_controller.hpp"

namespace contour::config {

enum class ControllerType { kP, kPid, kCcc };

struct ControlConfig {
  ControllerType controller = ControllerType::kCcc;
  std::array<double, 3> kp{0.6, 0.6, 0.6};
  std::array<double, 3> pid_kp{0.69, 0.69, 0.6};
  std::array<double, 3> pid_kd_s{0.06, 0.06, 0.05};
  std::array<double, 3> pid_ki_per_s{0.03, 0.03, 0.02};
  double feed_forward = 0.0;
  std::array<double, 3> velocity_limit_mm_min{0.0, 0.0, 0.0};  // 0 = none
  control::CouplingGains coupling{};
  control::ModelKind model = control::ModelKind::kCircle;
  control::WindowRule window_rule = control::WindowRule::kMultiStep;
  int window_capacity = 256;
  bool delay_compensation = true;
  // Documented defaults (control/CHATTER.md): model blend 5 ms, same geometry while ahead.
  control::DerivativeFilter derivative{0.005, control::SameGeometry::kAhead, 0.0};
};

ControllerType parse_controller_type(const std::string& name);  // throws std::invalid_argument
const char* controller_type_name(ControllerType t);

ControlConfig parse_control(Section& s);

// Builds the servo parameters for `type` (overriding cfg.controller) for the given drives
// (gain, tau, period) and bus delay. velocity limits become u_max = v_max / K.
control::ServoParams make_servo_params(const ControlConfig& cfg, ControllerType type,
                                       const std::array<control::FeedDriveParams, 3>& drives,
                                       int axes, double period_s, int delay_cycles);
control::ContourErrorParams make_model_params(const ControlConfig& cfg);

// The loop the stability check simulates (control/loop_stability.hpp), from the machine section:
// each axis' drive model (sim: gain, tau, delay_cycles, blu) as the real plant, its velocity and
// acceleration limits, and the configured tau as the daemon's acceleration-clamp time constant.
// A measured plant (`contourctl identify`) replaces gain_per_s / tau_s / delay_cycles afterwards.
control::LoopPlant make_loop_plant(const MachineConfig& m);

}  // namespace contour::config
