#pragma once
// The machine's discrete I/O on one GPIO backend: E-stop input (EstopMonitor), drive-enable,
// spindle-enable, coolant mist (M7) / flood (M8, M9 = both off) outputs, optional daemon-alive
// output toggled by the supervisor. Construction requests every configured line (throws GpioError
// naming the line); outputs start inactive. Output setters are non-RT (ioctl with libgpiod): the
// supervisor applies them; the RT loop only reads estop().tripped().
#include <memory>
#include <optional>
#include <string>

#include "drivers/gpio/estop_monitor.hpp"
#include "drivers/gpio/gpio.hpp"

namespace contour::drivers::gpio {

struct MachineIoSettings {
  LineSpec estop;         // required; active_low true by default (normally closed chain)
  LineSpec drive_enable;  // optional (configured() false -> absent)
  LineSpec spindle_enable;
  LineSpec coolant_mist;
  LineSpec coolant_flood;
  LineSpec alive;
  std::chrono::microseconds estop_debounce{5000};
};

struct MachineIoState {
  bool estop_asserted = false;
  bool estop_tripped = false;
  bool drive_enable = false, spindle_enable = false, coolant_mist = false, coolant_flood = false,
       alive = false;
};

class MachineIo {
 public:
  MachineIo(GpioBackend& backend, const MachineIoSettings& s);
  ~MachineIo();
  void start() { estop_->start(); }
  void stop() { estop_->stop(); }

  [[nodiscard]] EstopMonitor& estop() noexcept { return *estop_; }
  // Each returns false if the line is not configured.
  bool set_drive_enable(bool on);
  bool set_spindle_enable(bool on);
  bool set_coolant(bool mist, bool flood);  // M7: (true, x), M8: (x, true), M9: (false, false)
  bool toggle_alive();
  [[nodiscard]] MachineIoState state() const;

 private:
  static bool set(const std::unique_ptr<GpioOutputLine>& l, bool on);
  std::unique_ptr<EstopMonitor> estop_;
  std::unique_ptr<GpioOutputLine> drive_, spindle_, mist_, flood_, alive_;
};

}  // namespace contour::drivers::gpio
