#pragma once
// `force:` section — the 2-DOF cutting-force / position controller (seed 001, issue 5).
// The dynamometer endpoint and signal filter are in `dynamometer:` (not here).
//
// force:
//   enable: false                # force control on at start-up
//   reference_N: 1.0             # force reference (N)
//   plant:                       # identified cutting process (paper eq 3.8 by default)
//     k_f_N: 1.0                 # force per unit feed override (1.0 = 100 %)
//     tau_f_ms: 600
//     k_s_N: -1.0                # force per unit spindle command (see spindle.rpm_per_unit)
//     tau_s_ms: 800
//     k_v_mm_s: 4.5              # path speed at 100 % override
//     spindle_pole: physical     # physical: -1/(0.8s+1) | printed: -1/(-0.8s+1) (eq 3.8 as printed)
//   reference_model:
//     tau_m_ms: 200              # < tau_f, tau_s (eq 3.6)
//     position: type2            # type2: (2 tau s+1)/(tau s+1)^2 (no ramp lag) | paper: 1/(tau s+1)^2
//   design:                      # LQR / Kalman weights, normalised units (see force_2dof.hpp)
//     q_force, q_position, q_force_integral, q_position_integral, r_feed, r_spindle,
//     observer_input_noise, observer_state_noise, observer_measurement_noise
//   limits:
//     override_min_pct: 0, override_max_pct: 150, override_rate_pct_s: 1000,
//     force_ceiling_N: 3.0
//   spindle:
//     nominal_rpm: 3000, rpm_per_unit: 1000, min_rpm: 500, max_rpm: 6000, rate_rpm_s: 6000
//   fallback: hold               # hold (feed hold) | programmed_feed (force control off) |
//                                # fault (FAULT "stale force sample": controlled stop)
//   stale_ms: 20                 # a force sample older than this is stale
//   bumpless_ms: 100
#include "config/yaml_reader.hpp"
#include "control/force_2dof.hpp"
#include "control/force_controller.hpp"

namespace contour::config {

struct ForceConfig {
  bool enable = false;
  double reference_N = 1.0;
  control::ForceDesignParams design{};  // period_s is taken from machine.period_ms by the user
  control::ForceLimits limits{};
  bool stale_faults = false;  // fallback: fault
};

ForceConfig parse_force(Section& s);

}  // namespace contour::config
