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
    Section machine = top.child("machine");
    cfg.machine = parse_machine(machine);
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
