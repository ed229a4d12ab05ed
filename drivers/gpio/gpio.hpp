#pragma once
// GPIO lines behind a small interface with two backends: libgpiod v1.6 (Debian 12's libgpiod2,
// C++ bindings gpiod.hpp) and a simulated one controllable from tests and contour-machine-sim.
// Values at this interface are *logical* (active = true); polarity is applied by the backend from
// LineSpec::active_low. Requests happen at start-up and throw GpioError with a message naming the
// chip/line and the cause; per-line calls are non-RT (a libgpiod call is an ioctl) and are made by
// the supervisor / the E-stop thread, never by the RT loop (which reads atomics, see EstopMonitor).
#include <chrono>
#include <memory>
#include <stdexcept>
#include <string>

namespace contour::drivers::gpio {

struct LineSpec {
  std::string chip;  // "gpiochip0", "/dev/gpiochip0" or a label; may be empty with `name`
  int offset = -1;   // line offset on `chip`; -1 when looked up by `name`
  std::string name;  // line name (gpio-line-names); used when offset < 0
  bool active_low = false;
  std::string role;  // "estop", "drive_enable", ... (messages, consumer label)
  [[nodiscard]] bool configured() const { return offset >= 0 || !name.empty(); }
  [[nodiscard]] std::string describe() const;  // "estop (gpiochip0:17)" / "estop (line 'ESTOP')"
};

class GpioError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class WaitResult { kEvent, kTimeout, kError };

class GpioInputLine {
 public:
  virtual ~GpioInputLine() = default;
  [[nodiscard]] virtual bool active() = 0;  // logical level now
  // Blocks up to `timeout` for an edge (requested with edge events); consumes it.
  virtual WaitResult wait_event(std::chrono::nanoseconds timeout) = 0;
};

class GpioOutputLine {
 public:
  virtual ~GpioOutputLine() = default;
  virtual void set_active(bool on) = 0;
  [[nodiscard]] virtual bool active() const = 0;  // last value set
};

class GpioBackend {
 public:
  virtual ~GpioBackend() = default;
  virtual std::unique_ptr<GpioInputLine> request_input(const LineSpec& spec, bool edge_events) = 0;
  virtual std::unique_ptr<GpioOutputLine> request_output(const LineSpec& spec,
                                                         bool initial_active) = 0;
};

}  // namespace contour::drivers::gpio
