#include "config/spindle_config.hpp"

#include <chrono>

namespace contour::config {

namespace dm = drivers::modbus;

SpindleConfig parse_spindle(Section& s) {
  SpindleConfig cfg;
  if (!s.present()) return cfg;
  cfg.type = s.choice("type", "none", {"none", "canopen", "modbus_vfd", "sim"});
  if (cfg.type == "canopen")
    cfg.node_id = static_cast<int>(s.required_integer("node_id", 1, 127));
  else if (s.has("node_id"))
    s.error("node_id", "only for type: canopen");
  drivers::SpindleLimits& l = cfg.limits;
  l.min_rpm = s.number("min_rpm", 0.0, 0.0, 200000.0);
  l.max_rpm = s.number("max_rpm", 24000.0, 1.0, 200000.0);
  if (l.min_rpm > l.max_rpm) s.error("min_rpm", "must be <= max_rpm");
  l.rate_rpm_s = s.number("rate_rpm_s", 2000.0, 1.0, 1e6);
  l.at_speed_tolerance_rpm = s.number("at_speed_tolerance_rpm", 50.0, 0.0, 1e5);
  l.at_speed_tolerance_fraction = s.number("at_speed_tolerance_pct", 2.0, 0.0, 100.0) / 100.0;
  cfg.at_speed_timeout_s = s.number("at_speed_timeout_s", 10.0, 0.1, 600.0);
  const std::string wait = s.choice("at_speed_wait", "always", {"always", "force", "never"});
  cfg.at_speed_wait = wait == "always"  ? SpindleConfig::Wait::kAlways
                      : wait == "force" ? SpindleConfig::Wait::kForce
                                        : SpindleConfig::Wait::kNever;
  cfg.sim_tau_s = s.number("sim_tau_s", 0.2, 0.001, 60.0);
  cfg.override_min_percent = s.number("override_min_percent", 50.0, 0.0, 100.0);
  cfg.override_max_percent = s.number("override_max_percent", 100.0, 100.0, 1000.0);

  if (cfg.type != "modbus_vfd") {
    if (s.has("vfd")) s.error("vfd", "only for type: modbus_vfd");
    return cfg;
  }
  Section v = s.child("vfd");
  if (!v.present()) s.error("vfd", "required for type: modbus_vfd");
  dm::VfdSettings& f = cfg.vfd;
  f.limits = l;
  dm::TransportSettings& t = f.transport;
  const std::string transport = v.choice("transport", "rtu", {"tcp", "rtu"});
  t.transport = transport == "tcp" ? dm::Transport::kTcp : dm::Transport::kRtu;
  t.host = v.string("host", "127.0.0.1");
  t.port = static_cast<int>(v.integer("port", 502, 1, 65535));
  t.device = v.string("device", "/dev/ttyUSB0");
  t.baud = static_cast<int>(v.integer("baud", 19200, 1200, 4000000));
  const std::string parity = v.choice("parity", "even", {"none", "even", "odd"});
  t.parity = parity == "none" ? 'N' : parity == "even" ? 'E' : 'O';
  t.unit_id = static_cast<int>(v.integer("unit_id", 1, 1, 247));
  t.response_timeout = std::chrono::microseconds(
      static_cast<long>(1000.0 * v.number("timeout_ms", 50.0, 1.0, 5000.0)));
  f.update_rate_hz = v.number("update_rate_hz", 20.0, 0.1, 200.0);
  f.setpoint_register =
      static_cast<std::uint16_t>(v.required_integer("setpoint_register", 0, 65535));
  f.setpoint_counts_per_rpm = v.number("setpoint_counts_per_rpm", 1.0, 1e-6, 1e6);
  if (f.limits.max_rpm * f.setpoint_counts_per_rpm > 65535.0)
    v.error("setpoint_counts_per_rpm", "max_rpm does not fit a 16-bit setpoint register");
  {
    Section run = v.child("run");
    if (!run.present()) v.error("run", "required: {kind, address, ...}");
    f.run_is_coil = run.choice("kind", "register", {"register", "coil"}) == "coil";
    f.run_address = static_cast<std::uint16_t>(run.required_integer("address", 0, 65535));
    f.run_forward_value = static_cast<std::uint16_t>(run.integer("forward", 1, 0, 65535));
    f.run_reverse_value = static_cast<std::uint16_t>(run.integer("reverse", 2, 0, 65535));
    f.stop_value = static_cast<std::uint16_t>(run.integer("stop", 0, 0, 65535));
  }
  f.actual_register = static_cast<std::uint16_t>(v.required_integer("actual_register", 0, 65535));
  f.actual_function = v.choice("actual_function", "holding", {"holding", "input"}) == "holding"
                          ? dm::RegisterFunction::kHolding
                          : dm::RegisterFunction::kInput;
  f.actual_counts_per_rpm = v.number("actual_counts_per_rpm", 1.0, 1e-6, 1e6);
  return cfg;
}

}  // namespace contour::config
