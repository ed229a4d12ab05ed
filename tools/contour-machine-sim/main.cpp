// contour-machine-sim --config FILE --can IFACE [--modbus HOST:PORT] [fault flags] [quirk flags]
//                     [--storm SEED [--storm-interval SYNCS] [--storm-kinds LIST]]
// Quirks (drives that are not a complete CiA 301/402 drive, sim_drive.hpp SimQuirks):
// --missing-object NODE:INDEX[:SUB], --pdos NODE:COUNT[:MAX_ENTRIES], --expedited-only NODE,
// --tpdo-sampling NODE:sync|after_step (default: the node's drive profile, bus.*.profile).
// CiA 402 digital inputs 0x60FD (sim_drive.hpp InputSwitch): every axis drive has negative_limit,
// positive_limit and home_switch switches at its soft limits; --input-switch
// NODE:BIT:above|below:POS_MM adds one (bit on while the position is above/below POS_MM).
// 0x60FE:01 (digital outputs) is stored and readable over SDO.
// Encoder index and touch probe 1 (0x60B8..0x60BA, sim_drive.hpp): each axis drive's encoder
// has the index of its axis' machine.axes[].sim.index_pitch_mm / index_phase_mm (none without);
// --index NODE|all:PITCH_MM[:PHASE_MM] sets it (pitch 0: none), --no-touch-probe NODE removes the
// touch probe objects (a drive the master must refuse for home.use_index). The summary's axis
// node entries gain "index_latches" and "last_index_mm" (true position of the last pulse latched).
// CiA 401 I/O modules (sim_drive.hpp SimIoModule): --io-module NODE[:DI:DO:AI:AO] adds one
// (DI/DO bytes of 0x6000/0x6200, AI/AO INTEGER16 channels of 0x6401/0x6411, 0..8 each, default
// 2:2:2:2); its outputs are looped to its inputs each SYNC; --io-input NODE:SUB:VALUE pins
// 0x6000:SUB to VALUE (not looped). The fault and quirk flags (--drop-tpdo, --drop-tpdo2, --stop-heartbeat,
// --missing-object, --pdos, ...) take its node-id too. The summary's node entry shows its
// objects: "io": {"0x6000": [...], "0x6200": [...], "0x6401": [...], "0x6411": [...]}.
// The simulated machine for HIL: one process answering every bus node of the config (axes from
// machine.axes[].node_id, the spindle from bus.spindle.node_id) as CiA 402 drives on SocketCAN,
// advancing one plant step per SYNC (lockstep). Prints "ready: ..." on stdout once listening and a
// JSON summary as its last line on SIGINT/SIGTERM.
// --storm SEED: seeded random fault injection scheduled in SYNC counts (storm.hpp: kinds, gating,
// schedule); each injected event is one JSON line on stdout ({"storm":KIND,...}, flushed at
// once), and the summary gains "storm": {seed, events per kind, tpdo_dropped, emcy_sent}.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "drivers/can/socket_can.hpp"
#include "tools/contour-machine-sim/dynamometer_server.hpp"
#include "tools/contour-machine-sim/plant_io.hpp"
#include "tools/contour-machine-sim/sim_drive.hpp"
#include "tools/contour-machine-sim/storm.hpp"

