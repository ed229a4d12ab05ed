#pragma once
// SIGHUP reload (issue 16, "every change is applied or refused, never ignored"): which keys of the
// configuration file changed, and what happens to each one.
//
// The old and the new file are compared as YAML trees, key by key (flattened to dotted paths with
// list indices: "machine.axes[0].max_mm"; a key present in only one of them counts as changed), so
// that no changed key can escape the report, whatever section it is in. Each changed key is
// classified:
//   kLimits    applied live at a cycle boundary through the loop's LiveLimits (safety band and
//              limits, standstill rule, soft limits, axis velocity/acceleration, override and jog
//              maxima) and enforced from that cycle on;
//   kGains     applied live through the gains double buffer (control.*), after the same checks as
//              `gains set` (a structural change the running controller cannot take is refused);
//   kLog       applied at once (log.level);
//   kCompanion read by contour-web / contour-bridge, not by contourd: reported as such;
//   kRestart   everything else: refused with "needs restart" (the running value stays).
// Non-RT, allocates; no I/O (the caller loads the files).
#include <map>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace contour::daemon {

enum class ReloadClass { kLimits, kGains, kLog, kCompanion, kRestart };
const char* to_string(ReloadClass c) noexcept;

// Dotted key path -> scalar text ("~" for null); maps and sequences are expanded.
std::map<std::string, std::string> flatten_yaml(const YAML::Node& root);

struct KeyChange {
  std::string key;
  std::string old_value;  // "<absent>" when the key was not there
  std::string new_value;
  ReloadClass cls = ReloadClass::kRestart;
};
// Changed keys in key order. A whole list that changed length is reported per changed element.
std::vector<KeyChange> diff_config(const YAML::Node& old_root, const YAML::Node& new_root);
ReloadClass classify_key(const std::string& key);

// What one reload did, per key: shown in `status.config.last_reload`, logged, published as events.
struct ReloadReport {
  std::uint64_t cycle = 0;                 // loop cycle when it was applied
  std::vector<std::string> applied;        // "key: old -> new"
  std::vector<std::string> refused;        // "key: old -> new: reason"
  std::vector<std::string> pending_restart;  // keys whose file value differs from the running one
};

}  // namespace contour::daemon
