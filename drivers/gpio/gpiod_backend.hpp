#pragma once
// libgpiod v1.6 backend (gpiod.hpp / libgpiodcxx). Lines by chip + offset, or by line name (on
// `chip` if given, else searched over all chips). Errors become GpioError naming the role, the
// chip/line and the cause: missing chip, missing line name, offset out of range, busy line
// (with the current consumer). Not testable against hardware here (no gpio-sim in this kernel):
// only the error paths are exercised by tests.
#include <string>

#include "drivers/gpio/gpio.hpp"

namespace contour::drivers::gpio {

class GpiodBackend : public GpioBackend {
 public:
  explicit GpiodBackend(std::string consumer = "contourd") : consumer_(std::move(consumer)) {}
  std::unique_ptr<GpioInputLine> request_input(const LineSpec& spec, bool edge_events) override;
  std::unique_ptr<GpioOutputLine> request_output(const LineSpec& spec,
                                                 bool initial_active) override;

 private:
  std::string consumer_;
};

}  // namespace contour::drivers::gpio