namespace {

volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

// "N:A[:B]" -> {N, A, B}; throws CLI::ValidationError.
std::vector<long> parse_tuple(const std::string& s, std::size_t min_n, std::size_t max_n,
                              const std::string& flag) {
  std::vector<long> out;
  std::size_t pos = 0;
  while (pos <= s.size()) {
    const std::size_t c = s.find(':', pos);
    const std::string part = s.substr(pos, c == std::string::npos ? std::string::npos : c - pos);
    char* end = nullptr;
    const long v = std::strtol(part.c_str(), &end, 0);
    if (part.empty() || *end != '\0') throw CLI::ValidationError(flag, "bad number '" + part + "' in '" + s + "'");
    out.push_back(v);
    if (c == std::string::npos) break;
    pos = c + 1;
  }
  if (out.size() < min_n || out.size() > max_n) throw CLI::ValidationError(flag, "wrong field count in '" + s + "'");
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"contour-machine-sim: simulated CiA 402 machine on SocketCAN (lockstep with SYNC)"};
  std::string config_path, iface, modbus;
  std::vector<std::string> drop, drop2, fault, fault_motion, stop_hb, sdo_abort, malformed, drop_sdo;
  std::vector<std::string> missing_obj, pdos, tpdo_sampling;
  std::vector<long> expedited_only;
  std::vector<std::string> io_modules, io_inputs;
  std::vector<std::string> index_opt;
  std::vector<long> no_touch_probe;
  app.add_option("--config", config_path, "contourd YAML config (machine, bus)")->required();
  app.add_option("--can", iface, "CAN interface, e.g. vcan0")->required();
  app.add_option("--modbus", modbus, "HOST:PORT of the dynamometer Modbus TCP server");
  app.add_option("--drop-tpdo", drop, "NODE:FROM_SYNC[:COUNT] drop TPDOs (COUNT 0 = forever)");
  app.add_option("--drop-tpdo2", drop2,
                 "NODE:FROM_SYNC[:COUNT] drop the node's TPDO2..4 only: TPDO1 still comes (COUNT 0 = forever)");
  app.add_option("--fault", fault, "NODE:SYNC[:CODE] raise a drive fault (EMCY + statusword)");
  app.add_option("--fault-after-motion", fault_motion,
                 "NODE:SYNCS[:CODE] raise a drive fault SYNCS after the node starts moving");
  app.add_option("--stop-heartbeat", stop_hb, "NODE:SYNC stop the node's heartbeats");
  app.add_option("--sdo-abort", sdo_abort, "NODE:INDEX:SUB[:CODE] answer this object with an abort");
  app.add_option("--drop-sdo", drop_sdo, "NODE:COUNT ignore the node's first COUNT SDO requests");
  app.add_option("--malformed", malformed, "NODE:SYNC send malformed frames at this SYNC");
  std::vector<std::string> input_switch;
  app.add_option("--input-switch", input_switch,
                 "NODE:BIT:above|below:POS_MM a 0x60FD switch on the axis at POS_MM");
  app.add_option("--missing-object", missing_obj,
                 "NODE:INDEX[:SUB] the node's object dictionary lacks this object (every "
                 "sub-index without SUB); SDO access is aborted 0x06020000 / 0x06090011");
  app.add_option("--pdos", pdos,
                 "NODE:COUNT[:MAX_ENTRIES] the node has COUNT RPDOs and TPDOs (1..4) of at most "
                 "MAX_ENTRIES mapped objects (1..8)");
  app.add_option("--expedited-only", expedited_only,
                 "NODE the node's SDO server aborts segmented transfers (0x05040001)");
  app.add_option("--tpdo-sampling", tpdo_sampling,
                 "NODE:sync|after_step when the node samples its TPDO: at SYNC before its step, "
                 "or after it (default: tpdo_sampling of the node's drive profile)");
  app.add_option("--index", index_opt,
                 "NODE|all:PITCH_MM[:PHASE_MM] the axis encoder's index: one pulse per PITCH_MM of "
                 "true travel at PHASE_MM + k x PITCH_MM (default PHASE 0), latched by touch probe "
                 "1 (0x60B8..0x60BA); PITCH 0: no index (default: machine.axes[].sim.index_pitch_mm "
                 "and index_phase_mm)");
  app.add_option("--no-touch-probe", no_touch_probe,
                 "NODE the node's object dictionary lacks the touch probe 0x60B8, 0x60B9, 0x60BA");
  app.add_option("--io-module", io_modules,
                 "NODE[:DI:DO:AI:AO] a CiA 401 I/O module: DI/DO bytes (0x6000/0x6200), AI/AO "
                 "16-bit channels (0x6401/0x6411), 0..8 each (default 2:2:2:2); outputs looped "
                 "to inputs");
  app.add_option("--io-input", io_inputs,
                 "NODE:SUB:VALUE pin the I/O module's 0x6000:SUB to the byte VALUE (not looped)");
  std::string hb_consumer = "sync";
  app.add_option("--hb-consumer", hb_consumer,
                 "sync|wall how every node times the master's heartbeat (0x1016): in SYNCs "
                 "(lockstep, default) or on its own wall clock like a real drive")
      ->check(CLI::IsMember({"sync", "wall"}));
  std::uint64_t storm_seed = 0;
  long storm_interval = 5000;
  std::string storm_kinds;
  auto* storm_opt = app.add_option(
      "--storm", storm_seed,
      "SEED: random fault storm (std::mt19937_64), scheduled in SYNCs; same seed + same master "
      "= same events");
  app.add_option("--storm-interval", storm_interval,
                 "SYNCS mean gap between storm events, each gap uniform in [0.5, 1.5] x SYNCS "
                 "(default 5000)")
      ->check(CLI::Range(1L, 1000000000L))
      ->needs(storm_opt);
  app.add_option("--storm-kinds", storm_kinds,
                 "LIST comma list of storm kinds (default: all; modbus_* only with the "
                 "dynamometer server)")
      ->needs(storm_opt);
  app.footer(
      "Storm kinds (--storm-kinds):\n"
      "  tpdo_gap          an axis node withholds 1..(safety.missed_tpdo_streak - 1)\n"
      "                    TPDOs in a row: counted as missed, below the fault threshold\n"
      "  tpdo_burst        an axis node withholds missed_tpdo_streak + 2 TPDOs: fault\n"
      "  drive_fault       an axis node raises a drive fault (Fault + EMCY 0x2310,\n"
      "                    0x3210, 0x4310, 0x7121 or 0x8611); the master's fault reset\n"
      "                    (controlword bit 7 edge) clears it\n"
      "  heartbeat_gap     a node sends no heartbeat for 2 x its bus heartbeat_timeout_ms\n"
      "  modbus_timeout    dynamometer: no reply for 5 x the reader's response timeout\n"
      "  modbus_exception  dynamometer: exception replies (code 4) to the next 3 requests\n"
      "  modbus_disconnect dynamometer: closes the connection of the next request\n"
      "tpdo_burst, drive_fault and heartbeat_gap are fault-level: one fires only after\n"
      "every axis node has been operation enabled for 500 SYNCs in a row (postponed until\n"
      "then, same kind). Events never overlap; none comes within 50 SYNCs of a fault-level\n"
      "one. Each fired event is one JSON line on stdout, e.g.\n"
      "  {\"storm\":\"tpdo_gap\",\"node\":1,\"sync\":4711,\"count\":2}\n"
      "(sync = SYNC frames received since start). The summary gains \"storm\": {\"seed\",\n"
      "\"events\": {kind: n}, \"tpdo_dropped\": TPDOs withheld (storm and --drop-tpdo),\n"
      "\"emcy_sent\": EMCYs of drive_fault events, incl. the error-reset EMCY after the reset}.");
  contour::sim::PlantOptions plant_opt;  // --plant-io, --plant-event (soft PLC I/O, issue 20)
  contour::sim::add_plant_options(app, plant_opt);
  CLI11_PARSE(app, argc, argv);

