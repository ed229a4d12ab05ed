#include "config/config.hpp"

namespace contour::config {

namespace {
Config parse_root(const YAML::Node& root, const std::string& name) {
  Diagnostics diag(name);
  Config cfg;
  cfg.source = name;
  {
    Section top(root, "", diag);
    if (!top.present()) diag.error(root, "", "empty configuration");
    {
      Section sec = top.child("loop");
      cfg.loop = parse_loop(sec);
    }
    Section machine = top.child("machine");
    // No silent default machine (issue 16: a file without it used to run the paper's Table 1
    // machine). config/table1.yaml has that machine written out.
    if (top.present() && !machine.present()) {
      diag.error(root, "machine", "missing section: every configuration names its machine (axes, "
                                  "drives, limits); see config/sim.yaml or config/table1.yaml");
    }
    cfg.machine = parse_machine(machine, cfg.loop.period_us * 1e-6);
    {
      Section sec = top.child("safety");
      cfg.safety = parse_safety(sec);
    }
    {
      Section sec = top.child("telemetry");
      cfg.telemetry = parse_telemetry(sec);
    }
    {
      Section sec = top.child("socket");
      cfg.socket = parse_socket(sec);
    }
    {
      Section sec = top.child("log");
      cfg.log = parse_log(sec);
    }
    {
      Section sec = top.child("interpolator");
      cfg.interpolator = parse_interpolator(sec);
    }
    {
      Section sec = top.child("program");
      cfg.program = parse_program(sec);
    }
    {
      Section sec = top.child("control");
      cfg.control = parse_control(sec);
    }
    {
      Section sec = top.child("force");
      cfg.force = parse_force(sec);
    }
    {
      Section sec = top.child("bus");
      cfg.bus = parse_bus(sec);
      cfg.bus_lockstep = sec.boolean("lockstep", false);
      if (cfg.bus_lockstep && cfg.bus.type != "socketcan")
        sec.error("lockstep", "only meaningful with type: socketcan (simulated CANopen drives)");
    }
    {
      Section sec = top.child("dynamometer");
      cfg.dynamometer = parse_dynamometer(sec);
    }
    {
      Section sec = top.child("spindle");
      cfg.spindle = parse_spindle(sec);
      if (cfg.spindle.type == "canopen") {
        if (!cfg.bus.spindle)
          sec.error("type", "canopen needs the spindle node on the bus (bus.spindle)");
        else if (cfg.bus.spindle->node_id != cfg.spindle.node_id)
          sec.error("node_id", "must be bus.spindle.node_id (" +
                                   std::to_string(cfg.bus.spindle->node_id) + ")");
      } else if (cfg.spindle.type == "sim" && cfg.bus.type != "sim") {
        sec.error("type", "sim is the built-in simulated machine's spindle (bus.type: sim)");
      } else if (cfg.bus.spindle && cfg.spindle.type != "none") {
        sec.error("type", "bus.spindle is a CANopen spindle: type must be canopen");
      }
    }
    {
      Section sec = top.child("gpio");
      cfg.gpio = parse_gpio(sec);
    }
    {
      Section sec = top.child("plc");
      cfg.plc = parse_plc(sec);
    }
    {
      Section sec = top.child("mqtt");
      cfg.mqtt = parse_mqtt(sec);
    }
    {
      Section sec = top.child("mtconnect");
      cfg.mtconnect = parse_mtconnect(sec);
    }
    {
      Section sec = top.child("web");
      cfg.web = parse_web(sec);
    }
  }
  diag.throw_if_any();
  return cfg;
}
}  // namespace

Config load_config_file(const std::string& path) { return parse_root(load_yaml_file(path), path); }

Config load_config_string(const std::string& text, const std::string& name) {
  return parse_root(load_yaml_string(text, name), name);
}

}  // namespace contour::config
