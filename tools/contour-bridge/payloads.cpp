#include "tools/contour-bridge/payloads.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <limits>
#include <regex>

namespace contour::bridge {

using nlohmann::json;

std::int64_t now_us() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

std::string iso8601_utc(std::int64_t us) {
  const std::time_t s = static_cast<std::time_t>(us / 1000000);
  const auto ms = static_cast<int>((us % 1000000) / 1000);
  std::tm tm{};
  ::gmtime_r(&s, &tm);
  char b[96];
  std::snprintf(b, sizeof b, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900,
                tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, ms);
  return b;
}

namespace {

std::uint64_t leading_number(const std::string& s, std::size_t pos) {
  std::uint64_t v = 0;
  while (pos < s.size() && std::isdigit(static_cast<unsigned char>(s[pos])) != 0) {
    v = v * 10 + static_cast<std::uint64_t>(s[pos] - '0');
    ++pos;
  }
  return v;
}

bool starts_with(const std::string& s, const std::string& p) { return s.rfind(p, 0) == 0; }

// Snake-case code of a fault cause as the daemon names it ("following error" ->
// "following_error", "E-stop input" -> "e_stop_input").
std::string code_of(const std::string& cause) {
  std::string out;
  for (char c : cause) {
    if (std::isalnum(static_cast<unsigned char>(c)) != 0) {
      out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    } else if (!out.empty() && out.back() != '_') {
      out += '_';
    }
  }
  while (!out.empty() && out.back() == '_') out.pop_back();
  return out;
}

json copy_if_present(const json& from, std::initializer_list<const char*> keys) {
  json out = json::object();
  for (const char* k : keys) {
    if (from.contains(k)) out[k] = from[k];
  }
  return out;
}

double num(const json& j, const char* key, double def = 0.0) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return def;
  return j[key].get<double>();
}

}  // namespace

DaemonEvent classify_event(const json& line) {
  DaemonEvent e;
  const std::string ev = line.value("event", std::string());
  e.text = line.value("text", std::string());
  if (ev == "socket") {
    e.kind = "socket";
    return e;
  }
  std::string body = e.text;
  if (starts_with(body, "cycle ")) {
    e.cycle = leading_number(body, 6);
    const std::size_t colon = body.find(": ");
    if (colon != std::string::npos) body = body.substr(colon + 2);
  }
  static const std::regex kTransition(R"(^state (\w+) -> (\w+)(?: \(cause (.+)\))?$)");
  static const std::regex kProgram(R"(^program (\d+) (done|ended early))");
  std::smatch m;
  if (std::regex_search(body, m, kTransition)) {
    e.kind = "transition";
    e.from = m[1];
    e.to = m[2];
    if (m[3].matched) e.cause = m[3];
  } else if (std::regex_search(body, m, kProgram)) {
    e.kind = "program_end";
    e.job = std::stoull(m[1]);
    e.completed = m[2] == "done";
  } else if (starts_with(body, "FAULT ")) {
    e.kind = "fault";
    // "FAULT <cause>[ axis N| node N][: ...]": the cause is the text up to " axis"/" node"/":".
    std::string cause = body.substr(6);
    for (const char* cut : {" axis ", " node ", ":"}) {
      const std::size_t p = cause.find(cut);
      if (p != std::string::npos) cause = cause.substr(0, p);
    }
    e.cause = cause;
  } else if (body.find("EMCY") != std::string::npos) {
    e.kind = "emcy";
  } else if (starts_with(body, "E-STOP by") || starts_with(body, "E-STOP from")) {
    e.kind = "estop_request";
  } else if (starts_with(body, "hold by")) {
    e.kind = "hold_request";
  } else if (starts_with(body, "segment queue")) {
    e.kind = "underrun";
  } else if (starts_with(body, "spindle")) {
    e.kind = "spindle";
  } else if (starts_with(body, "command '")) {
    e.kind = "refused";
  } else if (starts_with(body, "force")) {
    e.kind = "force";
  } else if (starts_with(body, "gains generation")) {
    e.kind = "gains";
  } else if (starts_with(body, "safety limits")) {
    e.kind = "limits";
  } else if (body.find("fault") != std::string::npos ||
             body.find("heartbeat lost") != std::string::npos ||
             body.find("missed") != std::string::npos) {
    e.kind = "fault";  // a bus message (CANopen event thread) the daemon files as a fault
  } else {
    e.kind = "log";
  }
  return e;
}

