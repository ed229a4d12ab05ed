#include "drivers/gpio/estop_monitor.hpp"

#include <stdexcept>

namespace contour::drivers::gpio {

EstopMonitor::EstopMonitor(std::unique_ptr<GpioInputLine> line, std::chrono::microseconds debounce,
                           std::chrono::milliseconds recheck)
    : line_(std::move(line)), debounce_(debounce), recheck_(recheck) {
  if (!line_) throw std::invalid_argument("estop monitor: no input line");
}

EstopMonitor::~EstopMonitor() { stop(); }

void EstopMonitor::start() {
  if (thread_.joinable()) return;
  {
    std::lock_guard lk(line_mu_);
    commit(line_->active());
  }
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void EstopMonitor::stop() {
  {
    std::lock_guard lk(mu_);
    stop_.store(true);
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool EstopMonitor::sleep_for(std::chrono::microseconds d) {
  std::unique_lock lk(mu_);
  return !cv_.wait_for(lk, d, [this] { return stop_.load(); });
}

void EstopMonitor::commit(bool asserted) {
  asserted_.store(asserted, std::memory_order_release);
  if (asserted && !tripped_.exchange(true, std::memory_order_acq_rel)) trips_.fetch_add(1);
}

bool EstopMonitor::reset() {
  std::lock_guard lk(line_mu_);
  const bool now = line_->active();
  asserted_.store(now);
  if (now) return false;
  tripped_.store(false, std::memory_order_release);
  return true;
}

void EstopMonitor::run() {
  while (!stop_.load()) {
    // Bounded wait so stop() and the periodic re-check work without an extra wake-up fd.
    const auto wait = std::min<std::chrono::nanoseconds>(recheck_, std::chrono::milliseconds(20));
    const WaitResult w = line_->wait_event(wait);
    if (w == WaitResult::kError) {
      // Cannot trust the line: treat as asserted (fail safe) and back off.
      commit(true);
      if (!sleep_for(std::chrono::milliseconds(100))) break;
      continue;
    }
    if (w == WaitResult::kEvent) events_.fetch_add(1);
    bool level;
    {
      std::lock_guard lk(line_mu_);
      level = line_->active();
    }
    if (level == asserted_.load() && !(level && !tripped_.load())) continue;
    if (debounce_.count() > 0) {
      if (!sleep_for(debounce_)) break;
      std::lock_guard lk(line_mu_);
      if (line_->active() != level) continue;  // bounced
    }
    commit(level);
  }
}

}  // namespace contour::drivers::gpio
