#include "daemon/command_table.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <tuple>

#include "daemon/command_protocol.hpp"

namespace contour::daemon {

namespace {

using nlohmann::json;
using S = MachineState;

constexpr std::uint8_t bits(std::initializer_list<MachineState> ss) {
  std::uint8_t m = 0;
  for (MachineState s : ss) m = static_cast<std::uint8_t>(m | state_bit(s));
  return m;
}

ArgSpec number(std::string_view name, bool required, double lo, double hi, std::string_view help,
               Bound b = Bound::kStatic) {
  ArgSpec a;
  a.name = name;
  a.type = ArgType::kNumber;
  a.required = required;
  a.expect = "a number";
  a.lo = lo;
  a.hi = hi;
  a.bound = b;
  a.help = help;
  return a;
}

ArgSpec typed(std::string_view name, ArgType t, bool required, std::string_view expect,
              std::string_view help, std::string_view choices = {}) {
  ArgSpec a;
  a.name = name;
  a.type = t;
  a.required = required;
  a.expect = expect;
  a.help = help;
  a.choices = choices;
  return a;
}

constexpr double kInf = std::numeric_limits<double>::infinity();

std::vector<CommandSpec> build_table() {
  std::vector<CommandSpec> t;
  auto add = [&t](CommandSpec c) { t.push_back(std::move(c)); };
  const ArgSpec path = typed("path", ArgType::kString, false, "a string",
                             "part program file on the daemon's host");
  const ArgSpec program = typed("program", ArgType::kString, false, "a string", "part program text");
  const ArgSpec name = typed("name", ArgType::kString, false, "a string",
                             "name of an inline program in messages");
  add({CommandId::kStatus, "status", "machine state, positions, errors, loop timing", {}, kAnyState,
       false, false, "any", "the status object"});
  const ArgSpec start_line = typed(
      "start_line", ArgType::kJobNumber, false, "a line number (1: the first line)",
      "run from line: lines before it set the modal state only; the run starts with a safe approach "
      "(up to the clearance, across, down at the modal feed) to where that line begins");
  const ArgSpec preview = typed("preview", ArgType::kBool, false, "true or false",
                                "also plan the whole program once and reply its extents, time, blocks, tools and path");
  add({CommandId::kLoad, "load",
       "validate (file:line:column errors, soft limits) and plan a part program",
       {path, program, name, preview, start_line}, bits({S::kReady}), false, false,
       "READY, not jogging; exactly one of path / program",
       "{job, name, lines, motion_blocks, length_mm}; preview: also {blocks, tools, estimated_time_s, "
       "extents: {machine|work: {X: [min, max], ...}}, path_mm: [[x, y, z], ...]}"});
  {
    ArgSpec off = typed("offset", ArgType::kJobNumber, true, "a byte offset (0 starts an upload)",
                        "bytes received so far: 0 starts, each chunk continues exactly");
    add({CommandId::kUpload, "upload",
         "a part program of any size by content, in chunks of one socket line each; the final "
         "chunk loads it like `load` (limit socket.max_program_bytes)",
         {typed("name", ArgType::kString, true, "a non-empty string", "the program's name"), off,
          typed("data", ArgType::kString, true, "a string", "the next chunk of the program text"),
          typed("final", ArgType::kBool, false, "true or false", "last chunk: load the program"),
          preview, start_line},
         bits({S::kReady}), false, false, "READY for the final chunk (one upload at a time)",
         "{name, bytes, complete}; final: as `load` plus bytes"});
  }
  add({CommandId::kRun, "run", "start the loaded program (or load path / program first)",
       {path, program, name, start_line}, bits({S::kReady}), false, false,
       "READY with a program loaded (start_line: with path / program)",
       "{job, state}"});
  add({CommandId::kResult, "result",
       "run figures of a job: state, duration_s, max/rms_contour_error_um, faults, overruns",
       {typed("job", ArgType::kJobNumber, true, "a job number", "job number (from load/run)")},
       kAnyState, false, false, "any", "{job, state, finished, completed, duration_s, ...}"});
  add({CommandId::kHold, "hold", "feed hold: decelerate on the path and wait", {},
       bits({S::kRunning}), true, true, "RUNNING", "the status object"});
  add({CommandId::kResume, "resume", "continue after hold, M0/M1/M6", {}, bits({S::kHold}), true,
       false, "HOLD", "the status object"});
  add({CommandId::kStop, "stop",
       "stop the program (decelerate on the path, flush), brake a jog, or unload a program", {},
       bits({S::kReady, S::kRunning, S::kHold}), false, true,
       "RUNNING, HOLD, jogging, or a program loaded", "the status object"});
  add({CommandId::kEstop, "estop", "emergency stop: quick stop, drive enable off", {}, kAnyState,
       false, true, "any", "the status object"});
  add({CommandId::kReset, "reset", "leave FAULT/ESTOP once every cause is gone, re-enable", {},
       bits({S::kFault, S::kEstop}), false, false, "FAULT or ESTOP", "the status object"});
  add({CommandId::kEnable, "enable", "enable the drives", {}, bits({S::kDisabled}), true, false,
       "DISABLED", "the status object"});
  add({CommandId::kDisable, "disable", "disable the drives", {}, bits({S::kReady, S::kEnabling}),
       true, false, "READY or ENABLING", "the status object"});
  add({CommandId::kJog, "jog",
       "jog an axis by a distance, or continuously towards its soft limit while the client stays "
       "(dead-man: a disconnect, or no request for safety.jog_deadman_ms, brakes it; `stop` too)",
       {typed("axis", ArgType::kAxis, true, "an axis name or index", "axis name or index"),
        number("velocity_mm_min", true, 1e-3, kInf, "speed, up to safety.jog_max_velocity_mm_min",
               Bound::kJogVelocity),
        number("distance_mm", false, -1e4, 1e4,
               "signed distance, not 0; target inside the soft limits (or give continuous)"),
        typed("continuous", ArgType::kChoice, false, "+ or -",
              "jog continuously in this direction (instead of distance_mm)", "+|-")},
       bits({S::kReady}), false, false, "READY, no program loaded, not jogging",
       "{axis, target_mm} (continuous: also deadman_ms)"});
  const std::vector<ArgSpec> setpos{
      typed("axis", ArgType::kAxis, true, "an axis name or index", "axis name or index"),
      number("position_mm", true, -kInf, kInf, "new position, inside the axis' soft limits",
             Bound::kAxisPosition)};
  add({CommandId::kSetPosition, "set-position",
       "set an axis position (simulated machine, absolute encoders)", setpos,
       bits({S::kDisabled, S::kReady}), false, false, "DISABLED or READY, no program loaded",
       "{axis, position_mm}"});
  add({CommandId::kHome, "home",
       "home one axis, or every axis with a homing method in home.sequence order (switch search, "
       "latch, move to home_position_mm); `stop` aborts; progress in status.homing",
       {typed("axis", ArgType::kAxis, false, "an axis name or index", "axis name or index (absent: all)")},
       bits({S::kReady}), false, false, "READY, no program loaded, not jogging",
       "{homing: [axis names]}; status.homed says when each is done"});
  add({CommandId::kGains, "gains",
       "get, or set {kp, ki_per_s, kd_s, ff, cp, ci_per_s, cd_s, coupling}: validated, stability "
       "checked, swapped at a cycle boundary in any state (bumpless)",
       {typed("set", ArgType::kAny, false, "a non-empty object of gains", "gains to change (the handler checks names and ranges)"),
        typed("op", ArgType::kAny, false, "", "ignored (accepted for older clients)")},
       kAnyState, false, false, "any", "the active gains, their generation and the drive models measured by identify since start (identified)"});
  add({CommandId::kOverride, "override",
       "feed, rapid and spindle override in percent (LinuxCNC's: the feed override scales feed "
       "moves, the rapid override G0 moves, the spindle override the programmed S); at least one",
       {number("percent", false, 0.0, kInf, "feed override: 0 .. interpolator.feed_override_max_percent",
               Bound::kOverridePercent),
        number("rapid_percent", false, 0.0, kInf,
               "rapid override: 0 .. interpolator.rapid_override_max_percent",
               Bound::kRapidOverridePercent),
        number("spindle_percent", false, 0.0, kInf,
               "spindle override: spindle.override_min_percent .. override_max_percent",
               Bound::kSpindleOverridePercent)},
       kAnyState, false, false, "any",
       "{feed_override_percent, rapid_override_percent, spindle_override_percent}: what applies from the next cycle"});
  add({CommandId::kRecord, "record", "telemetry CSV recording",
       {typed("action", ArgType::kChoice, true, "\"start\" or \"stop\"", "start or stop", "start|stop"),
        typed("path", ArgType::kString, false, "a string",
              "CSV file, inside telemetry.directory (the only place records are written)"),
        typed("name", ArgType::kString, false, "a string",
              "CSV file name in telemetry.directory (default contourd-CYCLE.csv)")},
       kAnyState, false, false, "any", "{recording, path, directory}"});
  const ArgSpec topic = typed("topic", ArgType::kChoice, true, "\"telemetry\" or \"events\"",
                              "telemetry (samples) or events (log lines)", "telemetry|events");
  add({CommandId::kSubscribe, "subscribe",
       "stream telemetry samples (every loop sample, in batches) or events on this connection",
       {topic, number("decimation", false, 1.0, 10000.0,
                      "telemetry only: every N-th sample (default 1: every sample)")},
       kAnyState, false, false, "any", "{topic, decimation}"});
  add({CommandId::kUnsubscribe, "unsubscribe", "end a subscription", {topic}, kAnyState, false,
       false, "any", "{topic}"});
  add({CommandId::kForce, "force",
       "force control on/off and reference (needs `dynamometer:`); no argument: force status",
       {typed("enable", ArgType::kBool, false, "true or false", "on (true) or off (false)"),
        typed("action", ArgType::kChoice, false, "\"on\" or \"off\"", "on or off", "on|off"),
        number("reference_N", false, 0.0, kInf, "reference force, below the force ceiling",
               Bound::kForceReference),
        number("reference_n", false, 0.0, kInf, "alias of reference_N", Bound::kForceReference)},
       kAnyState, false, false, "any", "the force status object"});
  add({CommandId::kSimGpio, "sim_gpio",
       "gpio.backend sim only: set a simulated input's physical level (e.g. press the E-stop)",
       {typed("line", ArgType::kString, true, "a string (role or line name)", "role or line name"),
        typed("level", ArgType::kLevel, true, "0 or 1 (physical level)", "physical level")},
       kAnyState, false, false, "any", "{line, level}"});
  add({CommandId::kIo, "io",
       "soft PLC I/O image (plc:): list the signals, or force / unforce one (sim bus or "
       "plc.allow_forcing only)",
       {typed("action", ArgType::kChoice, false, "\"list\", \"force\" or \"unforce\"",
              "list (default), force or unforce", "list|force|unforce"),
        typed("name", ArgType::kString, false, "a string (signal name; unforce: or \"all\")",
              "force/unforce: the signal of plc.signals"),
        typed("value", ArgType::kAny, false, "a value", "force: TRUE/FALSE, a number or T#2s")},
       kAnyState, false, false, "any",
       "list: {cycle, forcing_allowed, signals: [{name, type, direction, source, value, forced, "
       "forceable, description}]}; force/unforce: {name, forced, value}"});
  add({CommandId::kPlcStatus, "plc_status",
       "soft PLC status: programs' scan times and overruns, I/O couplers, M-code and tool-change "
       "handshakes, latched faults, requests to the NC",
       {}, kAnyState, false, false, "any",
       "{present, cycle, scan_us, programs, devices, mcode, tool_change, faults, requests, cause}"});
  {
    // Issue 18: offsets, tool table, touch-off and MDI (daemon/commands_offsets.cpp).
    const auto coord = [](double lo, double hi, const char* ax) {
      return number(ax, false, lo, hi, "new value (mm) of this axis");
    };
    add({CommandId::kOffsets, "offsets",
         "get the work offsets G54..G59.3, G92, G28/G30 (mm, machine coordinates), or set one "
         "axis or more of one of them (persisted to program.var_file)",
         {typed("set", ArgType::kChoice, false, "one of G54..G59.3, G92, G28, G30",
                "the offset to change", "G54|G55|G56|G57|G58|G59|G59.1|G59.2|G59.3|G92|G28|G30"),
          coord(-1e5, 1e5, "X"), coord(-1e5, 1e5, "Y"), coord(-1e5, 1e5, "Z")},
         kAnyState, false, false, "get: any; set: not while a program runs",
         "{offsets: {active, G54..G59.3, G92, G92_applied, G28, G30}, var_file}"});
    add({CommandId::kTools, "tools",
         "get the tool table, or set (add) / remove a tool: length_mm, diameter_mm, pocket, "
         "comment (persisted to program.tool_table)",
         {number("set", false, 1, 99999, "tool number to set or add"),
          number("remove", false, 1, 99999, "tool number to remove"),
          number("length_mm", false, -1000, 1000, "tool length offset (Z)"),
          number("diameter_mm", false, 0, 1000, "diameter"),
          number("pocket", false, 0, 99999, "pocket"),
          typed("comment", ArgType::kString, false, "a string", "comment")},
         kAnyState, false, false, "get: any; set/remove: not while a program runs",
         "{tools: [{number, pocket, length_mm, diameter_mm, comment}], tool_table, tool}"});
    add({CommandId::kTouchOff, "touch-off",
         "set a work offset so that the axis' commanded position reads `value` in that system "
         "(G10 L20: G92 and the tool length offset accounted)",
         {typed("axis", ArgType::kAxis, true, "an axis name or index", "axis name or index"),
          number("value", true, -1e5, 1e5, "the position the axis shall read (mm)"),
          typed("offset", ArgType::kChoice, false, "one of G54..G59.3",
                "coordinate system (default: the active one)",
                "G54|G55|G56|G57|G58|G59|G59.1|G59.2|G59.3")},
         bits({S::kDisabled, S::kReady}), false, false, "DISABLED or READY, no program loaded",
         "{offset, axis, value, offsets}"});
    add({CommandId::kMdi, "mdi",
         "run one command line (or a few, separated by newlines) now, through the program path; "
         "modal state carries from one mdi to the next",
         {typed("text", ArgType::kString, true, "a string of G-code", "the G-code line(s)")},
         bits({S::kReady}), false, false, "READY, no program loaded, not jogging (where `run` is)",
         "{job, state, blocks}"});
  }
  add({CommandId::kIdentify, "identify",
       "commissioning: play a small velocity excitation on one axis at rest (~0.84 s, +-5 mm/s, "
       "at most 0.5 mm each way, net zero; the others hold) and fit its drive: gain, time "
       "constant, transport delay in cycles, compared with machine.axes[].drive",
       {typed("axis", ArgType::kAxis, true, "an axis name or index", "axis name or index")},
       bits({S::kReady}), true, false, "READY, no program loaded, not jogging",
       "{axis, gain_per_s, velocity_gain, tau_ms, delay_cycles, delay_confidence, "
       "rms_residual_um, excursion_mm, configured: {gain_per_s, tau_ms, delay_cycles}, "
       "delay_matches, gain_deviation_percent, tau_deviation_percent, verdict, record: "
       "{period_s, v_cmd_mm_s, position_mm}}"});
  add({CommandId::kSwitches, "switches",
       "the operator's program switches, as in LinuxCNC: block delete ('/' lines skipped, from the "
       "next line the interpreter reads), optional stop (M1 holds, judged when the path reaches "
       "it) and single block (the path stops before each new line; resume runs the next one); no "
       "argument: get",
       {typed("block_delete", ArgType::kBool, false, "true or false", "the block delete switch"),
        typed("optional_stop", ArgType::kBool, false, "true or false", "the optional stop switch"),
        typed("single_block", ArgType::kBool, false, "true or false", "the single block switch")},
       kAnyState, false, false, "any",
       "{block_delete, optional_stop, single_block}: as they are from the next cycle"});
  add({CommandId::kShutdown, "shutdown", "controlled stop, drives disabled, exit 0", {}, kAnyState,
       false, false, "any", "{shutting_down}"});
  return t;
}

bool type_ok(const ArgSpec& a, const json& v) {
  switch (a.type) {
    case ArgType::kNumber: return v.is_number();
    case ArgType::kJobNumber: return v.is_number_unsigned();
    case ArgType::kString: return v.is_string();
    case ArgType::kBool: return v.is_boolean();
    case ArgType::kAxis: return v.is_number_integer() || v.is_string();
    case ArgType::kObject: return v.is_object() && !v.empty();
    case ArgType::kChoice: {
      if (!v.is_string()) return false;
      const std::string s = v.get<std::string>();
      std::string_view rest = a.choices;
      while (!rest.empty()) {
        const auto bar = rest.find('|');
        if (rest.substr(0, bar) == s) return true;
        if (bar == std::string_view::npos) break;
        rest.remove_prefix(bar + 1);
      }
      return false;
    }
    case ArgType::kLevel:
      return v.is_boolean() || (v.is_number_integer() && (v.get<long>() == 0 || v.get<long>() == 1));
    case ArgType::kAny: return true;
  }
  return false;
}

}  // namespace

const std::vector<CommandSpec>& command_table() {
  static const std::vector<CommandSpec> table = build_table();
  return table;
}

const CommandSpec* find_command(std::string_view name) {
  for (const CommandSpec& c : command_table()) {
    if (c.name == name) return &c;
  }
  return nullptr;
}

bool is_safety_command(std::string_view name) {
  const CommandSpec* c = find_command(name);
  return c != nullptr && c->safety;
}

void validate_request(const CommandSpec& spec, const json& req, const BoundResolver& bounds) {
  for (auto it = req.begin(); it != req.end(); ++it) {
    if (it.key() == "id" || it.key() == "cmd") continue;
    bool known = false;
    for (const ArgSpec& a : spec.args) known = known || a.name == it.key();
    if (!known) throw CommandError("unknown argument '" + it.key() + "'");
  }
  for (const ArgSpec& a : spec.args) {
    const std::string key(a.name);
    if (!req.contains(key)) {
      if (a.required) throw CommandError("missing argument '" + key + "'");
      continue;
    }
    const json& v = req.at(key);
    if (!type_ok(a, v)) throw CommandError("argument '" + key + "' must be " + std::string(a.expect));
    if (a.type != ArgType::kNumber) continue;
    double lo = a.lo, hi = a.hi;
    if (a.bound != Bound::kStatic && bounds) std::tie(lo, hi) = bounds(a.bound, req);
    const double x = v.get<double>();
    if (!std::isfinite(x) || x < lo || x > hi) {
      throw CommandError("argument '" + key + "' = " + std::to_string(x) + " out of range [" +
                         std::to_string(lo) + ", " + std::to_string(hi) + "]");
    }
  }
}

void check_state(const CommandSpec& spec, MachineState st) {
  if (!spec.gate || (spec.states & state_bit(st)) != 0) return;
  throw CommandError(std::string(spec.name) + " is not allowed in state " + std::string(to_string(st)));
}

std::string protocol_markdown() {
  std::ostringstream o;
  o << "# contourd command protocol\n\n"
       "<!-- Generated from daemon/command_table.cpp by `contourd --protocol`; the unit test\n"
       "     `CommandTable.ProtocolDocumentIsGeneratedFromTheTable` fails when they differ. -->\n\n"
       "JSON lines over the Unix socket (`socket.path`). Request: `{\"id\": any, \"cmd\": NAME, "
       "...arguments}`; reply: `{\"id\", \"ok\": true, \"result\": ...}` or `{\"id\", \"ok\": "
       "false, \"error\": TEXT}`. Unknown arguments, wrong types and out-of-range values are "
       "refused with an error naming the argument. Safety commands are never refused for load or "
       "rate reasons.\n\n"
       "| command | what it does | allowed in | safety | reply |\n"
       "| --- | --- | --- | --- | --- |\n";
  for (const CommandSpec& c : command_table()) {
    o << "| `" << c.name << "` | " << c.summary << " | " << c.states_text << " | "
      << (c.safety ? "yes" : "") << " | " << c.reply << " |\n";
  }
  o << "\n## Arguments\n";
  for (const CommandSpec& c : command_table()) {
    if (c.args.empty()) continue;
    o << "\n### `" << c.name << "`\n\n| argument | type | required | range | meaning |\n"
         "| --- | --- | --- | --- | --- |\n";
    for (const ArgSpec& a : c.args) {
      std::string range;
      switch (a.bound) {
        case Bound::kStatic:
          if (a.type == ArgType::kNumber) {
            std::ostringstream r;
            r << "[" << (std::isinf(a.lo) ? std::string("-inf") : std::to_string(a.lo)) << ", "
              << (std::isinf(a.hi) ? std::string("inf") : std::to_string(a.hi)) << "]";
            range = r.str();
          } else if (a.type == ArgType::kChoice) {
            range = std::string(a.choices);
          }
          break;
        case Bound::kJogVelocity: range = "[0.001, safety.jog_max_velocity_mm_min]"; break;
        case Bound::kAxisPosition: range = "the axis' soft limits"; break;
        case Bound::kOverridePercent: range = "[0, interpolator.feed_override_max_percent]"; break;
        case Bound::kRapidOverridePercent: range = "[0, interpolator.rapid_override_max_percent]"; break;
        case Bound::kSpindleOverridePercent:
          range = "[spindle.override_min_percent, spindle.override_max_percent]";
          break;
        case Bound::kForceReference: range = "[0, force.limits.force_ceiling_N]"; break;
      }
      o << "| `" << a.name << "` | " << (a.expect.empty() ? std::string_view("any") : a.expect)
        << " | " << (a.required ? "yes" : "no") << " | " << range << " | " << a.help << " |\n";
    }
  }
  return o.str();
}

std::string command_summary_text() {
  std::ostringstream o;
  for (const CommandSpec& c : command_table()) {
    std::string n(c.name);
    n.resize(std::max<std::size_t>(n.size(), 14), ' ');
    o << "  " << n << c.summary << (c.safety ? " [safety]" : "") << "\n";
  }
  return o.str();
}

}  // namespace contour::daemon
