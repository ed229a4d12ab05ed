#include "config/gpio_config.hpp"

#include <chrono>

namespace contour::config {

namespace dg = drivers::gpio;

namespace {
dg::LineSpec parse_line(Section& parent, const std::string& role, const std::string& chip,
                        bool default_active_low, double* debounce_ms) {
  dg::LineSpec spec;
  spec.role = role;
  if (!parent.has(role)) {
    parent.accept(role);
    return spec;
  }
  Section l = parent.child(role);
  spec.chip = l.string("chip", chip);
  spec.offset = l.has("offset") ? static_cast<int>(l.integer("offset", -1, 0, 4095)) : -1;
  if (!l.has("offset")) l.accept("offset");
  spec.name = l.string("name", "");
  if (spec.offset < 0 && spec.name.empty()) l.error("offset", "give either offset or name");
  if (spec.offset >= 0 && !spec.name.empty())
    l.error("name", "give either offset or name, not both");
  if (spec.offset >= 0 && spec.chip.empty()) l.error("chip", "a line by offset needs a chip");
  spec.active_low = l.boolean("active_low", default_active_low);
  if (debounce_ms != nullptr) *debounce_ms = l.number("debounce_ms", 5.0, 0.0, 1000.0);
  return spec;
}
}  // namespace

GpioConfig parse_gpio(Section& s) {
  GpioConfig cfg;
  if (!s.present()) return cfg;
  cfg.enabled = true;
  cfg.backend = s.choice("backend", "libgpiod", {"libgpiod", "sim"});
  cfg.consumer = s.string("consumer", "contourd");
  const std::string chip = s.string("chip", "");
  double debounce_ms = 5.0;
  dg::MachineIoSettings& m = cfg.lines;
  if (!s.has("estop")) s.error("estop", "the E-stop input line is required");
  m.estop = parse_line(s, "estop", chip, true, &debounce_ms);
  m.estop_debounce = std::chrono::microseconds(static_cast<long>(debounce_ms * 1000.0));
  m.drive_enable = parse_line(s, "drive_enable", chip, false, nullptr);
  m.spindle_enable = parse_line(s, "spindle_enable", chip, false, nullptr);
  m.coolant_mist = parse_line(s, "coolant_mist", chip, false, nullptr);
  m.coolant_flood = parse_line(s, "coolant_flood", chip, false, nullptr);
  m.alive = parse_line(s, "alive", chip, false, nullptr);
  return cfg;
}

}  // namespace contour::config
