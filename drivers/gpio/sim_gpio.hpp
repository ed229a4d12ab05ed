#pragma once
// Simulated GPIO backend. Lines spring into existence when requested (keyed by name, else
// "chip:offset"); a line can be requested once (a second request fails "busy", like libgpiod).
// Tests and contour-machine-sim drive inputs by physical level and read outputs.
// Thread-safe: one mutex; input waiters are woken by a condition variable.
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "drivers/gpio/gpio.hpp"

namespace contour::drivers::gpio {

class SimGpio : public GpioBackend, public std::enable_shared_from_this<SimGpio> {
 public:
  static std::shared_ptr<SimGpio> create() { return std::shared_ptr<SimGpio>(new SimGpio()); }

  std::unique_ptr<GpioInputLine> request_input(const LineSpec& spec, bool edge_events) override;
  std::unique_ptr<GpioOutputLine> request_output(const LineSpec& spec,
                                                 bool initial_active) override;

  // Test / simulator side. `key` is the line name, or "chip:offset".
  void set_input_level(const std::string& key, bool physical_high);
  [[nodiscard]] bool output_level(const std::string& key) const;   // physical
  [[nodiscard]] bool output_active(const std::string& key) const;  // logical
  [[nodiscard]] bool exists(const std::string& key) const;
  [[nodiscard]] static std::string key_of(const LineSpec& spec);

 private:
  friend class SimInput;
  friend class SimOutput;
  struct Line {
    bool requested = false;
    bool output = false;
    bool active_low = false;
    bool level = false;  // physical
    std::uint64_t events = 0;
  };
  SimGpio() = default;
  Line& claim(const LineSpec& spec, bool output);
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::map<std::string, Line> lines_;
};

}  // namespace contour::drivers::gpio
