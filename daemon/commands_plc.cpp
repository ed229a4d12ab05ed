// Soft PLC commands (issue 20): `io` (the I/O image; force / unforce) and `plc_status`, and the
// `plc` object of `status`. The JSON shapes are daemon/plc_status.hpp's (documented in
// daemon/PLC.md). Non-RT: the engine's snapshot is a triple buffer the loop publishes each scan;
// forces go to the loop through the engine's SPSC ring and take effect at the next scan.
#include <chrono>
#include <string>
#include <thread>

#include <spdlog/spdlog.h>

#include "daemon/commands.hpp"
#include "daemon/daemon.hpp"
#include "daemon/plc_status.hpp"

namespace contour::daemon {

namespace {

using nlohmann::json;

// A forced value as the engine parses it ("TRUE", "12", "2.5", "T#2s").
std::string value_text(const json& v) {
  if (v.is_boolean()) return v.get<bool>() ? "TRUE" : "FALSE";
  if (v.is_number_integer()) return std::to_string(v.get<long long>());
  if (v.is_number()) return v.dump();
  if (v.is_string()) return v.get<std::string>();
  throw CommandError("io: argument 'value' must be TRUE/FALSE, a number or a string such as T#2s");
}

json signal_of(const PlcSnapshot& snap, const std::string& name) {
  const json io = plc_io_json(snap);
  for (const auto& s : io["signals"]) {
    if (s["name"] == name) return s;
  }
  return json::object();
}

}  // namespace

json Daemon::cmd_io(const json& req) {
  if (!plc_) throw CommandError("io: no soft PLC configured (plc: section)");
  const std::string action = req.value("action", std::string("list"));
  if (action == "list") {
    if (req.contains("name") || req.contains("value")) {
      throw CommandError("io: 'name' and 'value' go with action force / unforce");
    }
    return plc_io_json(plc_->snapshot());
  }
  if (!req.contains("name")) throw CommandError("io " + action + ": missing argument 'name'");
  const std::string name = req["name"].get<std::string>();
  std::string err;
  if (action == "force") {
    if (!req.contains("value")) throw CommandError("io force: missing argument 'value'");
    const std::string value = value_text(req["value"]);
    err = plc_->force(name, value);
    if (!err.empty()) throw CommandError("io force " + name + ": " + err);
    spdlog::warn("plc: signal '{}' FORCED to {}", name, value);
  } else {
    if (req.contains("value")) throw CommandError("io unforce: unknown argument 'value'");
    err = plc_->unforce(name);
    if (!err.empty()) throw CommandError("io unforce " + name + ": " + err);
    spdlog::warn("plc: signal '{}' unforced", name);
  }
  // The force takes effect at the next scan: wait for a snapshot that shows it (bounded).
  const bool want = action == "force";
  const bool every = action == "unforce" && (name == "all" || name == "*");
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  for (;;) {
    const PlcSnapshot snap = plc_->snapshot();
    if (every) {
      bool any = false;
      for (const auto& s : snap.signals) any = any || s.forced;
      if (!any) return {{"name", name}, {"forced", false}};
    } else {
      json s = signal_of(snap, name);
      if (s.empty()) {  // the name differs in case: the engine found it, report what it shows
        const int slot = plc_->find(name);
        if (slot >= 0 && static_cast<std::size_t>(slot) < snap.signals.size()) {
          s = signal_of(snap, snap.signals[static_cast<std::size_t>(slot)].name);
        }
      }
      if (!s.empty() && s.value("forced", false) == want) {
        return {{"name", s["name"]}, {"forced", want}, {"value", s["value"]}};
      }
    }
    if (std::chrono::steady_clock::now() > until) {
      throw CommandError("io " + action + ": the loop did not apply it (is it running?)");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

json Daemon::cmd_plc_status(const json&) {
  const LoopStatus st = loop_->status();
  if (!plc_) return {{"present", false}};
  json j = plc_status_json(plc_->snapshot());
  j["present"] = true;
  const json brief = plc_brief_json(st);
  j["requests"] = brief["requests"];
  j["cause"] = brief["cause"];
  return j;
}

json Daemon::plc_brief_json(const LoopStatus& st) {
  if (!st.plc_present) return {{"present", false}};
  const PlcRequests& r = st.plc_requests;
  json axis_fault = json::array();
  for (int i = 0; i < loop_->axes(); ++i) axis_fault.push_back(r.axis_fault[static_cast<std::size_t>(i)]);
  json cause{{"action", to_string(st.plc_cause.action)}, {"cycle", st.plc_cause.cycle}};
  if (st.plc_cause.action == PlcAction::kFault) cause["fault_code"] = st.plc_cause.code;
  if (st.plc_cause.action == PlcAction::kEngineFault) {
    // The index is the coupler's (I/O stale) or the program's (runtime error): named, not an axis.
    cause["engine_fault"] = to_string(st.plc_cause.engine);
    cause["code"] = st.plc_cause.code;
    const auto i = static_cast<std::size_t>(st.plc_cause.axis);
    if (st.plc_cause.engine == PlcFaultKind::kIoStale && st.plc_cause.axis >= 0 && i < cfg_.plc.modbus.size())
      cause["device"] = cfg_.plc.modbus[i].name;
    if (st.plc_cause.engine == PlcFaultKind::kRuntimeError && st.plc_cause.axis >= 0 &&
        i < cfg_.plc.programs.size())
      cause["program"] = cfg_.plc.programs[i].file;
  } else if (st.plc_cause.axis >= 0) {
    cause["axis"] = st.plc_cause.axis;
  }
  return {{"present", true},
          {"requests",
           {{"feed_hold", r.feed_hold},
            {"inhibit_start", r.inhibit_start},
            {"stop", r.stop},
            {"estop", r.estop},
            {"spindle_inhibit", r.spindle_inhibit},
            {"fault", r.fault},
            {"fault_code", r.fault_code},
            {"axis_fault", axis_fault}}},
          {"cause", cause}};
}

}  // namespace contour::daemon
