#pragma once
// `spindle:` section (issue 8). Absent -> type none.
//
// spindle:
//   type: modbus_vfd          # none | canopen | modbus_vfd | sim
//   node_id: 5                # canopen (CiA 402 velocity mode): must be bus.spindle's node_id
//   sim_tau_s: 0.2            # speed lag of the simulated spindle (type sim; the SimBus model
//                             # of a canopen spindle in offline runs)
//   min_rpm: 500
//   max_rpm: 12000
//   rate_rpm_s: 2000
//   at_speed_tolerance_rpm: 50
//   at_speed_tolerance_pct: 2
//   at_speed_timeout_s: 10    # a feed move waits at most this long for at-speed, then FAULT
//   at_speed_wait: always     # always | force (only with force control on) | never
//   override_min_percent: 50  # spindle override range (`override --spindle`; 100 % must be in it)
//   override_max_percent: 100
//   vfd:                      # modbus_vfd
//     transport: rtu          # rtu | tcp
//     device: /dev/ttyUSB1
//     baud: 19200
//     parity: even
//     host: 127.0.0.1         # tcp
//     port: 502
//     unit_id: 1
//     timeout_ms: 50
//     update_rate_hz: 20
//     setpoint_register: 0
//     setpoint_counts_per_rpm: 1.0
//     run: {kind: register, address: 1, forward: 1, reverse: 2, stop: 0}   # kind: register | coil
//     actual_register: 2
//     actual_function: holding   # holding | input
//     actual_counts_per_rpm: 1.0
#include <string>

#include "config/yaml_reader.hpp"
#include "drivers/modbus/vfd_spindle.hpp"
#include "drivers/spindle.hpp"

namespace contour::config {

struct SpindleConfig {
  std::string type = "none";
  int node_id = 0;  // canopen
  drivers::SpindleLimits limits{};
  double at_speed_timeout_s = 10.0;
  enum class Wait { kAlways, kForce, kNever };
  Wait at_speed_wait = Wait::kAlways;
  double sim_tau_s = 0.2;
  // Spindle override range, percent of the programmed speed (LinuxCNC's MIN/MAX_SPINDLE_OVERRIDE
  // defaults); the overridden speed is still clamped to min_rpm..max_rpm.
  double override_min_percent = 50.0;
  double override_max_percent = 100.0;
  drivers::modbus::VfdSettings vfd{};  // modbus_vfd; vfd.limits == limits
};

SpindleConfig parse_spindle(Section& s);

}  // namespace contour::config
