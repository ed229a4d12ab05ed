#pragma once
// E-stop input monitor. A non-RT thread waits for edge events on the E-stop line (libgpiod event
// fd or the simulated line), debounces (the new level must hold for `debounce`), and latches an
// assertion into an atomic flag. The RT loop reads tripped() each cycle: one relaxed atomic load,
// noexcept, wait-free. The latch is cleared only by reset() (supervisor, non-RT) and only while
// the input is released. The thread also re-reads the level every `recheck` (100 ms) so a missed
// edge cannot hide an asserted E-stop. This is a software view: machine safety rests on the
// hardware E-stop chain, not on this daemon staying alive.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>

#include "drivers/gpio/gpio.hpp"

namespace contour::drivers::gpio {

class EstopMonitor {
 public:
  EstopMonitor(std::unique_ptr<GpioInputLine> line, std::chrono::microseconds debounce,
               std::chrono::milliseconds recheck = std::chrono::milliseconds(100));
  ~EstopMonitor();
  EstopMonitor(const EstopMonitor&) = delete;
  EstopMonitor& operator=(const EstopMonitor&) = delete;

  void start();  // reads the level once (asserted at start -> tripped), spawns the thread
  void stop();

  // RT side.
  [[nodiscard]] bool tripped() const noexcept { return tripped_.load(std::memory_order_acquire); }
  [[nodiscard]] bool asserted() const noexcept { return asserted_.load(std::memory_order_acquire); }
  // Non-RT. Returns false (latch kept) while the E-stop input is still asserted.
  bool reset();
  [[nodiscard]] std::uint64_t trips() const noexcept { return trips_.load(); }
  [[nodiscard]] std::uint64_t events() const noexcept { return events_.load(); }

 private:
  void run();
  void commit(bool asserted);
  bool sleep_for(std::chrono::microseconds d);  // false if stopping

  std::unique_ptr<GpioInputLine> line_;
  std::chrono::microseconds debounce_;
  std::chrono::milliseconds recheck_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::mutex mu_;
  std::condition_variable cv_;
  std::mutex line_mu_;  // the line is read by the thread and by reset()
  std::atomic<bool> tripped_{false};
  std::atomic<bool> asserted_{false};
  std::atomic<std::uint64_t> trips_{0};
  std::atomic<std::uint64_t> events_{0};
};

}  // namespace contour::drivers::gpio
