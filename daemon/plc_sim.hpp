#pragma once
// The built-in simulated machine's PLC I/O for the sim bus (issue 20): the door, air supply,
// lube, carousel, drawbar and overtravel switches of control/plc_sim_plant.hpp, stepped inside
// the PLC scan (one step per servo cycle, lockstep like SimBus), so a test or a demo on
// config/sim.yaml sees the same machine contour-machine-sim serves over Modbus in HIL.
//
// The operator's and the fault injector's side (door, air, faults) is set from any thread
// (atomics, applied at the next step); the PLC side (step, get, set) is the RT thread's.
// Overtravel switches sit kLimitMargin_mm beyond machine.axes' soft limits.
#include <array>
#include <atomic>
#include <cstdint>

#include "config/config.hpp"
#include "control/plc_sim_plant.hpp"

namespace contour::daemon {

class PlcSimPlant {
 public:
  static constexpr double kLimitMargin_mm = 2.0;
  explicit PlcSimPlant(const config::Config& cfg);

  // Any thread.
  void set_door_open(bool open) noexcept { door_open_.store(open, std::memory_order_relaxed); }
  void set_air_supply(bool on) noexcept { air_.store(on, std::memory_order_relaxed); }
  void set_faults(const control::plc::PlantFaults& f) noexcept;
  [[nodiscard]] control::plc::PlantFaults faults() const noexcept;

  // RT thread: one step with the axes' positions; then get() the PLC inputs, set() its outputs.
  void step(double dt_s, const std::array<double, 3>& axis_mm) noexcept;
  [[nodiscard]] std::int64_t get(control::plc::PlantPoint p) const noexcept { return plant_.get(p); }
  void set(control::plc::PlantPoint p, std::int64_t v) noexcept { plant_.set(p, v); }
  [[nodiscard]] const control::plc::MachinePlant& plant() const noexcept { return plant_; }

 private:
  control::plc::MachinePlant plant_;
  std::atomic<bool> door_open_{false};
  std::atomic<bool> air_{true};
  std::atomic<std::uint8_t> faults_{0};  // bit 0 air_lost, 1 jam, 2 drawbar_stuck, 3 sensor_dead
};

}  // namespace contour::daemon