  contour::config::Config cfg;
  std::vector<contour::config::BusNodeConfig> nodes;
  try {
    cfg = contour::config::load_config_file(config_path);
    nodes = contour::config::resolve_bus_nodes(cfg.bus, cfg.machine);
  } catch (const contour::config::ConfigError& e) {
    for (const auto& m : e.errors()) std::cerr << m << "\n";
    return 78;
  }
  if (nodes.empty()) {
    std::cerr << config_path << ": no bus nodes (machine.axes[].node_id all 0, no bus.spindle)\n";
    return 78;
  }
  // Dynamometer: served when the config enables it or --modbus names an endpoint. Its force
  // follows the same machine: feed = the axes' resultant speed, spindle speed from the spindle
  // node, path position = distance travelled.
  std::unique_ptr<contour::sim::DynamometerServer> dyno;
  if (cfg.dynamometer.enabled || !modbus.empty()) {
    std::string host = cfg.dynamometer.reader.transport.host;
    int port = cfg.dynamometer.reader.transport.port;
    if (!modbus.empty()) {
      const auto colon = modbus.rfind(':');
      char* end = nullptr;
      const long p = colon == std::string::npos ? -1 : std::strtol(modbus.c_str() + colon + 1, &end, 10);
      if (colon == std::string::npos || p < 0 || p > 65535 || *end != '\0') {
        std::cerr << "contour-machine-sim: --modbus expects HOST:PORT, got '" << modbus << "'\n";
        return 2;
      }
      host = modbus.substr(0, colon);
      port = static_cast<int>(p);
    }
    try {
      dyno = std::make_unique<contour::sim::DynamometerServer>(
          cfg.dynamometer.reader.map, contour::sim::ForceModelParams{},
          cfg.dynamometer.reader.transport.unit_id);
      dyno->start(host, port);
      std::cout << "dynamometer: modbus tcp " << host << ":" << dyno->port() << std::endl;
    } catch (const std::exception& e) {
      std::cerr << "contour-machine-sim: dynamometer: " << e.what() << "\n";
      return 69;
    }
  }

