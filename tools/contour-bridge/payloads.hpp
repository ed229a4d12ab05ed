#pragma once
// What contour-bridge publishes, built from the daemon's replies (pure functions, unit-tested):
// the MQTT payloads of `state`, `position`, `event`, and the classification of the daemon's event
// lines. Field names and meanings: tools/contour-bridge/README.md "Topics and payloads". Job
// summaries are NOT built here: `job/<n>` is the daemon's `result` reply verbatim, the object
// `contourctl --json run --wait` prints.
//
// Status fields the daemon may add later (issue 18: homed, tool, tool_change, rapid/spindle
// overrides, work offsets) are passed through when present and absent otherwise.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace contour::bridge {

// Wall clock (CLOCK_REALTIME) in microseconds since the epoch, and as ISO 8601 UTC with
// milliseconds ("2026-01-31T12:00:00.123Z", the SHDR timestamp form).
std::int64_t now_us();
std::string iso8601_utc(std::int64_t us);

struct Identity {
  std::string machine_id;
  std::vector<std::string> axes;  // axis names from the machine config, in order
};

// One line of the daemon's `events` subscription, classified.
struct DaemonEvent {
  std::string kind;  // transition fault emcy program_start program_end estop_request
                     // hold_request underrun spindle refused force gains limits socket log
  std::string text;
  std::uint64_t cycle = 0;  // from "cycle N: ..." (0 when the line has none)
  std::uint64_t job = 0;    // program_end: the job number
  bool completed = false;   // program_end: "done" (true) or "ended early" (false)
  std::string from, to;     // transition
  std::string cause;        // transition (when given), fault
  std::string name;         // program_start (synthesised by the bridge): the program's name
};

DaemonEvent classify_event(const nlohmann::json& line);

// MTConnect vocabulary for the daemon's state (used by the state payload and the SHDR items).
std::string execution_of(const nlohmann::json& status);        // READY ACTIVE FEED_HOLD ...
std::string controller_mode_of(const nlohmann::json& status);  // AUTOMATIC MANUAL ...

// Alarms: the active fault (status.fault / cause) as a list of {code, severity, axis, value,
// limit, text}; empty when the machine has none.
nlohmann::json alarms_of(const nlohmann::json& status);

// `state` payload without its time stamp (so that two snapshots compare equal when nothing an
// operator sees has changed); `available` false = the daemon's socket is unreachable.
nlohmann::json state_payload(const nlohmann::json& status, const Identity& id, bool available);

// `position` payload without its time stamp: machine (and work, when the status has offsets)
// coordinates, actual and commanded, plus path feed and contour error.
nlohmann::json position_payload(const nlohmann::json& status, const Identity& id);

// Largest per-axis distance between two status' actual positions (mm); infinity when either
// lacks positions.
double max_axis_move_mm(const nlohmann::json& a, const nlohmann::json& b);

// Path feed rate from the commanded axis velocities, mm/s.
double path_feed_mm_s(const nlohmann::json& status);

// `event` payload: the classified event plus seq (per bridge run, from 1, no gaps), the bridge
// run's id (`session`, its start time in us) and a time stamp.
nlohmann::json event_payload(const DaemonEvent& e, std::uint64_t seq, std::int64_t session,
                             const Identity& id, std::int64_t ts_us);

}  // namespace contour::bridge
