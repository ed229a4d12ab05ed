#include "daemon/config_reload.hpp"

#include <regex>
#include <set>

namespace contour::daemon {

const char* to_string(ReloadClass c) noexcept {
  switch (c) {
    case ReloadClass::kLimits: return "limits";
    case ReloadClass::kGains: return "gains";
    case ReloadClass::kLog: return "log";
    case ReloadClass::kCompanion: return "companion";
    case ReloadClass::kRestart: return "restart";
  }
  return "?";
}

namespace {

void flatten(const YAML::Node& n, const std::string& path, std::map<std::string, std::string>& out) {
  if (n.IsMap()) {
    if (n.size() == 0) out[path] = "{}";
    for (const auto& kv : n) {
      const std::string k = kv.first.as<std::string>();
      flatten(kv.second, path.empty() ? k : path + "." + k, out);
    }
  } else if (n.IsSequence()) {
    if (n.size() == 0) out[path] = "[]";
    for (std::size_t i = 0; i < n.size(); ++i) flatten(n[i], path + "[" + std::to_string(i) + "]", out);
  } else if (n.IsScalar()) {
    out[path] = n.Scalar();
  } else {
    out[path] = "~";
  }
}

}  // namespace

std::map<std::string, std::string> flatten_yaml(const YAML::Node& root) {
  std::map<std::string, std::string> out;
  if (root.IsDefined() && !root.IsNull()) flatten(root, "", out);
  return out;
}

ReloadClass classify_key(const std::string& key) {
  // List indices are irrelevant to the class: machine.axes[2].max_mm -> machine.axes[].max_mm.
  static const std::regex index(R"(\[[0-9]+\])");
  const std::string k = std::regex_replace(key, index, "[]");
  static const std::set<std::string> limits = {
      "safety.ferror_mm",
      "safety.min_ferror_mm",
      "safety.contour_error_limit_mm",
      "safety.stop_decel_mm_s2",
      "safety.standstill_velocity_mm_s",
      "safety.standstill_time_s",
      "safety.standstill_timeout_s",
      "safety.jog_max_velocity_mm_min",
      "machine.axes[].min_mm",
      "machine.axes[].max_mm",
      "machine.axes[].max_velocity_mm_min",
      "machine.axes[].max_accel_mm_s2",
      "interpolator.feed_override_max_percent",
      "interpolator.rapid_override_max_percent",
      "spindle.override_min_percent",
      "spindle.override_max_percent",
  };
  if (limits.count(k) != 0) return ReloadClass::kLimits;
  auto under = [&](const char* section) {
    const std::string s(section);
    return k == s || k.compare(0, s.size() + 1, s + ".") == 0 || k.compare(0, s.size() + 1, s + "[") == 0;
  };
  if (under("control")) return ReloadClass::kGains;
  if (k == "log.level") return ReloadClass::kLog;
  if (under("mqtt") || under("mtconnect") || under("web")) return ReloadClass::kCompanion;
  return ReloadClass::kRestart;
}

std::vector<KeyChange> diff_config(const YAML::Node& old_root, const YAML::Node& new_root) {
  const auto a = flatten_yaml(old_root);
  const auto b = flatten_yaml(new_root);
  std::vector<KeyChange> out;
  auto ia = a.begin();
  auto ib = b.begin();
  auto add = [&](const std::string& key, const std::string& o, const std::string& n) {
    out.push_back({key, o, n, classify_key(key)});
  };
  while (ia != a.end() || ib != b.end()) {
    if (ib == b.end() || (ia != a.end() && ia->first < ib->first)) {
      add(ia->first, ia->second, "<absent>");
      ++ia;
    } else if (ia == a.end() || ib->first < ia->first) {
      add(ib->first, "<absent>", ib->second);
      ++ib;
    } else {
      if (ia->second != ib->second) add(ia->first, ia->second, ib->second);
      ++ia;
      ++ib;
    }
  }
  return out;
}

}  // namespace contour::daemon
