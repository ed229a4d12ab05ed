#pragma once
// Spindle as a VFD over Modbus (RTU normally; TCP for tests and Modbus-TCP VFDs). A non-RT thread
// at `update_rate_hz` (default 20 Hz) slews the setpoint (SpindleRamp), writes the setpoint
// register (counts = rpm * setpoint_counts_per_rpm, unsigned magnitude; direction via the run
// command values), writes run/stop (coil or register), and reads the actual speed register.
// Communication errors: counted, comm_ok=false, reconnect next cycle; the RT side only reads
// atomics (set_speed/status noexcept, no lock, no allocation).
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "drivers/modbus/modbus_client.hpp"
#include "drivers/spindle.hpp"

namespace contour::drivers::modbus {

struct VfdSettings {
  TransportSettings transport{};
  SpindleLimits limits{};
  std::uint16_t setpoint_register = 0;  // holding register, written
  double setpoint_counts_per_rpm = 1.0;
  bool run_is_coil = false;  // else a holding register
  std::uint16_t run_address = 1;
  std::uint16_t run_forward_value = 1;  // register values (coil: on/off)
  std::uint16_t run_reverse_value = 2;
  std::uint16_t stop_value = 0;
  RegisterFunction actual_function = RegisterFunction::kHolding;
  std::uint16_t actual_register = 2;
  double actual_counts_per_rpm = 1.0;
  double update_rate_hz = 20.0;
};

class VfdSpindle : public Spindle {
 public:
  explicit VfdSpindle(VfdSettings s);
  ~VfdSpindle() override;
  void start();
  void shutdown();  // stops the motor (best effort) and joins the thread

  double set_speed(double rpm) noexcept override;
  void stop() noexcept override { set_speed(0.0); }
  [[nodiscard]] SpindleStatus status() const noexcept override;
  [[nodiscard]] const SpindleLimits& limits() const noexcept override { return s_.limits; }
  [[nodiscard]] std::uint64_t comm_errors() const noexcept { return comm_errors_.load(); }

 private:
  void run();
  bool cycle(ModbusClient& c, double setpoint_rpm);
  VfdSettings s_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::mutex mu_;
  std::condition_variable cv_;
  std::atomic<double> target_{0.0}, setpoint_{0.0}, actual_{0.0};
  std::atomic<bool> comm_ok_{false};
  std::atomic<std::uint64_t> comm_errors_{0};
};

}  // namespace contour::drivers::modbus
