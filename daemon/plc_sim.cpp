#include "daemon/plc_sim.hpp"

namespace contour::daemon {

PlcSimPlant::PlcSimPlant(const config::Config& cfg) {
  std::array<double, 3> neg{-1e300, -1e300, -1e300}, pos{1e300, 1e300, 1e300};
  for (std::size_t a = 0; a < cfg.machine.axes.size() && a < 3; ++a) {
    neg[a] = cfg.machine.axes[a].min_mm - kLimitMargin_mm;
    pos[a] = cfg.machine.axes[a].max_mm + kLimitMargin_mm;
  }
  plant_.set_limits(neg, pos);
  plant_.step(0.0, {0.0, 0.0, 0.0});  // inputs valid before the first scan
}

void PlcSimPlant::set_faults(const control::plc::PlantFaults& f) noexcept {
  faults_.store(static_cast<std::uint8_t>((f.air_lost ? 1 : 0) | (f.carousel_jam ? 2 : 0) |
                                          (f.drawbar_stuck ? 4 : 0) | (f.pocket_sensor_dead ? 8 : 0)),
                std::memory_order_relaxed);
}

control::plc::PlantFaults PlcSimPlant::faults() const noexcept {
  const std::uint8_t b = faults_.load(std::memory_order_relaxed);
  return {(b & 1) != 0, (b & 2) != 0, (b & 4) != 0, (b & 8) != 0};
}

void PlcSimPlant::step(double dt_s, const std::array<double, 3>& axis_mm) noexcept {
  plant_.set_door_open(door_open_.load(std::memory_order_relaxed));
  plant_.set_air_supply(air_.load(std::memory_order_relaxed));
  plant_.set_faults(faults());
  plant_.step(dt_s, axis_mm);
}

}  // namespace contour::daemon
