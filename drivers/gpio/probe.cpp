#include "drivers/gpio/probe.hpp"

namespace contour::drivers::gpio {

std::vector<GpioProbeRecord> probe_gpio(GpioBackend& backend, const MachineIoSettings& s) {
  std::vector<GpioProbeRecord> out;
  auto one = [&](const char* role, LineSpec spec, bool input) {
    if (!spec.configured() && !input) return;
    if (spec.role.empty()) spec.role = role;
    GpioProbeRecord r;
    r.role = role;
    r.line = spec.describe();
    r.is_input = input;
    try {
      if (input) {
        auto l = backend.request_input(spec, false);
        r.active = l->active();
      } else {
        auto l = backend.request_output(spec, false);
      }
      r.ok = true;
    } catch (const std::exception& e) {
      r.error = e.what();
    }
    out.push_back(std::move(r));
  };
  one("estop", s.estop, true);
  one("drive_enable", s.drive_enable, false);
  one("spindle_enable", s.spindle_enable, false);
  one("coolant_mist", s.coolant_mist, false);
  one("coolant_flood", s.coolant_flood, false);
  one("alive", s.alive, false);
  return out;
}

}  // namespace contour::drivers::gpio
