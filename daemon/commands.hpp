#pragma once
// Command socket protocol of contourd (handlers: Daemon::handle in daemon/commands.cpp).
// Request {"id": any, "cmd": name, ...}; reply {"id", "ok", "result"|"error"} (command_server.hpp).
//   status                                   state, positions, errors, timing statistics
//   load   {path | program [, name]}         validate (file:line:column errors, soft limits), plan;
//                                            program: at most socket.max_program_bytes
//   upload {name, offset, data [, final]}    a program of any size in chunks (each request one
//                                            socket line); offset 0 starts, final: true loads it
//                                            (reply as load, + bytes). Total <= max_program_bytes
//   run    [{path | program}]                start the loaded program (READY)
//   result {job}                             run figures: state, duration_s, max/rms_contour_error_um,
//                                            faults, overruns, ...
//   hold | resume | stop | estop | reset | enable | disable
//   jog    {axis, velocity_mm_min, distance_mm}     READY, no program loaded, target in limits
//   set-position | home {axis, position_mm}         DISABLED/READY (sim and absolute encoders)
//   gains  [{set: {kp, ki_per_s, kd_s, ff, cp, ci_per_s, cd_s, coupling}}]  validated, stability
//                                            checked, swapped at a cycle boundary in any state
//                                            (controller state kept, bumpless integral)
//   override {percent}                       feed override
//   record {action: start|stop [, name | path]}  telemetry CSV, only in telemetry.directory:
//                                            name = file name there, path must be inside it;
//                                            reply {recording, path (absolute), directory}
//   subscribe | unsubscribe {topic: telemetry|events}
//   force  [{enable: bool | action: on|off, reference_N}]   force control (needs `dynamometer:`);
//                                            no argument: force status
//   sim_gpio {line: role|name, level: 0|1}   gpio.backend sim only: set a simulated input's
//                                            physical level (e.g. press the E-stop: estop, 0)
//   shutdown                                 controlled stop, drives disabled, exit 0
// Unknown arguments, wrong types and out-of-range values are errors naming the argument.
#include <nlohmann/json.hpp>

#include "config/machine_config.hpp"
#include "daemon/command_server.hpp"

namespace contour::daemon {

// Axis by name ("X", case-insensitive) or index; throws CommandError.
int axis_index(const nlohmann::json& v, const config::MachineConfig& m);

}  // namespace contour::daemon