  std::unique_ptr<contour::sim::PlantRunner> plant;
  if (!plant_opt.endpoint.empty()) {
    try {
      plant = std::make_unique<contour::sim::PlantRunner>(plant_opt, cfg);
      std::cout << "plant io: modbus tcp " << plant->host() << ":" << plant->port() << std::endl;
    } catch (const std::invalid_argument& e) {
      std::cerr << "contour-machine-sim: " << e.what() << "\n";
      return 2;
    } catch (const std::exception& e) {
      std::cerr << "contour-machine-sim: plant io: " << e.what() << "\n";
      return 69;
    }
  }

  // Storm kinds, checked before the bus is opened.
  std::vector<contour::sim::StormKind> storm_kind_list;
  if (*storm_opt) {
    if (storm_kinds.empty()) {
      // Default: every kind this machine can take (modbus_* need the dynamometer server).
      for (auto k : contour::sim::all_storm_kinds())
        if (dyno || !contour::sim::storm_needs_modbus(k)) storm_kind_list.push_back(k);
    } else {
      try {
        storm_kind_list = contour::sim::parse_storm_kinds(storm_kinds);
      } catch (const std::invalid_argument& e) {
        std::cerr << "contour-machine-sim: --storm-kinds: " << e.what() << "\n";
        return 2;
      }
      for (auto k : storm_kind_list) {
        if (!dyno && contour::sim::storm_needs_modbus(k)) {
          std::cerr << "contour-machine-sim: --storm-kinds: " << contour::sim::storm_kind_name(k)
                    << " needs the dynamometer server (dynamometer: in the config, or --modbus)\n";
          return 2;
        }
      }
    }
  }

