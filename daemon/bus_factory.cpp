#include "daemon/bus_factory.hpp"

#include <stdexcept>
#include <vector>

#include "daemon/sim_bus.hpp"

namespace contour::daemon {

std::unique_ptr<AxisBus> make_axis_bus(const config::Config& cfg, BusLog /*log*/) {
  if (cfg.bus.type != "sim") {
    throw std::runtime_error("bus.type '" + cfg.bus.type +
                             "' is not wired into contourd yet (only 'sim'); see daemon/README.md");
  }
  std::vector<control::FeedDriveParams> drives;
  for (const auto& a : cfg.machine.axes) {
    control::FeedDriveParams p = a.drive;
    p.period_s = cfg.machine.period_s;
    drives.push_back(p);
  }
  return std::make_unique<SimBus>(drives);
}

}  // namespace contour::daemon
