#pragma once
// `bus:` section: the field bus behind the axes (CANopen over SocketCAN, or the in-process sim).
//
//   bus:
//     type: socketcan            # sim | socketcan
//     interface: vcan0
//     bitrate: 1000000           # bit/s (bus-load estimate only; the link is set up by the OS)
//     load_ceiling_percent: 80   # refuse start-up above this worst-case (bit-stuffed) load
//     master_heartbeat_ms: 100   # master's own heartbeat (drives consume it, 0x1016)
//     boot_timeout_ms: 2000      # wait for boot-ups after NMT reset communication (>= 1000)
//     sdo_timeout_ms: 500
//     sdo_retries: 2
// (The TPDO receive deadline is loop.tpdo_deadline_us, the missed-TPDO streak that faults is
// safety.missed_tpdo_streak, the SYNC period is loop.period_us.)
//     profile_files: [drives/acme.yaml]   # drive profiles (config/drive_profiles.hpp), relative
//     profiles: {acme-x1: {rpdos: 1, ...}} #   to this file, and inline
//     drives: {profile: generic, mode: csv, heartbeat_ms: 50, heartbeat_timeout_ms: 200, sync_window_us: 0,
//              quick_stop_option: 2, quick_stop_decel: 2000000, rpdo: [...], tpdo: [...]}
//     nodes: [{node_id: 2, mode: csp, identity: {vendor_id: 0x1234}}]   # per-node overrides
//     spindle: {node_id: 4, mode: csv, sync_every: 10, ...}
// Node-ids of the axes come from machine.axes[].node_id. PDO entries are "0xIIII" (size from
// the CiA 402 object table) or "0xIIII:SS:BITS".
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "config/drive_profiles.hpp"
#include "config/machine_config.hpp"
#include "config/yaml_reader.hpp"

namespace contour::config {

struct BusPdoEntry {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::uint8_t bits = 0;
};

struct BusIdentity {
  std::optional<std::uint32_t> device_type;   // 0x1000
  std::optional<std::uint32_t> vendor_id;     // 0x1018:1
  std::optional<std::uint32_t> product_code;  // 0x1018:2
  std::optional<std::uint32_t> revision;      // 0x1018:3
};

struct BusNodeConfig {
  int node_id = 0;
  std::string role;         // "X", "Y", "Z" or "spindle"
  std::string mode = "csv";  // csv (0x6060 = 9), csp (8), pv (3, spindle only)
  int heartbeat_ms = 50;          // drive's producer time 0x1017
  int heartbeat_timeout_ms = 200;  // master's consumer timeout for this node
  int sync_window_us = 0;         // 0x1007 (0 = not written)
  int sync_every = 1;             // PDO transmission type (1 = every SYNC)
  int quick_stop_option = 2;      // 0x605A
  std::int64_t quick_stop_decel = 2000000;  // 0x6085, counts/s^2 (drive units)
  BusIdentity identity;
  DriveProfile profile;           // resolved from `profile: NAME` (default generic)
  std::vector<BusPdoEntry> rpdo;  // RPDO1 mapping (master -> drive)
  std::vector<BusPdoEntry> tpdo;  // TPDO1 mapping (drive -> master)
};

struct BusConfig {
  std::string type = "sim";
  std::string interface = "can0";
  long bitrate = 1000000;
  double load_ceiling_percent = 80.0;
  int master_heartbeat_ms = 100;
  int boot_timeout_ms = 2000;
  int sdo_timeout_ms = 500;
  int sdo_retries = 2;
  std::vector<std::string> profile_files;        // as written (relative to the config file)
  std::map<std::string, DriveProfile> profiles;  // built-ins, files, then bus.profiles
  BusNodeConfig drive_defaults;
  std::vector<BusNodeConfig> node_overrides;  // only keys present override
  std::vector<std::vector<std::string>> override_keys;  // keys present per override
  std::optional<BusNodeConfig> spindle;
};

BusConfig parse_bus(Section& s);

// The bus nodes in order: the machine's axes with node_id != 0 (X, Y, Z order), then the
// spindle. Throws ConfigError on duplicate node-ids.
std::vector<BusNodeConfig> resolve_bus_nodes(const BusConfig& bus, const MachineConfig& machine);

// Bit length of a CiA 301/402 object commonly mapped (0 when unknown).
int known_object_bits(std::uint16_t index);

}  // namespace contour::config