std::string execution_of(const json& st) {
  const std::string s = st.value("state", std::string());
  if (s == "RUNNING") return "ACTIVE";
  if (s == "HOLD") {
    // A programmed pause (M0/M1/M6) is PROGRAM_STOPPED, an operator's feed hold FEED_HOLD.
    if (st.contains("tool_change") && !st["tool_change"].is_null()) return "PROGRAM_STOPPED";
    return st.value("program_hold", false) ? "PROGRAM_STOPPED" : "FEED_HOLD";
  }
  if (s == "READY") return st.value("jogging", false) ? "ACTIVE" : "READY";
  if (s == "ENABLING") return "WAIT";
  if (s == "FAULT" || s == "ESTOP") return "INTERRUPTED";
  if (s == "DISABLED") return "STOPPED";
  return "UNAVAILABLE";
}

std::string controller_mode_of(const json& st) {
  if (st.value("jogging", false)) return "MANUAL";
  const std::string src = st.value("source", std::string());
  const std::string s = st.value("state", std::string());
  if (s == "RUNNING" || s == "HOLD" || st.value("job", 0ULL) != 0 ||
      st.value("loaded_job", 0ULL) != 0 || src == "program") {
    return "AUTOMATIC";
  }
  if (st.contains("mode") && st["mode"].is_string()) {
    const std::string m = st["mode"].get<std::string>();
    if (m == "mdi" || m == "MDI") return "MANUAL_DATA_INPUT";
  }
  return "MANUAL";
}

json alarms_of(const json& st) {
  json out = json::array();
  const std::string s = st.value("state", std::string());
  const std::string cause = st.value("cause", std::string("none"));
  if ((s == "FAULT" || s == "ESTOP") && cause != "none") {
    json a{{"code", code_of(cause)},
           {"severity", s == "ESTOP" ? "estop" : "fault"},
           {"text", cause}};
    if (st.contains("fault") && st["fault"].is_object()) {
      const json& f = st["fault"];
      if (f.value("axis", -1) >= 0) a["axis"] = f["axis"];
      if (f.contains("value")) a["value"] = f["value"];
      if (f.contains("limit")) a["limit"] = f["limit"];
    }
    out.push_back(a);
  }
  return out;
}

json state_payload(const json& st, const Identity& id, bool available) {
  if (!available) {
    return json{{"machine_id", id.machine_id},
                {"available", false},
                {"state", "UNAVAILABLE"},
                {"execution", "UNAVAILABLE"}};
  }
  json p{{"machine_id", id.machine_id},
         {"available", true},
         {"state", st.value("state", std::string("?"))},
         {"cause", st.value("cause", std::string("none"))},
         {"execution", execution_of(st)},
         {"mode", controller_mode_of(st)},
         {"source", st.value("source", std::string())},
         {"line", st.value("line", 0)},
         {"jogging", st.value("jogging", false)},
         {"drives_enabled", st.value("drives_enabled", false)},
         {"estop", st.value("state", std::string()) == "ESTOP" ||
                       (st.contains("gpio") && st["gpio"].value("estop_input", false))},
         {"alarms", alarms_of(st)}};
  // The program being run (or loaded), with its running contour-error figures.
  if (st.contains("program") && st["program"].is_object()) {
    const json& pr = st["program"];
    p["program"] = copy_if_present(pr, {"job", "name", "motion_blocks", "length_mm"});
    p["program"]["running"] = st.value("job", 0ULL) != 0 && st.value("job", 0ULL) == pr.value("job", 0ULL);
  } else {
    p["program"] = nullptr;
  }
  p["finished_job"] = st.value("finished_job", 0ULL);
  p["finished_ok"] = st.value("finished_ok", false);
  // Overrides: feed from today's status; rapid/spindle when the daemon reports them (issue 18).
  json ov{{"feed_percent", std::round(num(st, "feed_override", 1.0) * 1000.0) / 10.0}};
  for (const char* k : {"rapid_override", "spindle_override"}) {
    if (st.contains(k) && st[k].is_number()) {
      ov[std::string(k).substr(0, std::string(k).find('_')) + "_percent"] =
          std::round(st[k].get<double>() * 1000.0) / 10.0;
    }
  }
  if (st.contains("overrides") && st["overrides"].is_object()) ov.update(st["overrides"]);
  p["overrides"] = ov;
  if (st.contains("spindle") && st["spindle"].is_object()) {
    const json& sp = st["spindle"];
    // Speed rounded to 1 rpm: a ramp publishes, sensor noise does not.
    p["spindle"] = {{"present", sp.value("present", false)},
                    {"target_rpm", std::round(num(sp, "target_rpm"))},
                    {"actual_rpm", std::round(num(sp, "actual_rpm"))},
                    {"at_speed", sp.value("at_speed", false)}};
  }
  // Issue 18 fields, passed through as the daemon names them.
  for (const char* k : {"homed", "tool", "tool_change", "work_offset", "offsets", "mdi"}) {
    if (st.contains(k)) p[k] = st[k];
  }
  return p;
}

