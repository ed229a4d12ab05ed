#include "drivers/gpio/gpiod_backend.hpp"

#include <cerrno>
#include <cstring>
#include <gpiod.hpp>
#include <system_error>

namespace contour::drivers::gpio {

namespace {

gpiod::line find(const LineSpec& spec) {
  if (!spec.configured()) throw GpioError(spec.describe() + ": no offset or name configured");
  if (spec.offset >= 0) {
    if (spec.chip.empty()) throw GpioError(spec.describe() + ": offset given without chip");
    gpiod::chip chip;
    try {
      chip.open(spec.chip, gpiod::chip::OPEN_LOOKUP);
    } catch (const std::system_error& e) {
      throw GpioError(spec.describe() + ": open chip '" + spec.chip + "': " + e.code().message());
    }
    if (spec.offset >= static_cast<int>(chip.num_lines()))
      throw GpioError(spec.describe() + ": offset " + std::to_string(spec.offset) +
                      " out of range (chip has " + std::to_string(chip.num_lines()) + " lines)");
    try {
      return chip.get_line(static_cast<unsigned>(spec.offset));
    } catch (const std::system_error& e) {
      throw GpioError(spec.describe() + ": get line: " + e.code().message());
    }
  }
  gpiod::line line;
  try {
    if (spec.chip.empty()) {
      line = gpiod::find_line(spec.name);
    } else {
      gpiod::chip chip(spec.chip, gpiod::chip::OPEN_LOOKUP);
      line = chip.find_line(spec.name);
    }
  } catch (const std::system_error& e) {
    throw GpioError(spec.describe() + ": lookup: " + e.code().message());
  }
  if (!line)
    throw GpioError(spec.describe() + ": no GPIO line named '" + spec.name + "'" +
                    (spec.chip.empty() ? std::string(" on any chip") : " on " + spec.chip));
  return line;
}

void request(gpiod::line& line, const LineSpec& spec, const std::string& consumer, int type,
             int default_val) {
  gpiod::line_request req;
  req.consumer = consumer + ":" + spec.role;
  req.request_type = type;
  if (spec.active_low) req.flags = gpiod::line_request::FLAG_ACTIVE_LOW;
  try {
    line.request(req, default_val);
  } catch (const std::system_error& e) {
    std::string msg = spec.describe() + ": request: " + e.code().message();
    if (e.code().value() == EBUSY) {
      std::string user;
      try {
        user = line.consumer();
      } catch (...) {
      }
      msg += user.empty() ? " (line busy)" : " (line busy, used by '" + user + "')";
    }
    throw GpioError(msg);
  }
}

class GpiodInput : public GpioInputLine {
 public:
  explicit GpiodInput(gpiod::line l) : line_(std::move(l)) {}
  ~GpiodInput() override { line_.release(); }
  bool active() override { return line_.get_value() != 0; }
  WaitResult wait_event(std::chrono::nanoseconds timeout) override {
    try {
      if (!line_.event_wait(timeout)) return WaitResult::kTimeout;
      (void)line_.event_read();
      return WaitResult::kEvent;
    } catch (const std::exception&) {
      return WaitResult::kError;
    }
  }

 private:
  gpiod::line line_;
};

class GpiodOutput : public GpioOutputLine {
 public:
  GpiodOutput(gpiod::line l, bool on) : line_(std::move(l)), on_(on) {}
  ~GpiodOutput() override { line_.release(); }
  void set_active(bool on) override {
    line_.set_value(on ? 1 : 0);
    on_ = on;
  }
  bool active() const override { return on_; }

 private:
  gpiod::line line_;
  bool on_;
};

}  // namespace

std::unique_ptr<GpioInputLine> GpiodBackend::request_input(const LineSpec& spec, bool edges) {
  gpiod::line line = find(spec);
  request(line, spec, consumer_,
          edges ? gpiod::line_request::EVENT_BOTH_EDGES : gpiod::line_request::DIRECTION_INPUT, 0);
  return std::make_unique<GpiodInput>(std::move(line));
}

std::unique_ptr<GpioOutputLine> GpiodBackend::request_output(const LineSpec& spec, bool initial) {
  gpiod::line line = find(spec);
  request(line, spec, consumer_, gpiod::line_request::DIRECTION_OUTPUT, initial ? 1 : 0);
  return std::make_unique<GpiodOutput>(std::move(line), initial);
}

}  // namespace contour::drivers::gpio
