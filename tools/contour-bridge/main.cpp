// contour-bridge — contourd's companion on the shop network (issue 22): MQTT publisher (to a
// mosquitto or any MQTT 3.1.1 broker) and MTConnect SHDR adapter. A separate, non-real-time
// process that talks to contourd only through its command socket, exactly like contourctl.
//   contour-bridge --config FILE [--socket PATH]      run (systemd: contour-bridge.service)
//   contour-bridge --config FILE --devices-xml OUT    write the agent's Devices.xml and exit
//   contour-bridge --config FILE --check              validate config, credentials, TLS files
// Exit codes: 0 stopped by SIGTERM/SIGINT; 78 (EX_CONFIG) configuration, credentials or a port
// that cannot be used (restarting cannot fix those); 1 anything else.
#include <signal.h>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>

#include "config/config.hpp"
#include "tools/contour-bridge/bridge.hpp"
#include "tools/contour-bridge/credentials.hpp"
#include "tools/contour-bridge/devices_xml.hpp"

namespace {

constexpr int kExitConfig = 78;
std::atomic<bool> g_stop{false};

extern "C" void on_signal(int) { g_stop.store(true); }

void install_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;  // no SA_RESTART: poll() returns at once
  ::sigaction(SIGTERM, &sa, nullptr);
  ::sigaction(SIGINT, &sa, nullptr);
  struct sigaction ign {};
  ign.sa_handler = SIG_IGN;
  sigemptyset(&ign.sa_mask);
  ::sigaction(SIGPIPE, &ign, nullptr);  // a broker or agent that vanished: an error, not a signal
  ::sigaction(SIGHUP, &ign, nullptr);
}

void setup_logging() {
  auto logger = spdlog::stderr_logger_mt("contour-bridge");
  // Under systemd (journald adds its own time stamps) the level is enough.
  if (std::getenv("JOURNAL_STREAM") != nullptr) {
    logger->set_pattern("%l: %v");
  } else {
    logger->set_pattern("%Y-%m-%d %H:%M:%S.%e %l %v");
  }
  spdlog::set_default_logger(logger);
}

contour::bridge::DeviceInfo device_info(const contour::config::Config& cfg) {
  contour::bridge::DeviceInfo d;
  const auto& m = cfg.mtconnect;
  d.name = !m.device_name.empty() ? m.device_name
           : cfg.mqtt.present     ? cfg.mqtt.machine_id
                                  : std::string("contourd");
  d.uuid = m.device_uuid.empty() ? "contourd-" + d.name : m.device_uuid;
  d.manufacturer = m.manufacturer;
  d.model = m.model;
  d.serial_number = m.serial_number;
  for (const auto& a : cfg.machine.axes) d.axes.push_back(a.name);
  d.has_spindle = cfg.spindle.type != "none";
  return d;
}

// Atomic: a reader sees the old or the new file, never half of one.
void write_file(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    if (!out) throw std::runtime_error(path + ": cannot write");
    out << text;
    if (!out.flush()) throw std::runtime_error(path + ": write failed");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw std::runtime_error(path + ": " + ec.message());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "contour-bridge: contourd on the shop network — MQTT publisher and MTConnect SHDR adapter "
      "(tools/contour-bridge/README.md)"};
  std::string config_path, socket_path, devices_out;
  bool check = false;
  app.add_option("--config", config_path, "contourd's YAML config (its mqtt: and mtconnect: sections)")
      ->required();
  app.add_option("--socket", socket_path, "contourd's command socket (default: socket.path)");
  app.add_option("--devices-xml", devices_out, "write the MTConnect Devices.xml here and exit");
  app.add_flag("--check", check, "validate the config, credentials file and TLS files, then exit");
  CLI11_PARSE(app, argc, argv);

  setup_logging();
  contour::config::Config cfg;
  try {
    cfg = contour::config::load_config_file(config_path);
  } catch (const contour::config::ConfigError& e) {
    for (const auto& m : e.errors()) std::cerr << m << '\n';
    return kExitConfig;
  } catch (const std::exception& e) {
    std::cerr << config_path << ": " << e.what() << '\n';
    return kExitConfig;
  }
  try {
    if (!devices_out.empty()) {
      write_file(devices_out, contour::bridge::devices_xml(device_info(cfg)));
      std::cout << "contour-bridge: wrote " << devices_out << '\n';
      return 0;
    }
    if (!cfg.mtconnect.devices_xml.empty()) {
      write_file(cfg.mtconnect.devices_xml, contour::bridge::devices_xml(device_info(cfg)));
      spdlog::info("mtconnect: wrote {}", cfg.mtconnect.devices_xml);
    }
    contour::bridge::BridgeOptions opt;
    opt.socket_path = socket_path;
    if (check) {
      if (cfg.mqtt.present && !cfg.mqtt.credentials_file.empty()) {
        (void)contour::bridge::load_credentials(cfg.mqtt.credentials_file);
      }
      if (cfg.mqtt.present && cfg.mqtt.tls.enabled) {
        for (auto [key, path] : {std::pair{"ca_file", cfg.mqtt.tls.ca_file},
                                 std::pair{"cert_file", cfg.mqtt.tls.cert_file},
                                 std::pair{"key_file", cfg.mqtt.tls.key_file}}) {
          if (!path.empty() && ::access(path.c_str(), R_OK) != 0) {
            std::cerr << "mqtt.tls." << key << ": " << path << ": cannot read\n";
            return kExitConfig;
          }
        }
      }
      std::cout << "contour-bridge: " << config_path << ": OK\n";
      return 0;
    }
    install_signals();
    contour::bridge::Bridge bridge(cfg, opt);
    return bridge.run(g_stop);
  } catch (const contour::bridge::CredentialsError& e) {
    spdlog::critical("{}", e.what());
    return kExitConfig;
  } catch (const std::exception& e) {
    spdlog::critical("{}", e.what());
    return kExitConfig;
  }
}
