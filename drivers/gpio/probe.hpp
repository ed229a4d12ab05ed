#pragma once
// Commissioning probe for the GPIO lines (used by `contourd --probe gpio`): requests each
// configured line once and reports its state. The E-stop input is read (logical level); outputs
// are requested *inactive* (safe state) and reported as available or with the error. Non-RT.
#include <string>
#include <vector>

#include "drivers/gpio/machine_io.hpp"

namespace contour::drivers::gpio {

struct GpioProbeRecord {
  std::string role;  // "estop", "drive_enable", ...
  std::string line;  // LineSpec::describe()
  bool ok = false;
  bool is_input = false;
  bool active = false;  // input: logical level now; output: false (held inactive)
  std::string error;
};

std::vector<GpioProbeRecord> probe_gpio(GpioBackend& backend, const MachineIoSettings& s);

}  // namespace contour::drivers::gpio
