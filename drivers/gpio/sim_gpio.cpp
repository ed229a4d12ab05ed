#include "drivers/gpio/sim_gpio.hpp"

namespace contour::drivers::gpio {

class SimInput : public GpioInputLine {
 public:
  SimInput(std::shared_ptr<SimGpio> sim, std::string key, std::uint64_t seen)
      : sim_(std::move(sim)), key_(std::move(key)), seen_(seen) {}
  ~SimInput() override {
    std::lock_guard lk(sim_->mu_);
    sim_->lines_[key_].requested = false;
  }
  bool active() override {
    std::lock_guard lk(sim_->mu_);
    const auto& l = sim_->lines_[key_];
    return l.level != l.active_low;
  }
  WaitResult wait_event(std::chrono::nanoseconds timeout) override {
    std::unique_lock lk(sim_->mu_);
    auto& l = sim_->lines_[key_];
    if (!sim_->cv_.wait_for(lk, timeout, [&] { return l.events != seen_; }))
      return WaitResult::kTimeout;
    seen_ = l.events;
    return WaitResult::kEvent;
  }

 private:
  std::shared_ptr<SimGpio> sim_;
  std::string key_;
  std::uint64_t seen_;
};

class SimOutput : public GpioOutputLine {
 public:
  SimOutput(std::shared_ptr<SimGpio> sim, std::string key, bool on)
      : sim_(std::move(sim)), key_(std::move(key)) {
    set_active(on);
  }
  ~SimOutput() override {
    std::lock_guard lk(sim_->mu_);
    sim_->lines_[key_].requested = false;
  }
  void set_active(bool on) override {
    std::lock_guard lk(sim_->mu_);
    auto& l = sim_->lines_[key_];
    l.level = on != l.active_low;
    on_ = on;
  }
  bool active() const override { return on_; }

 private:
  std::shared_ptr<SimGpio> sim_;
  std::string key_;
  bool on_ = false;
};

std::string SimGpio::key_of(const LineSpec& spec) {
  return spec.offset >= 0 ? spec.chip + ":" + std::to_string(spec.offset) : spec.name;
}

SimGpio::Line& SimGpio::claim(const LineSpec& spec, bool output) {
  if (!spec.configured()) throw GpioError(spec.describe() + ": no offset or name configured");
  Line& l = lines_[key_of(spec)];
  if (l.requested) throw GpioError(spec.describe() + ": request: line busy (sim)");
  l.requested = true;
  l.output = output;
  l.active_low = spec.active_low;
  return l;
}

std::unique_ptr<GpioInputLine> SimGpio::request_input(const LineSpec& spec, bool /*edges*/) {
  std::lock_guard lk(mu_);
  Line& l = claim(spec, false);
  return std::make_unique<SimInput>(shared_from_this(), key_of(spec), l.events);
}

std::unique_ptr<GpioOutputLine> SimGpio::request_output(const LineSpec& spec, bool initial) {
  {
    std::lock_guard lk(mu_);
    claim(spec, true);
  }
  return std::make_unique<SimOutput>(shared_from_this(), key_of(spec), initial);
}

void SimGpio::set_input_level(const std::string& key, bool physical_high) {
  {
    std::lock_guard lk(mu_);
    Line& l = lines_[key];
    if (l.level != physical_high) {
      l.level = physical_high;
      ++l.events;
    }
  }
  cv_.notify_all();
}

bool SimGpio::output_level(const std::string& key) const {
  std::lock_guard lk(mu_);
  const auto it = lines_.find(key);
  return it != lines_.end() && it->second.level;
}

bool SimGpio::output_active(const std::string& key) const {
  std::lock_guard lk(mu_);
  const auto it = lines_.find(key);
  return it != lines_.end() && (it->second.level != it->second.active_low);
}

bool SimGpio::exists(const std::string& key) const {
  std::lock_guard lk(mu_);
  return lines_.count(key) != 0;
}

}  // namespace contour::drivers::gpio
