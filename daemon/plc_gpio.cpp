#include "daemon/plc_gpio.hpp"

#include <stdexcept>

namespace contour::daemon {

namespace dg = drivers::gpio;

PlcGpio::PlcGpio(dg::GpioBackend& backend, const std::vector<dg::LineSpec>& inputs,
                 const std::vector<dg::LineSpec>& outputs, const std::vector<bool>& safe,
                 std::chrono::milliseconds period, std::function<void(const std::string&)> log)
    : safe_(safe), period_(period), log_(std::move(log)) {
  if (inputs.size() > kPlcMaxGpioLines || outputs.size() > kPlcMaxGpioLines)
    throw std::invalid_argument("plc: more than " + std::to_string(kPlcMaxGpioLines) +
                                " GPIO inputs or outputs");
  safe_.resize(outputs.size(), false);
  for (const auto& s : inputs) in_.push_back(backend.request_input(s, false));
  for (std::size_t i = 0; i < outputs.size(); ++i)
    out_.push_back(backend.request_output(outputs[i], safe_[i]));
}

PlcGpio::~PlcGpio() { stop(); }

void PlcGpio::start() {
  if (thread_.joinable()) return;
  {
    std::lock_guard lk(mu_);
    stopping_ = false;
  }
  thread_ = std::thread([this] { run(); });
}

void PlcGpio::stop() {
  {
    std::lock_guard lk(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard lk(mu_);
  for (std::size_t i = 0; i < out_.size(); ++i) {
    try {
      if (out_[i]->active() != safe_[i]) out_[i]->set_active(safe_[i]);
    } catch (const std::exception& e) {
      if (log_) log_(std::string("plc gpio: safe output failed: ") + e.what());
    }
  }
}

void PlcGpio::poll_once() {
  std::lock_guard lk(mu_);
  GpioBits o;
  if (outbox_.read(o)) out_written_ = true;
  if (out_written_) {
    for (std::size_t i = 0; i < out_.size(); ++i) {
      const bool v = o.v[i] != 0;
      if (out_[i]->active() != v) out_[i]->set_active(v);
    }
  }
  GpioBits r;
  for (std::size_t i = 0; i < in_.size(); ++i) r.v[i] = in_[i]->active() ? 1 : 0;
  r.t_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
               .count();
  r.seq = ++seq_;
  inbox_.write(r);
}

void PlcGpio::run() {
  std::unique_lock lk(mu_);
  while (!stopping_) {
    lk.unlock();
    try {
      poll_once();
    } catch (const std::exception& e) {
      if (log_) log_(std::string("plc gpio: ") + e.what());
    }
    lk.lock();
    cv_.wait_for(lk, period_, [this] { return stopping_; });
  }
}

}  // namespace contour::daemon