  std::vector<contour::sim::SimDriveSetup> setups;
  for (const auto& n : nodes) {
    contour::sim::SimDriveSetup s;
    s.node_id = static_cast<std::uint8_t>(n.node_id);
    s.name = n.role;
    s.spindle = n.role == "spindle";
    s.period_s = cfg.machine.period_s;
    if (n.identity.vendor_id) s.vendor_id = *n.identity.vendor_id;
    if (n.identity.product_code) s.product_code = *n.identity.product_code;
    if (n.identity.revision) s.revision = *n.identity.revision;
    s.quirks.tpdo_after_step = n.profile.tpdo_sampling == "after_step";
    s.quirks.wall_clock_consumer = hb_consumer == "wall";
    for (const auto& ax : cfg.machine.axes) {
      if (ax.node_id != n.node_id) continue;
      s.counts_per_mm = ax.counts_per_mm;
      s.plant = ax.drive;
      s.plant.period_s = cfg.machine.period_s;
      // delay_cycles is reduced below by the CAN transport's period (TPDO sampled at SYNC).
      // The same switches as the in-process sim bus (daemon/sim_bus.hpp defaults).
      s.switches.push_back({0, ax.min_mm - 2.0, false});
      s.switches.push_back({1, ax.max_mm + 2.0, true});
      s.switches.push_back({2, ax.min_mm + 0.5, false});
      s.index_pitch_mm = ax.sim_index_pitch_mm;  // the in-process SimBus' encoder index
      s.index_phase_mm = ax.sim_index_phase_mm;
    }
    if (s.spindle) {
      s.counts_per_mm = 4096.0;  // counts per revolution
      s.spindle_tau_s = cfg.spindle.sim_tau_s;  // the same lag the offline model (SimBus) uses
    }
    setups.push_back(s);
  }
  const std::size_t drive_count = setups.size();
  try {
    for (const auto& d : io_modules) {
      auto v = parse_tuple(d, 1, 5, "--io-module");
      if (v[0] < 1 || v[0] > 127)
        throw CLI::ValidationError("--io-module", "node-id 1..127 in '" + d + "'");
      for (std::size_t k = 1; k < v.size(); ++k)
        if (v[k] < 0 || v[k] > 8)
          throw CLI::ValidationError("--io-module", "counts 0..8 in '" + d + "'");
      for (const auto& s : setups)
        if (s.node_id == v[0])
          throw CLI::ValidationError("--io-module",
                                     "node-id " + std::to_string(v[0]) + " is already simulated");
      contour::sim::SimDriveSetup s;
      s.node_id = static_cast<std::uint8_t>(v[0]);
      s.name = "io" + std::to_string(v[0]);
      s.period_s = cfg.machine.period_s;
      s.quirks.wall_clock_consumer = hb_consumer == "wall";
      s.io.enabled = true;
      if (v.size() > 1) s.io.digital_inputs = static_cast<int>(v[1]);
      if (v.size() > 2) s.io.digital_outputs = static_cast<int>(v[2]);
      if (v.size() > 3) s.io.analog_inputs = static_cast<int>(v[3]);
      if (v.size() > 4) s.io.analog_outputs = static_cast<int>(v[4]);
      setups.push_back(s);
    }
  } catch (const CLI::Error& e) {
    return app.exit(e);
  }
  try {
    auto find = [&](long node) -> contour::sim::SimDriveSetup& {
      for (auto& s : setups)
        if (s.node_id == node) return s;
      throw CLI::ValidationError("node", "node-id " + std::to_string(node) + " is not simulated");
    };
    for (const auto& d : drop) {
      auto v = parse_tuple(d, 2, 3, "--drop-tpdo");
      auto& s = find(v[0]);
      s.faults.drop_tpdo_from = v[1];
      s.faults.drop_tpdo_count = v.size() > 2 ? v[2] : 0;
    }
    for (const auto& d : drop2) {
      auto v = parse_tuple(d, 2, 3, "--drop-tpdo2");
      auto& s = find(v[0]);
      s.faults.drop_tpdo2_from = v[1];
      s.faults.drop_tpdo2_count = v.size() > 2 ? v[2] : 0;
    }
    for (const auto& d : fault) {
      auto v = parse_tuple(d, 2, 3, "--fault");
      auto& s = find(v[0]);
      s.faults.fault_at = v[1];
      if (v.size() > 2) s.faults.fault_code = static_cast<std::uint16_t>(v[2]);
    }
    for (const auto& d : fault_motion) {
      auto v = parse_tuple(d, 2, 3, "--fault-after-motion");
      auto& s = find(v[0]);
      s.faults.fault_after_motion = v[1];
      if (v.size() > 2) s.faults.fault_code = static_cast<std::uint16_t>(v[2]);
    }
    for (const auto& d : stop_hb) {
      auto v = parse_tuple(d, 2, 2, "--stop-heartbeat");
      find(v[0]).faults.stop_heartbeat_at = v[1];
    }
    for (const auto& d : sdo_abort) {
      auto v = parse_tuple(d, 3, 4, "--sdo-abort");
      auto& s = find(v[0]);
      s.faults.sdo_abort_object = (static_cast<std::uint32_t>(v[1]) << 8) | static_cast<std::uint32_t>(v[2]);
      if (v.size() > 3) s.faults.sdo_abort_code = static_cast<std::uint32_t>(v[3]);
    }
    for (const auto& d : drop_sdo) {
      auto v = parse_tuple(d, 2, 2, "--drop-sdo");
      find(v[0]).faults.drop_sdo_requests = v[1];
    }
    for (const auto& d : malformed) {
      auto v = parse_tuple(d, 2, 2, "--malformed");
      find(v[0]).faults.malformed_at = v[1];
    }
    for (const auto& d : missing_obj) {
      auto v = parse_tuple(d, 2, 3, "--missing-object");
      if (v[1] <= 0 || v[1] > 0xFFFF || (v.size() > 2 && (v[2] < 0 || v[2] > 0xFF)))
        throw CLI::ValidationError("--missing-object", "bad object in '" + d + "'");
      find(v[0]).quirks.missing.push_back(
          {static_cast<std::uint16_t>(v[1]), v.size() > 2 ? static_cast<int>(v[2]) : -1});
    }
    for (const auto& d : pdos) {
      auto v = parse_tuple(d, 2, 3, "--pdos");
      if (v[1] < 1 || v[1] > 4 || (v.size() > 2 && (v[2] < 1 || v[2] > 8)))
        throw CLI::ValidationError("--pdos", "COUNT 1..4, MAX_ENTRIES 1..8 in '" + d + "'");
      auto& s = find(v[0]);
      s.quirks.pdos = static_cast<int>(v[1]);
      if (v.size() > 2) s.quirks.pdo_max_entries = static_cast<int>(v[2]);
    }
    for (long n : expedited_only) find(n).quirks.expedited_only = true;
    for (long n : no_touch_probe)
      for (int index : {0x60B8, 0x60B9, 0x60BA})
        find(n).quirks.missing.push_back({static_cast<std::uint16_t>(index), -1});
    for (const auto& d : index_opt) {
      // NODE|all:PITCH_MM[:PHASE_MM] (decimals, not parse_tuple's integers).
      const auto c1 = d.find(':');
      const auto c2 = c1 == std::string::npos ? c1 : d.find(':', c1 + 1);
      auto number = [&](const std::string& t, double& x) {
        char* end = nullptr;
        x = std::strtod(t.c_str(), &end);
        return !t.empty() && *end == '\0' && std::isfinite(x);
      };
      double pitch = 0.0, phase = 0.0;
      if (c1 == std::string::npos ||
          !number(d.substr(c1 + 1, c2 == std::string::npos ? std::string::npos : c2 - c1 - 1), pitch) ||
          pitch < 0.0 || (c2 != std::string::npos && !number(d.substr(c2 + 1), phase)))
        throw CLI::ValidationError("--index", "expected NODE|all:PITCH_MM(>= 0)[:PHASE_MM], got '" + d + "'");
      const std::string node = d.substr(0, c1);
      if (node == "all") {
        for (std::size_t k = 0; k < drive_count; ++k) {
          if (setups[k].spindle) continue;
          setups[k].index_pitch_mm = pitch;
          setups[k].index_phase_mm = phase;
        }
      } else {
        auto& s = find(parse_tuple(node, 1, 1, "--index")[0]);
        if (s.spindle || s.io.enabled)
          throw CLI::ValidationError("--index", "node " + node + " is not an axis drive: '" + d + "'");
        s.index_pitch_mm = pitch;
        s.index_phase_mm = phase;
      }
    }
    for (const auto& d : io_inputs) {
      auto v = parse_tuple(d, 3, 3, "--io-input");
      auto& s = find(v[0]);
      if (!s.io.enabled || v[1] < 1 || v[1] > s.io.digital_inputs || v[2] < 0 || v[2] > 255)
        throw CLI::ValidationError(
            "--io-input",
            "NODE must be an --io-module, SUB 1..its DI bytes, VALUE 0..255: '" + d + "'");
      s.io.fixed_inputs.emplace_back(static_cast<int>(v[1]), static_cast<int>(v[2]));
    }
    for (const auto& d : input_switch) {
      // NODE:BIT:above|below:POS_MM (the position is a decimal, not parse_tuple's integer).
      const auto c1 = d.find(':');
      const auto c2 = c1 == std::string::npos ? c1 : d.find(':', c1 + 1);
      const auto c3 = c2 == std::string::npos ? c2 : d.find(':', c2 + 1);
      if (c3 == std::string::npos)
        throw CLI::ValidationError("--input-switch", "expected NODE:BIT:above|below:POS_MM, got '" + d + "'");
      const auto v = parse_tuple(d.substr(0, c2), 2, 2, "--input-switch");
      const std::string side = d.substr(c2 + 1, c3 - c2 - 1);
      char* end = nullptr;
      const std::string pos = d.substr(c3 + 1);
      const double x = std::strtod(pos.c_str(), &end);
      if (v[1] < 0 || v[1] > 31 || (side != "above" && side != "below") || pos.empty() ||
          *end != '\0' || !std::isfinite(x))
        throw CLI::ValidationError("--input-switch", "expected NODE:BIT(0..31):above|below:POS_MM, got '" + d + "'");
      find(v[0]).switches.push_back({static_cast<int>(v[1]), x, side == "above"});
    }
    for (const auto& d : tpdo_sampling) {
      const auto colon = d.find(':');
      const std::string word = colon == std::string::npos ? "" : d.substr(colon + 1);
      if (word != "sync" && word != "after_step")
        throw CLI::ValidationError("--tpdo-sampling", "expected NODE:sync|after_step, got '" + d + "'");
      auto v = parse_tuple(d.substr(0, colon), 1, 1, "--tpdo-sampling");
      find(v[0]).quirks.tpdo_after_step = word == "after_step";
    }
  } catch (const CLI::Error& e) {
    return app.exit(e);
  }

