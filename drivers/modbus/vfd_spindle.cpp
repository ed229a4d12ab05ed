#include "drivers/modbus/vfd_spindle.hpp"

#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace contour::drivers::modbus {

VfdSpindle::VfdSpindle(VfdSettings s) : s_(std::move(s)) {
  if (!(s_.update_rate_hz > 0.0 && s_.update_rate_hz <= 200.0))
    throw std::invalid_argument("vfd spindle: update_rate_hz must be in (0, 200]");
  if (!(s_.limits.max_rpm > 0.0) || s_.limits.min_rpm < 0.0 ||
      s_.limits.min_rpm > s_.limits.max_rpm)
    throw std::invalid_argument("vfd spindle: need 0 <= min_rpm <= max_rpm, max_rpm > 0");
  if (!(s_.limits.rate_rpm_s > 0.0)) throw std::invalid_argument("vfd spindle: rate_rpm_s <= 0");
}

VfdSpindle::~VfdSpindle() { shutdown(); }

void VfdSpindle::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void VfdSpindle::shutdown() {
  {
    std::lock_guard lk(mu_);
    stop_.store(true);
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

double VfdSpindle::set_speed(double rpm) noexcept {
  const double t = clamp_spindle_rpm(rpm, s_.limits);
  target_.store(t);
  return t;
}

SpindleStatus VfdSpindle::status() const noexcept {
  SpindleStatus st;
  st.target_rpm = target_.load();
  st.setpoint_rpm = setpoint_.load();
  st.actual_rpm = actual_.load();
  st.running = st.setpoint_rpm != 0.0;
  st.comm_ok = comm_ok_.load();
  st.fault = st.comm_ok ? SpindleFault::kNone : SpindleFault::kCommunication;
  st.at_speed = st.comm_ok && std::abs(st.setpoint_rpm - st.target_rpm) < 1e-6 &&
                spindle_at_speed(st.actual_rpm, st.target_rpm, s_.limits);
  return st;
}

bool VfdSpindle::cycle(ModbusClient& c, double sp) {
  const double counts = std::round(std::abs(sp) * s_.setpoint_counts_per_rpm);
  const auto reg = static_cast<std::uint16_t>(std::clamp(counts, 0.0, 65535.0));
  if (c.write_register(s_.setpoint_register, reg)) return false;
  const bool run = sp != 0.0;
  if (s_.run_is_coil) {
    if (c.write_coil(s_.run_address, run)) return false;
  } else {
    const std::uint16_t v =
        !run ? s_.stop_value : (sp > 0 ? s_.run_forward_value : s_.run_reverse_value);
    if (c.write_register(s_.run_address, v)) return false;
  }
  std::array<std::uint16_t, 1> a{};
  if (c.read_registers(s_.actual_function, s_.actual_register, a)) return false;
  const double mag = s_.actual_counts_per_rpm > 0 ? a[0] / s_.actual_counts_per_rpm : 0.0;
  actual_.store(sp < 0 ? -mag : mag);
  return true;
}

void VfdSpindle::run() {
  using Clock = std::chrono::steady_clock;
  ModbusClient client(s_.transport);
  SpindleRamp ramp(s_.limits);
  const double dt = 1.0 / s_.update_rate_hz;
  const auto period =
      std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(dt));
  auto next = Clock::now();
  while (!stop_.load()) {
    const double sp = ramp.step(target_.load(), dt);
    setpoint_.store(sp);
    bool ok = !client.connect();
    ok = ok && cycle(client, sp);
    if (!ok) {
      comm_errors_.fetch_add(1);
      client.close();
    }
    comm_ok_.store(ok);
    next += period;
    if (next < Clock::now()) next = Clock::now();
    std::unique_lock lk(mu_);
    if (cv_.wait_until(lk, next, [this] { return stop_.load(); })) break;
  }
  // Best effort stop on the way out (the drive's own comm-loss timeout is the real guard).
  if (!client.connect()) (void)cycle(client, 0.0);
  client.close();
}

}  // namespace contour::drivers::modbus
