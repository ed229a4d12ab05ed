#include "daemon/bus_factory.hpp"

#include <stdexcept>
#include <vector>

#include "daemon/canopen_bus.hpp"
#include "daemon/sim_bus.hpp"

namespace contour::daemon {

std::unique_ptr<AxisBus> make_axis_bus(const config::Config& cfg, BusLog log) {
  if (cfg.bus.type == "socketcan") {
    // The bus logs its start-up (bus load) and, from an event thread of its own, every master
    // event (EMCY text, drive fault, heartbeat loss, missed-TPDO streak) through `log`.
    return std::make_unique<CanopenBus>(cfg, std::move(log));
  }
  if (cfg.bus.type != "sim") {
    throw std::runtime_error("bus.type '" + cfg.bus.type + "' is not supported (sim, socketcan)");
  }
  auto bus = std::make_unique<SimBus>(sim_bus_drives(cfg));
  configure_sim_machine(*bus, cfg);  // 0x60FD limit/home switches, power-up position
  return bus;
}

}  // namespace contour::daemon
