#pragma once
// The whole contourd configuration: one YAML file, validated on load (unknown keys, wrong types
// and out-of-range values are errors naming file:line:column and the key path).
#include <string>

#include "config/bus_config.hpp"
#include "config/control_config.hpp"
#include "config/daemon_config.hpp"
#include "config/dynamometer_config.hpp"
#include "config/force_config.hpp"
#include "config/gpio_config.hpp"
#include "config/interpolator_config.hpp"
#include "config/machine_config.hpp"
#include "config/plc_config.hpp"
#include "config/program_config.hpp"
#include "config/shopnet_config.hpp"
#include "config/spindle_config.hpp"
#include "config/web_config.hpp"
#include "config/yaml_reader.hpp"

namespace contour::config {

struct Config {
  std::string source;  // file name (or "<string>")
  MachineConfig machine;
  LoopConfig loop;
  SafetyConfig safety;
  TelemetryConfig telemetry;
  SocketConfig socket;
  LogConfig log;
  InterpolatorConfig interpolator;
  ProgramConfig program;
  ControlConfig control;
  ForceConfig force;
  BusConfig bus;
  // `bus.lockstep: true` (socketcan only): the drives are simulated in lockstep with SYNC
  // (contour-machine-sim). The master then waits for every TPDO (up to kLockstepTpdoWaitMs)
  // instead of loop.tpdo_deadline_us, and counts heartbeat time in cycles, so that a cycle that
  // wakes late (VM steal time) cannot change the results. Never set it for real drives.
  // Parsed in config.cpp beside parse_bus() (bus_config.* has another owner; it belongs in
  // BusConfig).
  bool bus_lockstep = false;
  static constexpr int kLockstepTpdoWaitMs = 200;
  DynamometerConfig dynamometer;
  SpindleConfig spindle;
  GpioConfig gpio;
  PlcConfig plc;              // soft PLC (issue 20)
  MqttConfig mqtt;            // contour-bridge (issue 22); validated, not used by contourd
  MtconnectConfig mtconnect;  // contour-bridge (issue 22); validated, not used by contourd
  WebConfig web;              // contour-web (issue 21); validated, not used by contourd
};

// Throws ConfigError with every problem found.
Config load_config_file(const std::string& path);
Config load_config_string(const std::string& text, const std::string& name = "<string>");

}  // namespace contour::config
