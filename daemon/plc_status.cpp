#include "daemon/plc_status.hpp"

namespace contour::daemon {

namespace cp = control::plc;
using nlohmann::json;

json plc_value_json(cp::Type t, cp::Cell v) {
  switch (t) {
    case cp::Type::kBool:
      return v.i != 0;
    case cp::Type::kInt:
    case cp::Type::kDint:
      return v.i;
    case cp::Type::kReal:
    case cp::Type::kLreal:
      return v.r;
    case cp::Type::kTime:
      return static_cast<double>(v.i) * 1e-6;
    default:
      return nullptr;
  }
}

json plc_io_json(const PlcSnapshot& s) {
  json sig = json::array();
  for (const auto& v : s.signals) {
    sig.push_back({{"name", v.name},
                   {"type", cp::type_name(v.type)},
                   {"direction", v.direction},
                   {"source", v.source},
                   {"value", plc_value_json(v.type, v.value)},
                   {"forced", v.forced},
                   {"forceable", v.forceable},
                   {"description", v.description}});
  }
  return {{"cycle", s.cycle}, {"forcing_allowed", s.forcing_allowed}, {"signals", sig}};
}

namespace {
json scan_json(const PlcScanStats& st, double median_us) {
  return {{"last", st.last_ns * 1e-3},
          {"min", st.min_ns * 1e-3},
          {"median", median_us},
          {"max", st.max_ns * 1e-3}};
}
json fault_json(const PlcFault& f, const PlcSnapshot& s) {
  json j{{"kind", to_string(f.kind)}, {"code", f.code}, {"value", f.value}, {"limit", f.limit}};
  if (f.kind == PlcFaultKind::kIoStale && f.index >= 0 && static_cast<std::size_t>(f.index) < s.devices.size())
    j["device"] = s.devices[static_cast<std::size_t>(f.index)].name;
  if (f.kind == PlcFaultKind::kRuntimeError && f.index >= 0 &&
      static_cast<std::size_t>(f.index) < s.programs.size()) {
    j["program"] = s.programs[static_cast<std::size_t>(f.index)].name;
    j["line"] = f.code;
    j["error"] = cp::to_string(static_cast<cp::RunStatus>(static_cast<int>(f.value)));
  }
  return j;
}
}  // namespace

json plc_status_json(const PlcSnapshot& s) {
  json progs = json::array();
  for (const auto& p : s.programs) {
    json j{{"name", p.name},
           {"file", p.file},
           {"period_cycles", p.period_cycles},
           {"state", p.stats.state == 0 ? "running" : "stopped"},
           {"runs", p.stats.runs},
           {"overruns", p.stats.overruns},
           {"scan_us", scan_json(p.stats, p.median_us)},
           {"instructions",
            {{"last", p.stats.instructions_last},
             {"max", p.stats.instructions_max},
             {"worst_case", p.worst_case}}}};
    if (p.stats.state != 0)
      j["error"] = p.file + ":" + std::to_string(p.stats.error_line) + ": " +
                   cp::to_string(static_cast<cp::RunStatus>(p.stats.error_status));
    progs.push_back(std::move(j));
  }
  json devs = json::array();
  for (const auto& d : s.devices) {
    devs.push_back({{"name", d.name},
                    {"endpoint", d.endpoint},
                    {"state", d.state},
                    {"age_s", d.age_s},
                    {"connected", d.status.connected},
                    {"polls", d.status.polls},
                    {"reads", d.status.reads},
                    {"writes", d.status.writes},
                    {"timeouts", d.status.timeouts},
                    {"exceptions", d.status.exceptions},
                    {"reconnects", d.status.reconnects},
                    {"last_error", d.status.last_error}});
  }
  json faults = json::array();
  for (const auto& f : s.faults) faults.push_back(fault_json(f, s));
  return {{"cycle", s.cycle},
          {"scan_us", scan_json(s.scan, s.scan_median_us)},
          {"scans", s.scan.runs},
          {"programs", progs},
          {"devices", devs},
          {"mcode", {{"state", to_string(s.mcode)}, {"m", s.mcode_number}}},
          {"tool_change", {{"state", to_string(s.tool_change)}, {"tool", s.tool_number}}},
          {"faults", faults}};
}

}  // namespace contour::daemon
