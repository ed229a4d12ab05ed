#pragma once
// `gpio:` section (issue 8). Absent -> enabled = false (no E-stop input: the daemon must refuse
// to enable drives on a real machine without one; that policy is the daemon's).
//
// gpio:
//   backend: libgpiod         # libgpiod | sim
//   chip: gpiochip0           # default chip for lines given by offset
//   consumer: contourd
//   estop: {offset: 17, active_low: true, debounce_ms: 5}     # or {name: "ESTOP"}; chip: override
//   drive_enable: {offset: 18}
//   spindle_enable: {name: "SPINDLE_EN"}
//   coolant_mist: {offset: 20}
//   coolant_flood: {offset: 21}
//   alive: {offset: 22}       # optional daemon-alive output toggled by the supervisor
#include <string>

#include "config/yaml_reader.hpp"
#include "drivers/gpio/machine_io.hpp"

namespace contour::config {

struct GpioConfig {
  bool enabled = false;
  std::string backend = "sim";
  std::string consumer = "contourd";
  drivers::gpio::MachineIoSettings lines{};
};

GpioConfig parse_gpio(Section& s);

}  // namespace contour::config
