#pragma once
// Setup-time adapter (composition root): the validated `loop:`, `safety:`, `machine:` and `bus:`
// config -> the master's MasterConfig, drive profiles -> DriveQuirks. It lives in daemon/ so that
// drivers/ depends on nothing above it (tests/layering.sh). Header-only: a program or test that
// links contour::config and contour::drivers can use it without contour::daemon.
#include <cstdint>

#include "config/config.hpp"
#include "drivers/canopen/master.hpp"

namespace contour::daemon {

inline drivers::canopen::PdoMapping to_mapping(const std::vector<config::BusPdoEntry>& v) {
  drivers::canopen::PdoMapping m;
  for (const auto& e : v) {
    if (m.count >= drivers::canopen::PdoMapping::kMaxEntries) break;
    m.entries[m.count++] = drivers::canopen::PdoEntry{e.index, e.sub, e.bits};
  }
  return m;
}

inline drivers::canopen::DriveQuirks to_quirks(const config::DriveProfile& p) {
  namespace co = drivers::canopen;
  co::DriveQuirks q;
  q.profile = p.name;
  for (const auto& o : p.skip_objects) q.skip.push_back(co::ObjectRef{o.index, o.sub});
  q.rpdos = static_cast<std::uint8_t>(p.rpdos);
  q.tpdos = static_cast<std::uint8_t>(p.tpdos);
  q.rpdo_max_entries = static_cast<std::uint8_t>(p.rpdo_max_entries);
  q.tpdo_max_entries = static_cast<std::uint8_t>(p.tpdo_max_entries);
  q.expedited_only = p.sdo == "expedited_only";
  q.feedback = p.tpdo_sampling == "after_step" ? co::FeedbackTiming::kAfterStep
                                               : co::FeedbackTiming::kAtSync;
  return q;
}

// Which axis nodes map 0x60FD (TPDO2) and which 0x60FE:01 bits (RPDO2): the axes homed on a
// switch (home.method switch: the home switch is 0x60FD bit 2) and the PLC's cia402 bindings
// (plc.signals). Axis i is node i of `c` (resolve_bus_nodes: axes first, in machine.axes order).
// Other nodes keep their mapping as it was.
inline void add_digital_io(const config::Config& cfg, drivers::canopen::MasterConfig& c) {
  for (std::size_t a = 0; a < cfg.machine.axes.size() && a < c.nodes.size(); ++a) {
    if (cfg.machine.axes[a].home.method == config::HomeConfig::Method::kSwitch) c.nodes[a].digital_inputs = true;
  }
  if (!cfg.plc.present) return;
  for (const auto& sig : cfg.plc.signals) {
    const auto& b = sig.binding;
    if (b.kind != config::PlcBindingKind::kCia402 || b.axis < 0) continue;
    const auto a = static_cast<std::size_t>(b.axis);
    if (a >= cfg.machine.axes.size() || a >= c.nodes.size()) continue;
    auto& n = c.nodes[a];
    if (sig.direction == config::PlcDirection::kInput) {
      n.digital_inputs = true;
    } else if (sig.direction == config::PlcDirection::kOutput && b.bit >= 0 && b.bit < 32) {
      n.digital_output_mask |= 1u << b.bit;
    }
  }
}

// The axes homed on a switch with home.use_index map the drive's touch probe 1 (0x60B8 in an
// RPDO, 0x60B9 + 0x60BA in a TPDO: NodeSetup::touch_probe), the encoder index latch. Axis i is
// node i of `c`; other nodes map nothing of it.
inline void add_touch_probe(const config::Config& cfg, drivers::canopen::MasterConfig& c) {
  for (std::size_t a = 0; a < cfg.machine.axes.size() && a < c.nodes.size(); ++a) {
    const config::HomeConfig& h = cfg.machine.axes[a].home;
    if (h.method == config::HomeConfig::Method::kSwitch && h.use_index) c.nodes[a].touch_probe = true;
  }
}

// The PLC's cia401 bindings (plc.signals) -> one CiA 401 I/O module node per node-id, after the
// drives, in the order the signals first name them; each maps only the sub-indices the signals
// use (IoModuleMap). Heartbeat and transmission type: bus.drives' (heartbeat_ms,
// heartbeat_timeout_ms, sync_every). A node-id that is also a drive's is a ConfigError naming
// the signal.
inline void add_io_modules(const config::Config& cfg, drivers::canopen::MasterConfig& c) {
  namespace co = drivers::canopen;
  if (!cfg.plc.present) return;
  const std::size_t drives = c.nodes.size();
  for (const auto& sig : cfg.plc.signals) {
    const auto& b = sig.binding;
    if (b.kind != config::PlcBindingKind::kCia401) continue;
    if (b.address < 1 || b.address > co::kIoChannels) continue;  // the engine refuses it
    co::NodeSetup* n = nullptr;
    for (std::size_t i = 0; i < c.nodes.size(); ++i) {
      if (c.nodes[i].node_id != b.node_id) continue;
      if (i < drives) {
        throw config::ConfigError({sig.where + ": plc.signals '" + sig.name + "': cia401.node " +
                                   std::to_string(b.node_id) + " is the node of drive '" +
                                   c.nodes[i].name + "'"});
      }
      n = &c.nodes[i];
    }
    if (n == nullptr) {
      co::NodeSetup s;
      s.kind = co::NodeKind::kIoModule;
      s.node_id = static_cast<std::uint8_t>(b.node_id);
      s.name = "I/O module";
      s.heartbeat_ms = static_cast<std::uint16_t>(cfg.bus.drive_defaults.heartbeat_ms);
      s.heartbeat_timeout_ms =
          static_cast<std::uint16_t>(cfg.bus.drive_defaults.heartbeat_timeout_ms);
      s.sync_every = static_cast<std::uint8_t>(cfg.bus.drive_defaults.sync_every);
      s.quirks.profile = "cia401";
      c.nodes.push_back(s);
      n = &c.nodes.back();
    }
    const auto bit = static_cast<std::uint8_t>(1u << (b.address - 1));
    switch (b.object) {
      case config::Cia401Object::kDigitalInput:
        n->io.digital_inputs |= bit;
        break;
      case config::Cia401Object::kDigitalOutput:
        n->io.digital_outputs |= bit;
        break;
      case config::Cia401Object::kAnalogInput:
        n->io.analog_inputs |= bit;
        break;
      case config::Cia401Object::kAnalogOutput:
        n->io.analog_outputs |= bit;
        break;
    }
  }
}

// Throws config::ConfigError (duplicate node-ids, ...).
inline drivers::canopen::MasterConfig master_config_from(const config::Config& cfg) {
  using drivers::canopen::DriveMode;
  using drivers::canopen::MasterConfig;
  using drivers::canopen::NodeSetup;
  const config::BusConfig& bus = cfg.bus;
  const config::MachineConfig& machine = cfg.machine;
  MasterConfig c;
  c.period_us = static_cast<std::uint32_t>(cfg.loop.period_us);
  c.bitrate = static_cast<std::uint32_t>(bus.bitrate);
  c.load_ceiling = bus.load_ceiling_percent / 100.0;
  c.master_heartbeat_ms = static_cast<std::uint16_t>(bus.master_heartbeat_ms);
  c.boot_timeout_ms = bus.boot_timeout_ms;
  c.sdo_timeout_ms = bus.sdo_timeout_ms;
  c.sdo_retries = bus.sdo_retries;
  c.tpdo_deadline_us = cfg.loop.tpdo_deadline_us;
  c.missed_tpdo_fault = cfg.safety.missed_tpdo_streak;
  for (const auto& n : config::resolve_bus_nodes(bus, machine)) {
    NodeSetup s;
    s.node_id = static_cast<std::uint8_t>(n.node_id);
    s.name = n.role;
    s.mode = n.mode == "csp" ? DriveMode::kCsp
             : n.mode == "pv" ? DriveMode::kProfileVelocity
                              : DriveMode::kCsv;
    s.heartbeat_ms = static_cast<std::uint16_t>(n.heartbeat_ms);
    s.heartbeat_timeout_ms = static_cast<std::uint16_t>(n.heartbeat_timeout_ms);
    s.sync_window_us = static_cast<std::uint32_t>(n.sync_window_us);
    s.sync_every = static_cast<std::uint8_t>(n.sync_every);
    s.quick_stop_option = static_cast<std::int16_t>(n.quick_stop_option);
    s.quick_stop_decel = static_cast<std::uint32_t>(n.quick_stop_decel);
    s.device_type = n.identity.device_type;
    s.vendor_id = n.identity.vendor_id;
    s.product_code = n.identity.product_code;
    s.revision = n.identity.revision;
    s.rpdo = to_mapping(n.rpdo);
    s.tpdo = to_mapping(n.tpdo);
    s.quirks = to_quirks(n.profile);
    c.nodes.push_back(s);
  }
  add_digital_io(cfg, c);
  add_touch_probe(cfg, c);
  add_io_modules(cfg, c);
  return c;
}

}  // namespace contour::daemon