json position_payload(const json& st, const Identity& id) {
  json p{{"machine_id", id.machine_id},
         {"axes", id.axes},
         {"machine", {{"actual_mm", st.value("act_mm", json::array())},
                      {"commanded_mm", st.value("ref_mm", json::array())}}},
         {"feed_mm_s", path_feed_mm_s(st)},
         {"contour_error_um", num(st, "contour_error_um")},
         {"line", st.value("line", 0)},
         {"cycle", st.value("cycle", 0ULL)}};
  // Work coordinates when the daemon reports them (issue 18): positions as given, or machine
  // minus the active offset.
  if (st.contains("work_act_mm") && st.contains("work_ref_mm")) {
    p["work"] = {{"actual_mm", st["work_act_mm"]}, {"commanded_mm", st["work_ref_mm"]}};
  } else if (st.contains("work_offset_mm") && st["work_offset_mm"].is_array()) {
    const json& off = st["work_offset_mm"];
    auto minus = [&](const json& a) {
      json out = json::array();
      for (std::size_t i = 0; i < a.size(); ++i) {
        const double o = i < off.size() && off[i].is_number() ? off[i].get<double>() : 0.0;
        out.push_back(a[i].get<double>() - o);
      }
      return out;
    };
    p["work"] = {{"actual_mm", minus(st.value("act_mm", json::array()))},
                 {"commanded_mm", minus(st.value("ref_mm", json::array()))}};
  }
  return p;
}

double max_axis_move_mm(const json& a, const json& b) {
  if (!a.is_object() || !b.is_object() || !a.contains("act_mm") || !b.contains("act_mm")) {
    return std::numeric_limits<double>::infinity();
  }
  const json& x = a["act_mm"];
  const json& y = b["act_mm"];
  if (!x.is_array() || !y.is_array() || x.size() != y.size()) {
    return std::numeric_limits<double>::infinity();
  }
  double m = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    m = std::max(m, std::abs(x[i].get<double>() - y[i].get<double>()));
  }
  return m;
}

double path_feed_mm_s(const json& st) {
  if (!st.contains("cmd_mm_s") || !st["cmd_mm_s"].is_array()) return 0.0;
  double s = 0.0;
  for (const auto& v : st["cmd_mm_s"]) {
    if (v.is_number()) s += v.get<double>() * v.get<double>();
  }
  return std::sqrt(s);
}

json event_payload(const DaemonEvent& e, std::uint64_t seq, std::int64_t session,
                   const Identity& id, std::int64_t ts_us) {
  json p{{"machine_id", id.machine_id},
         {"seq", seq},
         {"session", session},
         {"ts", iso8601_utc(ts_us)},
         {"ts_us", ts_us},
         {"kind", e.kind},
         {"text", e.text}};
  if (e.cycle != 0) p["cycle"] = e.cycle;
  if (e.kind == "transition") {
    p["from"] = e.from;
    p["to"] = e.to;
    if (!e.cause.empty()) p["cause"] = e.cause;
  }
  if (e.kind == "fault" && !e.cause.empty()) p["cause"] = e.cause;
  if (e.kind == "program_end" || e.kind == "program_start") p["job"] = e.job;
  if (e.kind == "program_end") p["completed"] = e.completed;
  if (e.kind == "program_start" && !e.name.empty()) p["name"] = e.name;
  return p;
}

}  // namespace contour::bridge
