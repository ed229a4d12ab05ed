// libFuzzer target (issue 11): the command socket's line protocol (daemon/command_protocol.hpp)
// with a handler that reads arguments the way daemon/commands.cpp does (json::at/get, which throw
// nlohmann exceptions, CommandError for bad values) and the daemon's one pure argument validator,
// axis_index(). Input: one request line (any bytes; a '\n' inside is kept, the server would have
// split there, the protocol function must still cope).
// Contract checked:
//   - never crashes, never lets an exception out (ASan/UBSan, libFuzzer's uncaught-exception
//   abort);
//   - the reply is an object with a boolean "ok"; ok == false -> string "error"; ok == true ->
//     "result" present and the handler ran;
//   - the handler runs only for an object request with a string "cmd" (and never for a line
//     nested deeper than kMaxRequestDepth);
//   - an object request's "id" is echoed unchanged;
//   - to_line() gives exactly one '\n', at the end, and the line parses back to an object.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "config/machine_config.hpp"
#include "daemon/command_protocol.hpp"
#include "daemon/commands.hpp"

using contour::daemon::CommandError;
using json = nlohmann::json;

namespace {
void check_at(bool c, int line) {
  if (!c) {
    std::fprintf(stderr, "command_fuzz: check at command_fuzz.cpp:%d failed\n", line);
    std::abort();
  }
}
#define check(c) check_at((c), __LINE__)

const contour::config::MachineConfig& machine() {
  static const contour::config::MachineConfig m = [] {
    contour::config::MachineConfig c;
    for (const char* n : {"X", "Y", "Z"}) {
      contour::config::AxisConfig a;
      a.name = n;
      c.axes.push_back(a);
    }
    return c;
  }();
  return m;
}

// Reads arguments like the daemon's handlers: unknown commands and bad values are CommandErrors,
// wrong types surface as nlohmann exceptions ("bad argument: ...").
json handler(const json& req) {
  const std::string cmd = req.at("cmd").get<std::string>();
  if (cmd == "status" || cmd == "hold" || cmd == "resume" || cmd == "stop" || cmd == "estop" ||
      cmd == "reset" || cmd == "enable" || cmd == "disable" || cmd == "shutdown")
    return json{{"state", "READY"}};
  if (cmd == "jog") {
    const int axis = contour::daemon::axis_index(req.at("axis"), machine());
    const double v = req.at("velocity_mm_min").get<double>();
    const double d = req.value("distance_mm", 1.0);
    if (!(v > 0.0)) throw CommandError("argument 'velocity_mm_min' must be > 0");
    return json{{"axis", axis}, {"distance_mm", d}};
  }
  if (cmd == "set-position" || cmd == "home") {
    const int axis = contour::daemon::axis_index(req.at("axis"), machine());
    return json{{"axis", axis}, {"position_mm", req.value("position_mm", 0.0)}};
  }
  if (cmd == "load" || cmd == "run") {
    if (req.contains("path")) return json{{"path", req.at("path").get<std::string>()}};
    if (req.contains("program"))
      return json{{"blocks", req.at("program").get<std::string>().size()}};
    if (cmd == "load") throw CommandError("load needs 'path' or 'program'");
    return json::object();
  }
  if (cmd == "result") return json{{"job", req.at("job").get<std::uint64_t>()}};
  if (cmd == "override") {
    const double p = req.at("percent").get<double>();
    if (!(p >= 0.0 && p <= 200.0)) throw CommandError("argument 'percent' out of range 0..200");
    return json{{"percent", p}};
  }
  if (cmd == "gains") {
    if (!req.contains("set")) return json{{"kp", {30.0, 30.0, 30.0}}};
    json out = json::object();
    for (const auto& [k, v] : req.at("set").items()) {
      if (v.is_array()) {
        for (const auto& x : v) (void)x.get<double>();
      } else {
        (void)v.get<double>();
      }
      out[k] = v;
    }
    return out;
  }
  if (cmd == "record") {
    const std::string a = req.at("action").get<std::string>();
    if (a != "start" && a != "stop") throw CommandError("argument 'action' must be start or stop");
    return json{{"recording", a == "start"}};
  }
  if (cmd == "subscribe" || cmd == "unsubscribe") {
    const std::string t = req.at("topic").get<std::string>();
    if (t != "telemetry" && t != "events") throw CommandError("unknown topic '" + t + "'");
    return json{{"topic", t}};
  }
  if (cmd == "force") throw CommandError("force: not implemented yet");
  throw std::runtime_error("unknown command '" + cmd + "'");
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view line(reinterpret_cast<const char*>(data), size);
  bool handler_ran = false;
  const auto out = contour::daemon::handle_request_line(line, [&](const json& req) {
    handler_ran = true;
    check(req.is_object());
    check(req.contains("cmd") && req["cmd"].is_string());
    return handler(req);
  });
  const json& r = out.reply;
  check(r.is_object());
  check(r.contains("ok") && r["ok"].is_boolean());
  check(out.error == !r["ok"].get<bool>());
  if (out.error) {
    check(r.contains("error") && r["error"].is_string());
  } else {
    check(handler_ran && r.contains("result"));
  }
  if (contour::daemon::json_nesting_depth(line, contour::daemon::kMaxRequestDepth) >
      contour::daemon::kMaxRequestDepth) {
    check(!handler_ran && out.error);
  } else {
    const json req = json::parse(line, nullptr, false);
    if (!req.is_discarded() && req.is_object()) {
      const bool has_cmd = req.contains("cmd") && req["cmd"].is_string();
      check(handler_ran == has_cmd);
      if (req.contains("id")) check(r.contains("id") && r["id"] == req["id"]);
    } else {
      check(!handler_ran);
    }
  }
  const std::string text = contour::daemon::to_line(r);
  check(!text.empty() && text.back() == '\n' && text.find('\n') == text.size() - 1);
  const json back = json::parse(std::string_view(text).substr(0, text.size() - 1), nullptr, false);
  check(!back.is_discarded() && back.is_object());
  return 0;
}
