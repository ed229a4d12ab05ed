#pragma once
// MTConnect SHDR for contour-bridge (pure, unit-tested): the data items the adapter serves, their
// values computed from the daemon's status and job results, and the SHDR lines an agent reads:
//   <timestamp>|<key>|<value>[|<key>|<value>...]          events and samples
//   <timestamp>|<key>|<level>|<native_code>|<native_severity>|<qualifier>|<message>   conditions
// (one condition per line; level NORMAL, WARNING, FAULT or UNAVAILABLE; `NORMAL||||` clears every
// active condition of the item). Values never contain '|' or a line break (replaced).
//
// The same item table generates Devices.xml (devices_xml.hpp), so the keys an agent is told about
// and the keys on the wire cannot drift apart. README "MTConnect SHDR items" lists them.
#include <map>
#include <optional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace contour::bridge {

// Where an item sits in the device model.
enum class ItemPlace { kDevice, kController, kPath, kAxis, kSpindle };
enum class ItemCategory { kEvent, kSample, kCondition };

struct ItemDef {
  std::string key;  // SHDR key = DataItem name
  ItemCategory category;
  std::string type;        // MTConnect type (x:... = contourd's extension namespace)
  std::string sub_type;    // "" = none
  std::string units;       // "" = none
  ItemPlace place;
  std::string axis;        // kAxis: the axis name
  std::string coordinate_system;  // "" or MACHINE
};

// The adapter's items for a machine with these axes (names from the machine config) and, when
// `spindle:` configures one, a spindle.
std::vector<ItemDef> shdr_items(const std::vector<std::string>& axes, bool has_spindle);

// Namespace URN of contourd's extension items (Devices.xml declares it as prefix `x`).
inline constexpr const char* kExtensionUrn = "urn:contourd.org:mtconnect:1.0";

struct Condition {
  std::string level;  // NORMAL WARNING FAULT UNAVAILABLE
  std::string native_code;
  std::string native_severity;
  std::string qualifier;  // HIGH LOW or ""
  std::string message;
  bool operator==(const Condition&) const = default;
};

// '|' and line breaks replaced: a value is one SHDR field.
std::string shdr_field(const std::string& s);

class ShdrModel {
 public:
  ShdrModel(const std::vector<std::string>& axes, bool has_spindle);

  // Every item from a status reply; available == false (daemon unreachable): all UNAVAILABLE
  // except avail itself.
  void update(const nlohmann::json& status, bool available);
  // KPIs of the last finished job (the daemon's `result` reply).
  void set_job_result(const nlohmann::json& result);

  // Lines for what changed since the last call (and marks it sent). ts: SHDR time stamp.
  std::vector<std::string> changed_lines(const std::string& ts);
  // Every item's current value: what a newly connected agent gets first.
  [[nodiscard]] std::vector<std::string> snapshot_lines(const std::string& ts) const;

  [[nodiscard]] const std::vector<ItemDef>& items() const { return items_; }
  [[nodiscard]] std::string value(const std::string& key) const;

 private:
  void set(const std::string& key, const std::string& value);
  void set_conditions(const std::string& key, std::vector<Condition> active);
  static std::string condition_line(const std::string& ts, const std::string& key,
                                    const Condition& c);

  std::vector<std::string> axes_;
  std::vector<ItemDef> items_;
  std::vector<std::string> order_;               // data item keys, in table order
  std::map<std::string, std::string> values_;    // current
  std::map<std::string, std::string> sent_;      // as last sent by changed_lines
  std::map<std::string, std::vector<Condition>> conditions_;  // active; empty = NORMAL
  std::map<std::string, std::optional<std::vector<Condition>>> sent_conditions_;
  nlohmann::json job_;                           // last job result
};

}  // namespace contour::bridge