  // The CAN transport is one period of the configured delay when the TPDO is sampled at SYNC
  // (see sim_drive.hpp); sampled after the step it adds none.
  for (auto& s : setups) {
    for (const auto& ax : cfg.machine.axes) {
      if (ax.node_id != s.node_id || s.quirks.tpdo_after_step) continue;
      s.plant.delay_cycles = ax.drive.delay_cycles > 0 ? ax.drive.delay_cycles - 1 : 0;
      if (ax.drive.delay_cycles == 0)
        std::cerr << "contour-machine-sim: axis " << ax.name
                  << ": delay_cycles 0 cannot be matched over CAN with the TPDO sampled at SYNC "
                     "(one period is the minimum)\n";
    }
  }

  std::unique_ptr<contour::drivers::SocketCan> bus;
  try {
    // Only what the drives consume: a flood of unrelated frames is dropped by the kernel and
    // cannot push a SYNC out of the socket queue (lockstep would break).
    // Heartbeats 0x701..0x77F: the master's is consumed (0x1016), the others are ignored.
    std::vector<contour::drivers::CanFilter> filters{
        {0x000, 0x7FF}, {0x080, 0x7FF}, {0x700, 0x780}};
    for (const auto& s : setups) {
      filters.push_back({0x200u + s.node_id, 0x7FF});
      filters.push_back({0x300u + s.node_id, 0x7FF});  // RPDO2: 0x60FE:01 (drive digital outputs)
      // RPDO3: a drive's 0x60B8 (touch probe) when neither RPDO1 nor RPDO2 has room; a CiA 401
      // module's outputs may take RPDO3/4.
      filters.push_back({0x400u + s.node_id, 0x7FF});
      if (s.io.enabled) filters.push_back({0x500u + s.node_id, 0x7FF});
      filters.push_back({0x600u + s.node_id, 0x7FF});
    }
    bus = std::make_unique<contour::drivers::SocketCan>(iface, filters);
  } catch (const contour::drivers::SocketCanError& e) {
    std::cerr << "contour-machine-sim: " << e.what() << "\n";
    return 69;  // EX_UNAVAILABLE
  }
  std::uint64_t tx_frames = 0, rx_frames = 0;
  auto send = [&](const contour::drivers::CanFrame& f) {
    // The simulator may block briefly rather than drop: it must not lose lockstep answers.
    for (int i = 0; i < 1000; ++i) {
      if (bus->send(f) != contour::drivers::SendResult::kDropped) break;
      bus->wait_readable(100000);
    }
    ++tx_frames;
  };
  std::vector<std::unique_ptr<contour::sim::SimDrive>> drives;
  for (const auto& s : setups) drives.push_back(std::make_unique<contour::sim::SimDrive>(s, send));

