#include "daemon/probe.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <exception>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "drivers/can/socket_can.hpp"
#include "drivers/canopen/probe.hpp"
#include "drivers/gpio/gpiod_backend.hpp"
#include "drivers/gpio/probe.hpp"
#include "drivers/gpio/sim_gpio.hpp"
#include "drivers/modbus/probe.hpp"

namespace contour::daemon {

namespace {

using json = nlohmann::ordered_json;  // keys in the order written: "probe" first
namespace dm = drivers::modbus;
namespace dg = drivers::gpio;
namespace dc = drivers::canopen;

constexpr int kExitOk = 0;
constexpr int kExitPartial = 1;
constexpr int kExitUnavailable = 69;  // EX_UNAVAILABLE
constexpr int kExitConfig = 78;       // EX_CONFIG

void emit(std::FILE* out, const json& j) {
  const std::string s = j.dump(-1, ' ', false, json::error_handler_t::replace);
  std::fprintf(out, "%s\n", s.c_str());
  std::fflush(out);  // an integrator watches the samples arrive
}

std::string hex(std::uint32_t v, int digits) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%0*X", digits, v);
  return b;
}

int config_error(std::FILE* out, ProbeKind k, const std::string& msg) {
  emit(out, {{"probe", to_string(k)}, {"error", msg}, {"exit", kExitConfig}});
  return kExitConfig;
}

// total: records; answered: the device replied; ok: replied and everything in the record is good.
int summary(std::FILE* out, ProbeKind k, int total, int answered, int ok,
            json extra = json::object()) {
  const int code = total > 0 && ok == total ? kExitOk
                   : answered == 0          ? kExitUnavailable
                                            : kExitPartial;
  json j{{"probe", to_string(k)},
         {"summary", true},
         {"total", total},
         {"answered", answered},
         {"ok", ok}};
  j.update(extra);
  j["exit"] = code;
  emit(out, j);
  return code;
}

// ---------------------------------------------------------------- modbus
int probe_modbus(const config::Config& cfg, const ProbeOptions& opt, std::FILE* out) {
  if (!cfg.dynamometer.enabled)
    return config_error(out, ProbeKind::kModbus,
                        cfg.source + ": no 'dynamometer' section: nothing to probe over Modbus");
  const dm::DynamometerSettings& s = cfg.dynamometer.reader;
  const int count = opt.count > 0 ? opt.count : kProbeDefaultModbusCount;
  static constexpr std::array<const char*, dm::kForceChannels> kKeys = {"fx_n", "fy_n", "fz_n"};
  int total = 0;
  int answered = 0;
  int good = 0;
  std::int64_t prev_t_ns = 0;
  try {
    dm::probe_dynamometer(s, count, [&](const dm::ProbeRecord& r) {
      ++total;
      json j{{"probe", "modbus"}, {"index", r.index}, {"ok", r.ok}};
      if (r.ok) {
        const dm::ForceSample& x = r.sample;
        const std::int64_t now = dm::steady_now_ns();
        j["valid"] = x.valid;
        j["seq"] = x.seq;
        j["t_ns"] = x.t_ns;
        j["age_ms"] = static_cast<double>(now - x.t_ns) * 1e-6;
        if (prev_t_ns != 0) j["dt_ms"] = static_cast<double>(x.t_ns - prev_t_ns) * 1e-6;
        prev_t_ns = x.t_ns;
        for (std::size_t c = 0; c < dm::kForceChannels; ++c)
          if (s.map.channels[c].enabled) j[kKeys[c]] = x.force_N[c];
        j["raw_start"] = x.raw_start;
        j["raw"] = std::vector<std::uint16_t>(x.raw.begin(), x.raw.begin() + x.raw_count);
        if (s.map.status.enabled) {
          const std::size_t k = static_cast<std::size_t>(s.map.status.address - x.raw_start);
          const std::uint16_t v = k < x.raw_count ? x.raw[k] : 0;
          const bool bit = ((v >> s.map.status.valid_bit) & 1u) != 0;
          j["status"] = {{"address", s.map.status.address},
                         {"value", v},
                         {"valid", bit == s.map.status.valid_when_set}};
        }
        ++answered;
        if (x.valid) ++good;
      } else {
        j["error"] = dm::error_kind_name(r.error);
        j["error_text"] = r.error_text;
      }
      j["latency_ms"] = r.latency_ms;
      emit(out, j);
    });
  } catch (const std::exception& e) {  // settings the probe cannot use (register block)
    return config_error(out, ProbeKind::kModbus, cfg.source + ": dynamometer: " + e.what());
  }
  const auto& t = s.transport;
  const std::string endpoint =
      t.transport == dm::Transport::kTcp ? t.host + ":" + std::to_string(t.port) : t.device;
  return summary(out, ProbeKind::kModbus, total, answered, good, {{"endpoint", endpoint}});
}

// ---------------------------------------------------------------- can
int probe_can(const config::Config& cfg, const ProbeOptions& opt, std::FILE* out) {
  if (cfg.bus.type != "socketcan")
    return config_error(out, ProbeKind::kCan,
                        cfg.source + ": bus.type is '" + cfg.bus.type +
                            "': --probe can needs bus.type socketcan and bus.interface");
  dc::CanProbeSettings s;
  try {
    for (const auto& n : config::resolve_bus_nodes(cfg.bus, cfg.machine))
      s.nodes.push_back({static_cast<std::uint8_t>(n.node_id), n.role});
  } catch (const std::exception& e) {
    return config_error(out, ProbeKind::kCan, e.what());
  }
  s.scan = opt.scan || s.nodes.empty();
  s.sdo_timeout = std::chrono::milliseconds(cfg.bus.sdo_timeout_ms);
  // Listen one heartbeat period of the slowest configured producer (plus margin) before asking.
  s.listen = std::chrono::milliseconds(std::max(250, 2 * cfg.bus.drive_defaults.heartbeat_ms + 50));
  std::unique_ptr<drivers::SocketCan> bus;
  try {
    bus = std::make_unique<drivers::SocketCan>(cfg.bus.interface);  // no filter: hear everyone
  } catch (const std::exception& e) {
    emit(out, {{"probe", "can"},
               {"interface", cfg.bus.interface},
               {"error", e.what()},
               {"exit", kExitUnavailable}});
    return kExitUnavailable;
  }
  const int rounds = opt.count > 0 ? opt.count : 1;
  int total = 0;
  int good = 0;
  int found = 0;
  for (int round = 0; round < rounds; ++round) {
    for (const auto& r : dc::probe_canopen(*bus, s)) {
      ++total;
      json j{{"probe", "can"},
             {"round", round},
             {"node_id", r.node_id},
             {"name", r.name},
             {"configured", r.configured},
             {"found", r.found}};
      if (r.nmt) {
        j["nmt"] = dc::nmt_state_name(*r.nmt);
        j["nmt_source"] = r.nmt_source;
      }
      if (r.device_type) j["device_type"] = hex(*r.device_type, 8);
      if (r.vendor_id) j["vendor_id"] = hex(*r.vendor_id, 8);
      if (r.product_code) j["product_code"] = hex(*r.product_code, 8);
      if (r.revision) j["revision"] = hex(*r.revision, 8);
      if (r.serial) j["serial"] = hex(*r.serial, 8);
      if (r.statusword) {
        j["statusword"] = hex(*r.statusword, 4);
        j["cia402_state"] = dc::cia402_state_name(dc::decode_statusword(*r.statusword));
      }
      if (r.mode_display) j["mode_display"] = *r.mode_display;
      j["errors"] = r.errors;
      emit(out, j);
      if (r.found) ++found;
      // A configured node counts as good when it answered with its identity and no object failed.
      if (r.found && r.vendor_id && r.errors.empty()) ++good;
    }
  }
  return summary(out, ProbeKind::kCan, total, found, good, {{"interface", cfg.bus.interface}});
}

// ---------------------------------------------------------------- gpio
int probe_gpio_lines(const config::Config& cfg, const ProbeOptions& opt, std::FILE* out) {
  if (!cfg.gpio.enabled && !opt.gpio_backend)
    return config_error(out, ProbeKind::kGpio,
                        cfg.source + ": no 'gpio' section: nothing to probe");
  std::shared_ptr<dg::GpioBackend> backend = opt.gpio_backend;
  if (!backend) {
    if (cfg.gpio.backend == "sim") {
      // As the daemon does (io_channels.cpp): a fresh simulated input reads physical low, which
      // an active-low E-stop takes as pressed; the simulated chain starts closed (released).
      auto sim = dg::SimGpio::create();
      const auto& e = cfg.gpio.lines.estop;
      if (e.configured()) sim->set_input_level(dg::SimGpio::key_of(e), e.active_low);
      backend = sim;
    } else {
      backend = std::make_shared<dg::GpiodBackend>(cfg.gpio.consumer);
    }
  }
  const int rounds = opt.count > 0 ? opt.count : 1;
  int total = 0;
  int good = 0;
  for (int round = 0; round < rounds; ++round) {
    if (round > 0) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    for (const auto& r : dg::probe_gpio(*backend, cfg.gpio.lines)) {
      ++total;
      json j{{"probe", "gpio"}, {"round", round}, {"role", r.role},
             {"line", r.line},  {"ok", r.ok},     {"direction", r.is_input ? "input" : "output"}};
      if (r.ok) {
        j["active"] = r.active;
        if (r.role == "estop") j["estop"] = r.active ? "asserted" : "released";
        ++good;
      } else {
        j["error"] = r.error;
      }
      emit(out, j);
    }
  }
  return summary(out, ProbeKind::kGpio, total, good, good, {{"backend", cfg.gpio.backend}});
}

}  // namespace

std::optional<ProbeKind> parse_probe_kind(std::string_view s) noexcept {
  if (s == "modbus") return ProbeKind::kModbus;
  if (s == "can") return ProbeKind::kCan;
  if (s == "gpio") return ProbeKind::kGpio;
  return std::nullopt;
}

const char* to_string(ProbeKind k) noexcept {
  switch (k) {
    case ProbeKind::kModbus:
      return "modbus";
    case ProbeKind::kCan:
      return "can";
    case ProbeKind::kGpio:
      return "gpio";
  }
  return "?";
}

int run_probe(const config::Config& cfg, const ProbeOptions& opt, std::FILE* out) {
  switch (opt.kind) {
    case ProbeKind::kModbus:
      return probe_modbus(cfg, opt, out);
    case ProbeKind::kCan:
      return probe_can(cfg, opt, out);
    case ProbeKind::kGpio:
      return probe_gpio_lines(cfg, opt, out);
  }
  return 2;
}

}  // namespace contour::daemon
