#pragma once
// Sections read by the daemon itself: `loop:`, `safety:`, `telemetry:`, `socket:`, `log:`.
#include <string>

#include "config/yaml_reader.hpp"

namespace contour::config {

struct LoopConfig {
  int period_us = 1000;          // servo period (also the interpolation period)
  int priority = 80;             // SCHED_FIFO priority
  int cpu = -1;                  // CPU affinity of the RT thread; -1 = none
  bool require_realtime = false; // refuse to start when SCHED_FIFO / mlockall are not permitted
  bool lock_memory = true;
  int tpdo_deadline_us = 750;    // receive deadline for TPDOs inside the cycle
};

struct SafetyConfig {
  // Following-error band like LinuxCNC's MIN_FERROR/FERROR: allowed error grows linearly with speed
  // from min_ferror_mm at standstill to ferror_mm at max_velocity.
  double ferror_mm = 1.0;
  double min_ferror_mm = 0.1;
  double contour_error_limit_mm = 0.5;
  int missed_tpdo_streak = 3;          // consecutive missed TPDOs of one node -> FAULT
  double stop_decel_mm_s2 = 1000.0;    // controlled-stop deceleration along the path
  double jog_max_velocity_mm_min = 3000.0;
  // Continuous jog dead-man: the jog brakes when the client that started it disconnects or sends
  // nothing (any request renews it) for this long. Needs a restart.
  double jog_deadman_ms = 500.0;
  // Power stages are switched off only at standstill (issue 16): after a controlled stop, a
  // `disable` or SIGTERM the drives stay enabled with a zero command until every axis' measured
  // speed has stayed below standstill_velocity_mm_s for standstill_time_s; if that does not happen
  // within standstill_timeout_s the drives get the CiA 402 quick stop (their own ramp, 0x6085, then
  // disabled by the drive at standstill: quick stop option code 0x605A) and the log says which axis
  // still moved.
  double standstill_velocity_mm_s = 1.0;
  double standstill_time_s = 0.05;
  double standstill_timeout_s = 2.0;
  // Run-time limit-cycle / chatter watchdog (issue 16; control::ChatterMonitor, control/CHATTER.md):
  // per axis over a sliding window, the RMS cycle-to-cycle change of the velocity command and the
  // rate of clamped cycles. Above a warning level for warn_s: a warning event; above a fault level
  // for fault_s: FAULT "limit cycle" naming the axis and the figure. YAML: safety.chatter.
  struct Chatter {
    bool enable = true;
    double window_s = 0.1;             // window_ms
    double warn_mm_s = 5.0;            // RMS |dv| per cycle, mm/s
    double warn_clamps_per_s = 50.0;
    double warn_s = 0.25;              // warn_ms
    double fault_mm_s = 40.0;
    double fault_clamps_per_s = 300.0;
    double fault_s = 0.5;              // fault_ms
  } chatter;
};

struct TelemetryConfig {
  std::string directory = "/var/lib/contourd/records";
  int decimation = 1;              // one sample every N cycles
  int ring_capacity = 65536;       // samples (power of two)
};

struct SocketConfig {
  std::string path = "/run/contourd/contourd.sock";
  int mode = 0660;                 // octal in YAML as a string "0660" or number 432
  std::string group;
  int max_clients = 16;            // a full table never refuses: the longest-idle client gives way
  int max_line_bytes = 65536;
  double idle_timeout_s = 60.0;    // no complete request this long: dropped (subscribers exempt)
  int max_requests_per_s = 500;    // per client (1 s burst); estop/hold/stop are never refused
  int max_buffered_bytes = 4 << 20;  // per client: replies/events unread beyond this: dropped
  // Largest part program `load {program}` / the chunked `upload` accepts (bytes of text).
  long max_program_bytes = 16L << 20;
};

struct LogConfig {
  std::string level = "info";      // trace|debug|info|warn|error
  bool journald_format = false;    // no timestamps/colour, level as syslog prefix <N>
};

LoopConfig parse_loop(Section& s);
SafetyConfig parse_safety(Section& s);
TelemetryConfig parse_telemetry(Section& s);
SocketConfig parse_socket(Section& s);
LogConfig parse_log(Section& s);

}  // namespace contour::config
