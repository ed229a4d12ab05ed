#include "config/bus_config.hpp"

#include <algorithm>
#include <cstdlib>

namespace contour::config {

int known_object_bits(std::uint16_t index) {
  switch (index) {
    case 0x6040: case 0x6041: case 0x603F: case 0x6071: case 0x6072: case 0x6077: return 16;
    case 0x6060: case 0x6061: return 8;
    case 0x6064: case 0x606C: case 0x607A: case 0x60FF: case 0x60F4: case 0x6062: return 32;
    default: return 0;
  }
}

namespace {

std::vector<BusPdoEntry> default_rpdo(const std::string& mode) {
  return {{0x6040, 0, 16}, {static_cast<std::uint16_t>(mode == "csp" ? 0x607A : 0x60FF), 0, 32}};
}

std::vector<BusPdoEntry> parse_pdo_list(Section& s, const std::string& key,
                                        const std::vector<BusPdoEntry>& def) {
  s.accept(key);
  if (!s.has(key)) return def;
  const YAML::Node n = s.node()[key];
  const std::string path = s.path().empty() ? key : s.path() + "." + key;
  std::vector<BusPdoEntry> out;
  if (!n.IsSequence() || n.size() == 0 || n.size() > 8) {
    s.diag().error(n, path, "expected a list of 1 to 8 objects (\"0x6041\" or \"0x6041:0:16\")");
    return def;
  }
  int bits = 0;
  for (std::size_t i = 0; i < n.size(); ++i) {
    const std::string txt = n[i].IsScalar() ? n[i].Scalar() : std::string();
    const std::string p = path + "[" + std::to_string(i) + "]";
    char* end = nullptr;
    const unsigned long idx = std::strtoul(txt.c_str(), &end, 0);
    BusPdoEntry e;
    e.index = static_cast<std::uint16_t>(idx);
    bool ok = end != txt.c_str() && idx > 0 && idx <= 0xFFFF;
    if (ok && *end == ':') {
      const unsigned long sub = std::strtoul(end + 1, &end, 0);
      unsigned long b = 0;
      if (*end == ':') b = std::strtoul(end + 1, &end, 0);
      ok = sub <= 0xFF && (b == 8 || b == 16 || b == 32) && *end == '\0';
      e.sub = static_cast<std::uint8_t>(sub);
      e.bits = static_cast<std::uint8_t>(b);
    } else if (ok) {
      ok = *end == '\0';
      e.bits = static_cast<std::uint8_t>(known_object_bits(e.index));
      if (ok && e.bits == 0) {
        s.diag().error(n[i], p, "object " + txt + " has no known size: write it as \"" + txt +
                                    ":SUB:BITS\"");
        continue;
      }
    }
    if (!ok) {
      s.diag().error(n[i], p, "expected \"0xIIII\" or \"0xIIII:SUB:BITS\", got '" + txt + "'");
      continue;
    }
    bits += e.bits;
    out.push_back(e);
  }
  if (bits > 64) s.diag().error(n, path, "mapping exceeds 64 bits (8 bytes per PDO)");
  return out;
}

std::optional<std::uint32_t> opt_u32(Section& s, const std::string& key) {
  if (!s.has(key)) {
    s.accept(key);
    return std::nullopt;
  }
  return static_cast<std::uint32_t>(s.integer(key, 0, 0, 0xFFFFFFFFL));
}

// Reads the node keys present in `s` on top of `base`.
BusNodeConfig parse_node(Section& s, const BusNodeConfig& base, bool spindle,
                         const std::map<std::string, DriveProfile>& profiles) {
  BusNodeConfig n = base;
  {
    const std::string name = s.string("profile", base.profile.name);
    if (auto it = profiles.find(name); it != profiles.end()) {
      n.profile = it->second;
    } else {
      std::string known;
      for (const auto& kv : profiles) known += (known.empty() ? "" : ", ") + kv.first;
      s.error("profile", "unknown drive profile '" + name + "' (known: " + known +
                             "; define it in bus.profiles or bus.profile_files)");
    }
  }
  const std::vector<std::string> modes =
      spindle ? std::vector<std::string>{"csv", "pv"} : std::vector<std::string>{"csv", "csp"};
  n.mode = s.choice("mode", base.mode, modes);
  n.heartbeat_ms = static_cast<int>(s.integer("heartbeat_ms", base.heartbeat_ms, 0, 65535));
  n.heartbeat_timeout_ms =
      static_cast<int>(s.integer("heartbeat_timeout_ms", base.heartbeat_timeout_ms, 0, 65535));
  if (n.heartbeat_ms > 0 && n.heartbeat_timeout_ms > 0 && n.heartbeat_timeout_ms <= n.heartbeat_ms)
    s.error("heartbeat_timeout_ms", "must be longer than heartbeat_ms");
  n.sync_window_us = static_cast<int>(s.integer("sync_window_us", base.sync_window_us, 0, 1000000));
  n.sync_every = static_cast<int>(s.integer("sync_every", base.sync_every, 1, 240));
  n.quick_stop_option =
      static_cast<int>(s.integer("quick_stop_option", base.quick_stop_option, 0, 8));
  n.quick_stop_decel = s.integer("quick_stop_decel", base.quick_stop_decel, 1, 0xFFFFFFFFL);
  {
    Section id = s.child("identity");
    if (id.present()) {
      n.identity.device_type = opt_u32(id, "device_type");
      n.identity.vendor_id = opt_u32(id, "vendor_id");
      n.identity.product_code = opt_u32(id, "product_code");
      n.identity.revision = opt_u32(id, "revision");
    }
    id.finish();
  }
  const bool mode_changed = n.mode != base.mode;
  n.rpdo = parse_pdo_list(s, "rpdo", mode_changed ? default_rpdo(n.mode) : base.rpdo);
  n.tpdo = parse_pdo_list(s, "tpdo", base.tpdo);
  // The master maps everything into RPDO1/TPDO1: it must fit the drive's PDO.
  const struct {
    const char* key;
    const std::vector<BusPdoEntry>& map;
    int max;
  } checks[2] = {{"rpdo", n.rpdo, n.profile.rpdo_max_entries},
                 {"tpdo", n.tpdo, n.profile.tpdo_max_entries}};
  for (const auto& c : checks) {
    if (static_cast<int>(c.map.size()) <= c.max) continue;
    s.error(s.has(c.key) ? c.key : "profile",
            std::string(c.key) + " maps " + std::to_string(c.map.size()) +
                " objects, drive profile '" + n.profile.name + "' allows " +
                std::to_string(c.max) + " per PDO (" + c.key + "_max_entries)");
  }
  return n;
}

}  // namespace

BusConfig parse_bus(Section& s) {
  BusConfig b;
  b.type = s.choice("type", "sim", {"sim", "socketcan"});
  b.interface = s.string("interface", b.type == "socketcan" ? "can0" : "");
  b.bitrate = s.integer("bitrate", 1000000, 10000, 1000000);
  b.load_ceiling_percent = s.number("load_ceiling_percent", 80.0, 1.0, 100.0);
  b.master_heartbeat_ms = static_cast<int>(s.integer("master_heartbeat_ms", 100, 0, 65535));
  b.boot_timeout_ms = static_cast<int>(s.integer("boot_timeout_ms", 2000, 1000, 60000));
  b.sdo_timeout_ms = static_cast<int>(s.integer("sdo_timeout_ms", 500, 10, 10000));
  b.sdo_retries = static_cast<int>(s.integer("sdo_retries", 2, 0, 10));

  b.profiles = builtin_drive_profiles();
  s.accept("profile_files");
  if (s.has("profile_files")) {
    const YAML::Node files = s.node()["profile_files"];
    const std::string path = s.path().empty() ? "profile_files" : s.path() + ".profile_files";
    if (!files.IsSequence()) {
      s.diag().error(files, path, "expected a list of file names");
    } else {
      const std::string& src = s.diag().file();
      const auto slash = src.rfind('/');
      const std::string dir = slash == std::string::npos ? "" : src.substr(0, slash + 1);
      for (std::size_t i = 0; i < files.size(); ++i) {
        const std::string p = path + "[" + std::to_string(i) + "]";
        if (!files[i].IsScalar() || files[i].Scalar().empty()) {
          s.diag().error(files[i], p, "expected a file name");
          continue;
        }
        const std::string f = files[i].Scalar();
        b.profile_files.push_back(f);
        try {
          for (auto& [name, prof] : load_drive_profile_file(f.front() == '/' ? f : dir + f)) {
            const auto builtin = builtin_drive_profiles();
            if (b.profiles.count(name) != 0 && builtin.count(name) == 0)
              s.diag().error(files[i], p, "profile '" + name + "' is defined twice");
            else
              b.profiles[name] = prof;
          }
        } catch (const ConfigError& e) {
          for (const auto& m : e.errors()) s.diag().error(files[i], p, m);
        }
      }
    }
  }
  {
    Section ps = s.child("profiles");
    parse_drive_profiles(ps, b.profiles);
    ps.finish();
  }

  BusNodeConfig base;
  base.profile = b.profiles.at("generic");
  base.rpdo = default_rpdo("csv");
  base.tpdo = {{0x6041, 0, 16}, {0x6064, 0, 32}};
  {
    Section d = s.child("drives");
    b.drive_defaults = parse_node(d, base, false, b.profiles);
    d.finish();
  }
  for (Section& o : s.list("nodes")) {
    BusNodeConfig n = parse_node(o, b.drive_defaults, false, b.profiles);
    n.node_id = static_cast<int>(o.required_integer("node_id", 1, 127));
    std::vector<std::string> keys;
    for (const auto& kv : o.node()) keys.push_back(kv.first.as<std::string>());
    b.node_overrides.push_back(n);
    b.override_keys.push_back(keys);
    o.finish();
  }
  {
    Section sp = s.child("spindle");
    if (sp.present()) {
      BusNodeConfig sbase = b.drive_defaults;
      sbase.mode = "csv";
      sbase.sync_every = 10;  // a spindle speed changes slowly: keep the bus for the axes
      sbase.rpdo = default_rpdo("csv");
      sbase.tpdo = {{0x6041, 0, 16}, {0x606C, 0, 32}};
      BusNodeConfig n = parse_node(sp, sbase, true, b.profiles);
      n.node_id = static_cast<int>(sp.required_integer("node_id", 1, 127));
      n.role = "spindle";
      b.spindle = n;
    }
    sp.finish();
  }
  if (b.type == "socketcan" && b.interface.empty()) s.error("interface", "required for socketcan");
  return b;
}

std::vector<BusNodeConfig> resolve_bus_nodes(const BusConfig& bus, const MachineConfig& machine) {
  std::vector<BusNodeConfig> out;
  for (const auto& ax : machine.axes) {
    if (ax.node_id == 0) continue;
    BusNodeConfig n = bus.drive_defaults;
    for (const auto& o : bus.node_overrides)
      if (o.node_id == ax.node_id) n = o;
    n.node_id = ax.node_id;
    n.role = ax.name;
    out.push_back(n);
  }
  if (bus.spindle) out.push_back(*bus.spindle);
  std::vector<std::string> errors;
  for (std::size_t i = 0; i < out.size(); ++i)
    for (std::size_t j = i + 1; j < out.size(); ++j)
      if (out[i].node_id == out[j].node_id)
        errors.push_back("bus: node-id " + std::to_string(out[i].node_id) + " used by " +
                         out[i].role + " and " + out[j].role);
  for (const auto& o : bus.node_overrides) {
    const bool used = std::any_of(out.begin(), out.end(),
                                  [&](const BusNodeConfig& n) { return n.node_id == o.node_id; });
    if (!used)
      errors.push_back("bus.nodes: node_id " + std::to_string(o.node_id) +
                       " is not an axis node (machine.axes[].node_id)");
  }
  if (!errors.empty()) throw ConfigError(errors);
  return out;
}

}  // namespace contour::config
