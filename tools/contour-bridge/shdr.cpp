#include "tools/contour-bridge/shdr.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "tools/contour-bridge/payloads.hpp"

namespace contour::bridge {

using nlohmann::json;

namespace {

constexpr const char* kUnavailable = "UNAVAILABLE";
// Data items per SHDR line: agents accept long lines, people reading a capture prefer short ones.
constexpr std::size_t kPairsPerLine = 16;

std::string fmt(const char* f, double v) {
  if (!std::isfinite(v)) return kUnavailable;
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  std::string s = b;
  // "-0.0000": a sign flip in the noise around zero is not a change.
  if (!s.empty() && s[0] == '-' && s.find_first_not_of("-0.") == std::string::npos) s.erase(0, 1);
  return s;
}

double number_at(const json& arr, std::size_t i) {
  if (!arr.is_array() || i >= arr.size() || !arr[i].is_number()) return std::nan("");
  return arr[i].get<double>();
}

}  // namespace

std::string shdr_field(const std::string& s) {
  std::string out = s;
  for (char& c : out) {
    if (c == '|') c = '/';
    if (c == '\n' || c == '\r' || c == '\t') c = ' ';
  }
  return out;
}

std::vector<ItemDef> shdr_items(const std::vector<std::string>& axes, bool has_spindle) {
  using C = ItemCategory;
  using P = ItemPlace;
  std::vector<ItemDef> v{
      {"avail", C::kEvent, "AVAILABILITY", "", "", P::kDevice, "", ""},
      {"estop", C::kEvent, "EMERGENCY_STOP", "", "", P::kController, "", ""},
      {"system", C::kCondition, "SYSTEM", "", "", P::kController, "", ""},
      {"overruns", C::kEvent, "x:LOOP_OVERRUNS", "", "", P::kController, "", ""},
      {"mode", C::kEvent, "CONTROLLER_MODE", "", "", P::kPath, "", ""},
      {"exec", C::kEvent, "EXECUTION", "", "", P::kPath, "", ""},
      {"program", C::kEvent, "PROGRAM", "", "", P::kPath, "", ""},
      {"line", C::kEvent, "LINE_NUMBER", "ABSOLUTE", "", P::kPath, "", ""},
      {"path_feedrate", C::kSample, "PATH_FEEDRATE", "ACTUAL", "MILLIMETER/SECOND", P::kPath, "",
       ""},
      {"feed_ovr", C::kEvent, "PATH_FEEDRATE_OVERRIDE", "PROGRAMMED", "", P::kPath, "", ""},
      {"rapid_ovr", C::kEvent, "PATH_FEEDRATE_OVERRIDE", "RAPID", "", P::kPath, "", ""},
      {"tool", C::kEvent, "TOOL_NUMBER", "", "", P::kPath, "", ""},
  };
  if (axes.size() == 3) {
    v.push_back({"path_pos", C::kSample, "PATH_POSITION", "ACTUAL", "MILLIMETER_3D", P::kPath, "",
                 "MACHINE"});
  }
  // contourd's KPIs (extension namespace): the contour error now and the last job's figures.
  v.push_back({"ce", C::kSample, "x:CONTOUR_ERROR", "ACTUAL", "MILLIMETER", P::kPath, "", ""});
  v.push_back({"job", C::kEvent, "x:JOB_NUMBER", "", "", P::kPath, "", ""});
  v.push_back({"job_completed", C::kEvent, "x:JOB_COMPLETED", "", "", P::kPath, "", ""});
  v.push_back({"job_duration", C::kSample, "x:JOB_DURATION", "", "SECOND", P::kPath, "", ""});
  v.push_back(
      {"job_ce_max", C::kSample, "x:CONTOUR_ERROR_MAX", "", "MILLIMETER", P::kPath, "", ""});
  v.push_back(
      {"job_ce_rms", C::kSample, "x:CONTOUR_ERROR_RMS", "", "MILLIMETER", P::kPath, "", ""});
  v.push_back(
      {"job_fe_max", C::kSample, "x:FOLLOWING_ERROR_MAX", "", "MILLIMETER", P::kPath, "", ""});
  for (const auto& a : axes) {
    v.push_back({a + "act", C::kSample, "POSITION", "ACTUAL", "MILLIMETER", P::kAxis, a, "MACHINE"});
    v.push_back(
        {a + "cmd", C::kSample, "POSITION", "COMMANDED", "MILLIMETER", P::kAxis, a, "MACHINE"});
  }
  if (!has_spindle) return v;
  v.push_back({"Srpm", C::kSample, "ROTARY_VELOCITY", "ACTUAL", "REVOLUTION/MINUTE", P::kSpindle,
               "", ""});
  v.push_back({"Scmd", C::kSample, "ROTARY_VELOCITY", "COMMANDED", "REVOLUTION/MINUTE",
               P::kSpindle, "", ""});
  v.push_back({"Sovr", C::kEvent, "ROTARY_VELOCITY_OVERRIDE", "", "", P::kSpindle, "", ""});
  v.push_back({"Smode", C::kEvent, "ROTARY_MODE", "", "", P::kSpindle, "", ""});
  return v;
}

ShdrModel::ShdrModel(const std::vector<std::string>& axes, bool has_spindle)
    : axes_(axes), items_(shdr_items(axes, has_spindle)) {
  for (const auto& it : items_) {
    if (it.category == ItemCategory::kCondition) {
      conditions_[it.key] = {Condition{kUnavailable, "", "", "", ""}};
    } else {
      order_.push_back(it.key);
      values_[it.key] = kUnavailable;
    }
  }
}

std::string ShdrModel::value(const std::string& key) const {
  auto it = values_.find(key);
  return it == values_.end() ? std::string() : it->second;
}

void ShdrModel::set(const std::string& key, const std::string& value) {
  values_[key] = shdr_field(value);
}

void ShdrModel::set_conditions(const std::string& key, std::vector<Condition> active) {
  for (auto& c : active) {
    c.native_code = shdr_field(c.native_code);
    c.native_severity = shdr_field(c.native_severity);
    c.message = shdr_field(c.message);
  }
  conditions_[key] = std::move(active);
}

void ShdrModel::update(const json& st, bool available) {
  if (!available) {
    for (const auto& k : order_) values_[k] = kUnavailable;
    values_["avail"] = "UNAVAILABLE";
    for (auto& [k, c] : conditions_) c = {Condition{kUnavailable, "", "", "", ""}};
    return;
  }
  set("avail", "AVAILABLE");
  const std::string state = st.value("state", std::string());
  const bool estop = state == "ESTOP" ||
                     (st.contains("gpio") && st["gpio"].value("estop_input", false));
  set("estop", estop ? "TRIGGERED" : "ARMED");
  if (st.contains("timing") && st["timing"].contains("overruns")) {
    set("overruns", std::to_string(st["timing"].value("overruns", 0ULL)));
  }
  set("mode", controller_mode_of(st));
  set("exec", execution_of(st));
  if (st.contains("program") && st["program"].is_object()) {
    set("program", st["program"].value("name", std::string()));
  } else {
    set("program", "");
  }
  set("line", std::to_string(st.value("line", 0)));
  set("path_feedrate", fmt("%.3f", path_feed_mm_s(st)));
  const double feed = st.contains("feed_override") && st["feed_override"].is_number()
                          ? st["feed_override"].get<double>()
                          : std::nan("");
  set("feed_ovr", fmt("%.0f", feed * 100.0));
  set("rapid_ovr", st.contains("rapid_override") && st["rapid_override"].is_number()
                       ? fmt("%.0f", st["rapid_override"].get<double>() * 100.0)
                       : kUnavailable);
  if (st.contains("tool") && st["tool"].is_number_integer()) {
    set("tool", std::to_string(st["tool"].get<long>()));
  } else if (st.contains("tool") && st["tool"].is_object() && st["tool"].contains("number")) {
    set("tool", st["tool"]["number"].dump());
  } else {
    set("tool", kUnavailable);
  }
  const json act = st.value("act_mm", json::array());
  const json ref = st.value("ref_mm", json::array());
  if (values_.count("path_pos") != 0) {
    set("path_pos", fmt("%.4f", number_at(act, 0)) + " " + fmt("%.4f", number_at(act, 1)) + " " +
                        fmt("%.4f", number_at(act, 2)));
  }
  for (std::size_t i = 0; i < axes_.size(); ++i) {
    set(axes_[i] + "act", fmt("%.4f", number_at(act, i)));
    set(axes_[i] + "cmd", fmt("%.4f", number_at(ref, i)));
  }
  set("ce", fmt("%.6f", st.value("contour_error_um", std::nan("")) / 1000.0));
  if (values_.count("Srpm") != 0) {
    const json sp = st.value("spindle", json::object());
    set("Srpm", fmt("%.0f", sp.value("actual_rpm", std::nan(""))));
    set("Scmd", fmt("%.0f", sp.value("command_rpm", std::nan(""))));
    set("Smode", "SPINDLE");
    set("Sovr", st.contains("spindle_override") && st["spindle_override"].is_number()
                    ? fmt("%.0f", st["spindle_override"].get<double>() * 100.0)
                    : kUnavailable);
  }
  // Alarms as conditions of `system`.
  std::vector<Condition> active;
  for (const auto& a : alarms_of(st)) {
    Condition c;
    c.level = "FAULT";
    c.native_code = a.value("code", std::string());
    c.native_severity = a.value("severity", std::string());
    std::string msg = a.value("text", std::string());
    if (a.contains("axis") && a["axis"].is_number_integer()) {
      const auto ax = a["axis"].get<long>();
      if (ax >= 0 && static_cast<std::size_t>(ax) < axes_.size()) {
        msg += " (axis " + axes_[static_cast<std::size_t>(ax)] + ")";
      }
    }
    if (a.contains("value") && a.contains("limit") && a["value"].is_number() &&
        a["limit"].is_number()) {
      const double v = a["value"].get<double>();
      const double l = a["limit"].get<double>();
      if (l != 0.0 || v != 0.0) {
        char b[96];
        std::snprintf(b, sizeof b, ": %g beyond limit %g", v, l);
        msg += b;
        c.qualifier = std::abs(v) > std::abs(l) ? "HIGH" : "";
      }
    }
    c.message = msg;
    active.push_back(c);
  }
  set_conditions("system", active);
}

void ShdrModel::set_job_result(const json& r) {
  job_ = r;
  set("job", std::to_string(r.value("job", 0ULL)));
  set("job_completed", r.value("completed", false) ? "true" : "false");
  set("job_duration", fmt("%.3f", r.value("duration_s", std::nan(""))));
  set("job_ce_max", fmt("%.6f", r.value("max_contour_error_um", std::nan("")) / 1000.0));
  set("job_ce_rms", fmt("%.6f", r.value("rms_contour_error_um", std::nan("")) / 1000.0));
  set("job_fe_max", fmt("%.6f", r.value("max_following_error_um", std::nan("")) / 1000.0));
}

std::string ShdrModel::condition_line(const std::string& ts, const std::string& key,
                                      const Condition& c) {
  return ts + "|" + key + "|" + c.level + "|" + c.native_code + "|" + c.native_severity + "|" +
         c.qualifier + "|" + c.message;
}

std::vector<std::string> ShdrModel::changed_lines(const std::string& ts) {
  std::vector<std::string> out;
  std::string line;
  std::size_t pairs = 0;
  for (const auto& k : order_) {
    const std::string& v = values_[k];
    auto it = sent_.find(k);
    if (it != sent_.end() && it->second == v) continue;
    sent_[k] = v;
    if (pairs == kPairsPerLine) {
      out.push_back(line);
      pairs = 0;
    }
    if (pairs == 0) line = ts;
    line += "|" + k + "|" + v;
    ++pairs;
  }
  if (pairs > 0) out.push_back(line);
  for (const auto& [key, active] : conditions_) {
    auto& sent = sent_conditions_[key];
    if (sent && *sent == active) continue;
    const bool unavailable = active.size() == 1 && active[0].level == kUnavailable;
    if (active.empty()) {
      out.push_back(condition_line(ts, key, Condition{"NORMAL", "", "", "", ""}));
    } else if (unavailable) {
      out.push_back(condition_line(ts, key, active[0]));
    } else {
      // Clear the codes no longer active, then state the new or changed ones.
      if (sent) {
        for (const auto& old : *sent) {
          const bool still = std::any_of(active.begin(), active.end(), [&](const Condition& c) {
            return c.native_code == old.native_code;
          });
          if (!still && !old.native_code.empty() && old.level != kUnavailable) {
            out.push_back(
                condition_line(ts, key, Condition{"NORMAL", old.native_code, "", "", ""}));
          }
        }
      }
      for (const auto& c : active) {
        if (!sent || std::find(sent->begin(), sent->end(), c) == sent->end()) {
          out.push_back(condition_line(ts, key, c));
        }
      }
    }
    sent = active;
  }
  return out;
}

std::vector<std::string> ShdrModel::snapshot_lines(const std::string& ts) const {
  std::vector<std::string> out;
  std::string line;
  std::size_t pairs = 0;
  for (const auto& k : order_) {
    if (pairs == kPairsPerLine) {
      out.push_back(line);
      pairs = 0;
    }
    if (pairs == 0) line = ts;
    line += "|" + k + "|" + values_.at(k);
    ++pairs;
  }
  if (pairs > 0) out.push_back(line);
  for (const auto& [key, active] : conditions_) {
    if (active.empty()) {
      out.push_back(condition_line(ts, key, Condition{"NORMAL", "", "", "", ""}));
    } else {
      for (const auto& c : active) out.push_back(condition_line(ts, key, c));
    }
  }
  return out;
}

}  // namespace contour::bridge
