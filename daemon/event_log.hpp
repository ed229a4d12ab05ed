#pragma once
// Logging: spdlog (async) for everything outside the RT thread; the RT thread posts fixed-size
// RtEvents into an SPSC ring (daemon/servo_loop.hpp) that EventLogger's thread drains, formats and
// logs, and hands to an observer (the daemon: fault list of the running program, socket events).
// setup_logging(): async stderr logger; journald_format drops timestamps/colour and prefixes each
// line with the syslog priority "<N>" that journald parses from a service's stderr.
#include <atomic>
#include <functional>
#include <string>
#include <thread>

#include "config/daemon_config.hpp"
#include "daemon/servo_loop.hpp"

namespace contour::daemon {

void setup_logging(const config::LogConfig& cfg);

// One line describing an event ("FAULT following_error axis 0: 1.234 mm > band 0.456 mm").
std::string describe(const RtEvent& e);
std::string_view to_string(CommandKind k) noexcept;

class EventLogger {
 public:
  using Observer = std::function<void(const RtEvent&, const std::string& text)>;
  EventLogger(SpscRing<RtEvent>& ring, Observer obs);
  ~EventLogger();
  EventLogger(const EventLogger&) = delete;
  EventLogger& operator=(const EventLogger&) = delete;
  // Optional: text for an event that needs non-RT context (a hold's message from the planner);
  // "" keeps describe()'s. Set before start().
  void set_describer(std::function<std::string(const RtEvent&)> f) { describer_ = std::move(f); }
  void start();
  void stop();   // drains the rest
  void drain();  // synchronous (tests)
  [[nodiscard]] std::uint64_t dropped() const noexcept { return ring_.dropped(); }

 private:
  SpscRing<RtEvent>& ring_;
  Observer obs_;
  std::function<std::string(const RtEvent&)> describer_;
  std::thread thread_;
  std::atomic<bool> running_{false};
};

}  // namespace contour::daemon
