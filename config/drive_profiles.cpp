#include "config/drive_profiles.hpp"

#include <algorithm>
#include <cstdlib>

namespace contour::config {

bool DriveProfile::same_settings(const DriveProfile& o) const {
  return skip_objects == o.skip_objects && rpdos == o.rpdos && tpdos == o.tpdos &&
         rpdo_max_entries == o.rpdo_max_entries && tpdo_max_entries == o.tpdo_max_entries &&
         sdo == o.sdo && tpdo_sampling == o.tpdo_sampling;
}

const std::vector<std::uint16_t>& skippable_objects() {
  static const std::vector<std::uint16_t> v = {0x1006, 0x1007, 0x1008, 0x1016,
                                               0x605A, 0x6085, 0x60C2};
  return v;
}

std::map<std::string, DriveProfile> builtin_drive_profiles() {
  std::map<std::string, DriveProfile> m;
  DriveProfile g;
  g.name = "generic";
  g.description = "complete CiA 301/402 drive (every optional object, 4 PDOs of 8 entries)";
  m[g.name] = g;
  DriveProfile s = g;
  s.name = "contour-machine-sim";
  s.description = "contour-machine-sim's simulated drive";
  m[s.name] = s;
  return m;
}

namespace {

std::vector<ProfileObject> parse_objects(Section& s, const std::string& key) {
  s.accept(key);
  std::vector<ProfileObject> out;
  if (!s.has(key)) return out;
  const YAML::Node n = s.node()[key];
  const std::string path = s.path().empty() ? key : s.path() + "." + key;
  if (!n.IsSequence()) {
    s.diag().error(n, path, "expected a list of objects (\"0x1006\" or \"0x60C2:01\")");
    return out;
  }
  const auto& allowed = skippable_objects();
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string txt = n[i].IsScalar() ? n[i].Scalar() : std::string();
    const std::string p = path + "[" + std::to_string(i) + "]";
    char* end = nullptr;
    const unsigned long idx = std::strtoul(txt.c_str(), &end, 0);
    ProfileObject o;
    bool ok = !txt.empty() && end != txt.c_str() && idx > 0 && idx <= 0xFFFF;
    o.index = static_cast<std::uint16_t>(idx);
    if (ok && *end == ':') {
      const char* start = end + 1;
      const unsigned long sub = std::strtoul(start, &end, 0);
      ok = end != start && sub <= 0xFF && *end == '\0';
      o.sub = static_cast<int>(sub);
    } else if (ok) {
      ok = *end == '\0';
    }
    if (!ok) {
      s.diag().error(n[i], p, "expected \"0xIIII\" or \"0xIIII:SUB\", got '" + txt + "'");
      continue;
    }
    if (std::find(allowed.begin(), allowed.end(), o.index) == allowed.end()) {
      s.diag().error(n[i], p,
                     "object " + txt +
                         " cannot be skipped: the master needs it (skippable: 0x1006 0x1007 "
                         "0x1008 0x1016 0x605A 0x6085 0x60C2)");
      continue;
    }
    out.push_back(o);
  }
  return out;
}

}  // namespace

DriveProfile parse_drive_profile(Section& s, const std::string& name) {
  DriveProfile p;
  p.name = name;
  p.description = s.string("description", "");
  p.skip_objects = parse_objects(s, "skip_objects");
  p.rpdos = static_cast<int>(s.integer("rpdos", 4, 1, 4));
  p.tpdos = static_cast<int>(s.integer("tpdos", 4, 1, 4));
  p.rpdo_max_entries = static_cast<int>(s.integer("rpdo_max_entries", 8, 1, 8));
  p.tpdo_max_entries = static_cast<int>(s.integer("tpdo_max_entries", 8, 1, 8));
  p.sdo = s.choice("sdo", "segmented", {"segmented", "expedited_only"});
  p.tpdo_sampling = s.choice("tpdo_sampling", "sync", {"sync", "after_step"});
  return p;
}

void parse_drive_profiles(Section& s, std::map<std::string, DriveProfile>& out) {
  if (!s.present()) return;
  const auto builtin = builtin_drive_profiles();
  for (const auto& kv : s.node()) {
    const std::string name = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
    s.accept(name);
    const std::string path = s.path().empty() ? name : s.path() + "." + name;
    if (name.empty()) {
      s.diag().error(kv.first, path, "a profile name must be a string");
      continue;
    }
    Section p(kv.second, path, s.diag());
    DriveProfile d = parse_drive_profile(p, name);
    p.finish();
    // The shipped files (config/drives/) restate the built-ins; changing one is an error.
    if (auto b = builtin.find(name); b != builtin.end() && !b->second.same_settings(d)) {
      s.diag().error(kv.first, path,
                     "'" + name + "' is a built-in profile and cannot be changed; copy it under "
                     "another name");
      continue;
    }
    if (out.count(name) != 0 && builtin.count(name) == 0) {
      s.diag().error(kv.first, path, "profile '" + name + "' is defined twice");
      continue;
    }
    out[name] = d;
  }
}

std::map<std::string, DriveProfile> load_drive_profile_file(const std::string& path) {
  const YAML::Node root = load_yaml_file(path);
  Diagnostics diag(path);
  std::map<std::string, DriveProfile> out;
  {
    Section s(root, "", diag);
    if (!s.present()) diag.error(root, "", "empty profile file (expected a map name -> profile)");
    parse_drive_profiles(s, out);
    s.finish();
  }
  diag.throw_if_any();
  return out;
}

}  // namespace contour::config