  std::unique_ptr<contour::sim::Storm> storm;
  if (*storm_opt) {
    contour::sim::StormSetup ss;
    ss.seed = storm_seed;
    ss.interval_syncs = storm_interval;
    ss.missed_tpdo_streak = cfg.safety.missed_tpdo_streak;
    ss.period_s = cfg.machine.period_s;
    const auto reader_timeout = std::chrono::duration_cast<std::chrono::milliseconds>(
        cfg.dynamometer.reader.transport.response_timeout);
    ss.modbus_no_reply = 5 * std::max(std::chrono::milliseconds(1), reader_timeout);
    std::vector<contour::sim::StormNode> sn;
    for (std::size_t i = 0; i < drive_count; ++i) {  // the drives, not the I/O modules
      contour::sim::StormNode n;
      n.drive = drives[i].get();
      n.axis = !setups[i].spindle;
      n.heartbeat_timeout_ms = nodes[i].heartbeat_ms > 0 ? nodes[i].heartbeat_timeout_ms : 0;
      n.sync_every = std::max(1, nodes[i].sync_every);
      sn.push_back(n);
    }
    ss.kinds = storm_kind_list;
    try {
      storm = std::make_unique<contour::sim::Storm>(
          ss, sn, dyno.get(), [](const std::string& line) { std::cout << line << std::endl; });
    } catch (const std::invalid_argument& e) {
      std::cerr << "contour-machine-sim: --storm: " << e.what() << "\n";
      return 2;
    }
  }

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  for (auto& d : drives) d->power_on();
  std::cout << "ready: " << iface << " nodes";
  for (const auto& s : setups) std::cout << " " << int{s.node_id} << "(" << s.name << ")";
  std::cout << std::endl;

