#include "daemon/io_channels.hpp"

#include <stdexcept>

#include "drivers/gpio/gpiod_backend.hpp"

namespace contour::daemon {

namespace dm = drivers::modbus;
namespace dg = drivers::gpio;

IoChannels::IoChannels(const config::Config& cfg, std::function<void(const std::string&)> log)
    : cfg_(cfg), log_(std::move(log)) {
  if (cfg_.dynamometer.enabled) {
    reader_ = std::make_unique<dm::DynamometerReader>(cfg_.dynamometer.reader);
  }
  if (cfg_.spindle.type == "modbus_vfd") {
    auto v = cfg_.spindle.vfd;
    v.limits = cfg_.spindle.limits;
    vfd_ = std::make_unique<dm::VfdSpindle>(v);
  }
  if (cfg_.gpio.enabled) {
    dg::GpioBackend* backend = nullptr;
    if (cfg_.gpio.backend == "sim") {
      sim_ = dg::SimGpio::create();
      // A fresh simulated input reads physical low, which an active-low E-stop would take as
      // pressed: start with the chain closed (released), as on a healthy machine.
      const auto& e = cfg_.gpio.lines.estop;
      sim_->set_input_level(dg::SimGpio::key_of(e), e.active_low);
      backend = sim_.get();
    } else {
      gpiod_ = std::make_unique<dg::GpiodBackend>(cfg_.gpio.consumer);
      backend = gpiod_.get();
    }
    io_ = std::make_unique<dg::MachineIo>(*backend, cfg_.gpio.lines);
  }
}

IoChannels::~IoChannels() { stop(); }

void IoChannels::start(std::function<IoOutputs()> outputs, std::chrono::milliseconds period) {
  if (started_) return;
  started_ = true;
  if (reader_) reader_->start();
  if (vfd_) vfd_->start();
  if (io_) io_->start();
  {
    std::lock_guard lk(mu_);
    stopping_ = false;
  }
  if (io_ && outputs) {
    thread_ = std::thread([this, o = std::move(outputs), period] { supervise(o, period); });
  }
  if (log_) {
    if (reader_) {
      const auto& t = cfg_.dynamometer.reader.transport;
      log_("dynamometer: polling " +
           (t.transport == dm::Transport::kTcp ? t.host + ":" + std::to_string(t.port) : t.device) +
           " at " + std::to_string(cfg_.dynamometer.reader.poll_rate_hz) + " Hz");
    }
    if (vfd_) {
      const auto& t = cfg_.spindle.vfd.transport;
      log_("spindle: VFD over Modbus " +
           (t.transport == dm::Transport::kTcp ? t.host + ":" + std::to_string(t.port) : t.device));
    }
    if (io_)
      log_("gpio: backend " + cfg_.gpio.backend + ", E-stop " + cfg_.gpio.lines.estop.describe());
  }
}

void IoChannels::stop() {
  {
    std::lock_guard lk(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  if (reader_) reader_->stop();
  if (vfd_) vfd_->shutdown();  // run/stop register to stop, best effort
  if (io_) {
    io_->stop();
    // Safe state: enables and coolant off (MachineIo's destructor does it again).
    std::lock_guard lk(io_mu_);
    io_->set_drive_enable(false);
    io_->set_spindle_enable(false);
    io_->set_coolant(false, false);
  }
  started_ = false;
}

dm::ForceReading IoChannels::read_force() noexcept {
  if (!reader_) return dm::ForceReading{};
  return reader_->read(dm::steady_now_ns());
}

bool IoChannels::estop_tripped() const noexcept { return io_ != nullptr && io_->estop().tripped(); }

void IoChannels::set_spindle_rpm(double rpm) noexcept {
  if (reader_) reader_->set_spindle_rpm(rpm);
}

void IoChannels::command_spindle(double rpm) noexcept {
  if (vfd_) vfd_->set_speed(rpm);
}

drivers::SpindleStatus IoChannels::spindle_status() const noexcept {
  return vfd_ ? vfd_->status() : drivers::SpindleStatus{};
}

bool IoChannels::reset_estop() {
  if (!io_) return true;
  return io_->estop().reset();
}

bool IoChannels::estop_asserted() const { return io_ != nullptr && io_->estop().asserted(); }

std::optional<dm::DynamometerStatus> IoChannels::dynamometer_status() const {
  if (!reader_) return std::nullopt;
  return reader_->status();
}

std::optional<dg::MachineIoState> IoChannels::gpio_state() const {
  if (!io_) return std::nullopt;
  std::lock_guard lk(io_mu_);
  return io_->state();
}

std::string IoChannels::sim_key(const std::string& line) const {
  const auto& l = cfg_.gpio.lines;
  const std::pair<const char*, const dg::LineSpec*> roles[] = {
      {"estop", &l.estop},
      {"drive_enable", &l.drive_enable},
      {"spindle_enable", &l.spindle_enable},
      {"coolant_mist", &l.coolant_mist},
      {"coolant_flood", &l.coolant_flood},
      {"alive", &l.alive}};
  for (const auto& [role, spec] : roles) {
    if (!spec->configured()) continue;
    const std::string key = dg::SimGpio::key_of(*spec);
    if (line == role || line == key || (!spec->name.empty() && line == spec->name)) return key;
  }
  return {};
}

void IoChannels::apply_outputs(const IoOutputs& o) {
  if (!io_) return;
  std::lock_guard lk(io_mu_);
  const dg::MachineIoState s = io_->state();
  // Only on change: with libgpiod each set is an ioctl.
  if (s.drive_enable != o.drive_enable) io_->set_drive_enable(o.drive_enable);
  if (s.spindle_enable != o.spindle_enable) io_->set_spindle_enable(o.spindle_enable);
  if (s.coolant_mist != o.mist || s.coolant_flood != o.flood) io_->set_coolant(o.mist, o.flood);
  if (o.loop_cycle != last_cycle_) {
    last_cycle_ = o.loop_cycle;
    if (io_->toggle_alive()) alive_toggles_.fetch_add(1);
  }
}

void IoChannels::supervise(std::function<IoOutputs()> outputs, std::chrono::milliseconds period) {
  std::unique_lock lk(mu_);
  while (!stopping_) {
    lk.unlock();
    try {
      apply_outputs(outputs());
    } catch (const std::exception& e) {
      if (log_) log_(std::string("gpio: output update failed: ") + e.what());
    }
    lk.lock();
    cv_.wait_for(lk, period, [this] { return stopping_; });
  }
}

}  // namespace contour::daemon
