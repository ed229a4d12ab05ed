#pragma once
// The command set of contourd's socket, declared once (issue 15 "One command table"): each
// command's name, its arguments (type, range, required), the states it is allowed in, whether it
// is a safety command (never refused for load reasons), and a summary. From this table:
//   - Daemon::handle dispatches (daemon/commands.cpp: one handler per CommandId; the compiler's
//     switch check keeps table and handlers in step) after validate_request() has refused unknown
//     arguments, wrong types and out-of-range values;
//   - `contourd --protocol` prints daemon/PROTOCOL.md (a test keeps the checked-in file equal);
//   - `contourctl --help` lists the socket commands with the same summaries;
//   - the command server exempts safety commands from its per-client limits, and gateways
//     (WebSocket, MQTT) take names, arguments and states from here.
// Pure data and validation: no Daemon, no I/O. Non-RT.
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/machine_state.hpp"

namespace contour::daemon {

enum class CommandId : std::uint8_t {
  kStatus, kLoad, kUpload, kRun, kResult, kHold, kResume, kStop, kEstop, kReset, kEnable, kDisable, kJog,
  kSetPosition, kHome, kGains, kOverride, kRecord, kSubscribe, kUnsubscribe, kForce, kSimGpio,
  kShutdown, kIo, kPlcStatus, kOffsets, kTools, kTouchOff, kMdi, kIdentify, kSwitches,
};

enum class ArgType : std::uint8_t {
  kNumber,     // finite number, within [lo, hi] (or the bound resolved at run time)
  kJobNumber,  // unsigned integer
  kString,
  kBool,
  kAxis,       // axis name ("X", case-insensitive) or index
  kObject,     // non-empty JSON object (checked further by the handler)
  kChoice,     // one of `choices` (a '|'-separated list)
  kLevel,      // 0, 1, true or false
  kAny,
};

// A range that depends on the running configuration (resolved by the daemon).
enum class Bound : std::uint8_t {
  kStatic,           // [lo, hi] as declared
  kJogVelocity,      // [1e-3, safety.jog_max_velocity_mm_min]
  kAxisPosition,     // the soft limits of the request's axis
  kOverridePercent,  // [0, interpolator.feed_override_max_percent]
  kRapidOverridePercent,    // [0, interpolator.rapid_override_max_percent]
  kSpindleOverridePercent,  // [spindle.override_min_percent, spindle.override_max_percent]
  kForceReference,   // [0, force.limits.force_ceiling_N]
};

struct ArgSpec {
  std::string_view name;
  ArgType type = ArgType::kAny;
  bool required = false;
  std::string_view expect;   // wrong type: "argument '<name>' must be <expect>"
  std::string_view help;
  double lo = -std::numeric_limits<double>::infinity();
  double hi = std::numeric_limits<double>::infinity();
  Bound bound = Bound::kStatic;
  std::string_view choices;  // kChoice: "start|stop"
};

[[nodiscard]] constexpr std::uint8_t state_bit(MachineState s) noexcept {
  return static_cast<std::uint8_t>(1U << static_cast<unsigned>(s));
}
inline constexpr std::uint8_t kAnyState = 0x7F;

struct CommandSpec {
  CommandId id = CommandId::kStatus;
  std::string_view name;
  std::string_view summary;
  std::vector<ArgSpec> args;
  std::uint8_t states = kAnyState;  // states in which the command can take effect
  // The dispatcher itself refuses other states ("<name> is not allowed in state S"); otherwise
  // the handler checks (its messages say more, e.g. "with a program loaded").
  bool gate = false;
  bool safety = false;      // estop, hold, stop: never refused for load or rate reasons
  std::string_view states_text;  // the rule in words, for the protocol document
  std::string_view reply;        // what the result holds
};

// The whole table, in the order of the protocol document.
const std::vector<CommandSpec>& command_table();
// nullptr for an unknown name.
const CommandSpec* find_command(std::string_view name);
[[nodiscard]] bool is_safety_command(std::string_view name);

// Resolves a run-time bound for a request (the daemon's configuration): {lo, hi}.
using BoundResolver = std::function<std::pair<double, double>(Bound, const nlohmann::json& req)>;

// Refuses, with CommandError and the same texts the handlers always used:
//   "unknown argument 'k'", "missing argument 'k'", "argument 'k' must be <expect>",
//   "argument 'k' = v out of range [lo, hi]". Keys "id" and "cmd" are the envelope.
void validate_request(const CommandSpec& spec, const nlohmann::json& req, const BoundResolver& bounds);
// "<name> is not allowed in state S" when the spec gates states and `st` is not allowed.
void check_state(const CommandSpec& spec, MachineState st);

// daemon/PROTOCOL.md (Markdown), generated from the table.
std::string protocol_markdown();
// One line per command: "  name  summary" (contourctl --help footer).
std::string command_summary_text();

}  // namespace contour::daemon