  contour::drivers::CanFrame f;
  double path_mm = 0.0;
  long last_syncs = 0;
  // --plant-stdin: plant events typed (or piped by a test) on stdin, applied between SYNCs.
  bool stdin_open = plant != nullptr && plant_opt.from_stdin;
  std::string stdin_buf;
  while (g_stop == 0) {
    bus->wait_readable(5000000);
    const std::int64_t now = mono_ns();
    while (bus->receive(f)) {
      ++rx_frames;
      if (storm && f.id == contour::drivers::canopen::kCobSync && !f.error && !f.rtr && !f.extended)
        storm->on_sync();  // before the drives step: an event acts on this SYNC
      for (auto& d : drives) {
        d->set_wall(now);
        d->on_frame(f);
      }
    }
    for (auto& d : drives) d->tick_wall(now);
    if (plant && !drives.empty()) {
      std::array<double, 3> axis_mm{};
      std::size_t a = 0;
      for (const auto& d : drives)
        if (!d->is_spindle() && !d->is_io_module() && a < 3) axis_mm[a++] = d->position_mm();
      plant->step(drives.front()->syncs(), axis_mm);
      pollfd in{0, POLLIN, 0};
      if (stdin_open && ::poll(&in, 1, 0) == 1) {
        char buf[256];
        const ssize_t n = ::read(0, buf, sizeof buf);
        if (n <= 0) stdin_open = false;  // EOF: no more events
        if (n > 0) stdin_buf.append(buf, static_cast<std::size_t>(n));
        for (auto nl = stdin_buf.find('\n'); nl != std::string::npos; nl = stdin_buf.find('\n')) {
          const std::string kind = stdin_buf.substr(0, nl);
          stdin_buf.erase(0, nl + 1);
          if (kind.empty()) continue;
          try {
            plant->apply_now(kind, drives.front()->syncs());
          } catch (const std::invalid_argument& e) {
            std::cerr << "contour-machine-sim: stdin: " << e.what() << std::endl;
          }
        }
      }
    }
    if (dyno) {
      double v2 = 0.0, rpm = 0.0;
      for (const auto& d : drives) {
        if (d->is_io_module()) continue;
        if (d->is_spindle()) {
          rpm = d->spindle_rpm();
        } else {
          v2 += d->velocity_mm_s() * d->velocity_mm_s();
        }
      }
      const double v = std::sqrt(v2);
      const long syncs = drives.empty() ? 0 : drives.front()->syncs();
      path_mm += v * cfg.machine.period_s * static_cast<double>(syncs - last_syncs);
      last_syncs = syncs;
      dyno->set_feed(v * 60.0);
      dyno->set_spindle(rpm);
      dyno->set_path_position(path_mm);
    }
  }
  nlohmann::json j;
  j["rx_frames"] = rx_frames;
  j["tx_frames"] = tx_frames;
  j["rx_overflow"] = bus->stats().rx_overflow;
  for (const auto& d : drives) {
    nlohmann::json n;
    n["node_id"] = d->node_id();
    n["syncs"] = d->syncs();
    n["position_mm"] = d->position_mm();
    if (d->is_io_module()) {
      nlohmann::json io;
      io["0x6000"] = d->io_values(0x6000);
      io["0x6200"] = d->io_values(0x6200);
      io["0x6401"] = d->io_values(0x6401);
      io["0x6411"] = d->io_values(0x6411);
      n["io"] = io;
      n["nmt"] = contour::drivers::canopen::nmt_state_name(d->nmt());
    } else {
      n["state"] = contour::drivers::canopen::cia402_state_name(d->state());
      if (!d->is_spindle()) {
        n["index_latches"] = d->index_latches();
        if (d->index_latches() > 0) n["last_index_mm"] = d->last_index_mm();
      }
    }
    j["nodes"].push_back(n);
  }
  if (storm) j["storm"] = storm->summary();
  if (plant) j["plant"] = plant->summary();
  std::cout << j.dump() << std::endl;
  return 0;
}
