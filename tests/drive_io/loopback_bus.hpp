#pragma once
// A CAN bus in one process for the drive_io tests: the master's frames go to every simulated
// drive (contour-machine-sim's SimDrive) at once, the drives' frames queue for the master. Records
// what the master sent (sdo_writes() lists its SDO downloads per node) and can lose RPDO1 frames
// to node 1 on the way (drop_rpdo1: the drive keeps the last one it got).
#include <cstdint>
#include <deque>
#include <memory>
#include <utility>
#include <vector>

#include "drivers/can/can_bus.hpp"
#include "drivers/canopen/codec.hpp"
#include "tools/contour-machine-sim/sim_drive.hpp"

namespace contour::test {

class SimLoopback final : public drivers::CanBus {
 public:
  std::vector<std::unique_ptr<sim::SimDrive>> drives;
  std::deque<drivers::CanFrame> to_master;
  std::vector<drivers::CanFrame> from_master;
  int drop_rpdo1 = 0;

  void add(sim::SimDriveSetup s) {
    drives.push_back(std::make_unique<sim::SimDrive>(
        std::move(s), [this](const drivers::CanFrame& f) { to_master.push_back(f); }));
    drives.back()->power_on();
  }
  drivers::SendResult send(const drivers::CanFrame& f) noexcept override {
    from_master.push_back(f);
    if (f.id == drivers::canopen::kCobRpdo[0] + 1 && drop_rpdo1 > 0) {
      --drop_rpdo1;
      return drivers::SendResult::kOk;
    }
    for (auto& d : drives) d->on_frame(f);
    return drivers::SendResult::kOk;
  }
  bool receive(drivers::CanFrame& f) noexcept override {
    if (to_master.empty()) return false;
    f = to_master.front();
    to_master.pop_front();
    return true;
  }
  bool wait_readable(std::int64_t) noexcept override { return !to_master.empty(); }
  drivers::CanStats stats() const noexcept override { return {}; }
  drivers::BusState bus_state() const noexcept override { return drivers::BusState::kErrorActive; }
  void clear_bus_state() noexcept override {}

  // The SDO requests (initiate download) the master sent to `node`, as (index, sub, value).
  struct Write {
    std::uint16_t index;
    std::uint8_t sub;
    std::uint32_t value;
    bool operator==(const Write&) const = default;
  };
  [[nodiscard]] std::vector<Write> sdo_writes(std::uint8_t node) const {
    namespace co = drivers::canopen;
    std::vector<Write> w;
    for (const auto& f : from_master) {
      if (f.id != co::kCobSdoRx + node || f.dlc != 8 || (f.data[0] & 0xE0) != 0x20) continue;
      w.push_back({co::get_u16(&f.data[1]), f.data[3], co::get_u32(&f.data[4])});
    }
    return w;
  }
};

}  // namespace contour::test
