#pragma once
// A CAN bus in one process for the drive_io tests: the master's frames go to every simulated
// drive (contour-machine-sim's SimDrive) at once, the drives' frames queue for the master. Records
// what the master sent (sdo_writes() lists its SDO downloads per node) and can lose RPDO1 frames
// to node 1 on the way (drop_rpdo1: the drive keeps the last one it got).
#include <unistd.h>

#include <cstdint>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "config/config.hpp"
#include "daemon/canopen_bus.hpp"
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

// A simulated CiA 402 drive with the tests' Table-1-like plant (120 1/s, 30 ms) at 1 ms;
// contour-machine-sim's default switches unless the test sets its own.
inline sim::SimDriveSetup sim_drive_setup(std::uint8_t node, const std::string& name,
                                          double counts_per_mm = 2000.0) {
  sim::SimDriveSetup s;
  s.node_id = node;
  s.name = name;
  s.counts_per_mm = counts_per_mm;
  s.plant.gain_per_s = 120.0;
  s.plant.tau_s = 0.03;
  s.plant.period_s = 0.001;
  s.period_s = 0.001;
  return s;
}

// The real daemon::CanopenBus over a SimLoopback (no event thread: the test takes the events),
// started by start() once the test has added its nodes; cycle() is one begin/read/write.
struct LoopbackBench {
  explicit LoopbackBench(const config::Config& c) : cfg(c) {}
  void start() {
    bus = std::make_unique<daemon::CanopenBus>(cfg, can, daemon::CanopenBus::Log{});
    bus->set_event_thread(false);
    bus->start();
  }
  daemon::BusFeedback cycle(const daemon::AxisCommands& cmd) {
    daemon::BusFeedback fb;
    bus->begin_cycle();
    bus->read(fb);
    bus->write(cmd);
    return fb;
  }
  config::Config cfg;
  SimLoopback can;
  std::unique_ptr<daemon::CanopenBus> bus;
};

// A directory of this test's own (<tmp>/<prefix>_<pid>_<n>), removed at the end; load() writes a
// config text to c.yaml in it and loads it (relative program files resolve there).
struct ScratchDir {
  explicit ScratchDir(const std::string& prefix) {
    dir = std::filesystem::temp_directory_path() /
          (prefix + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::create_directories(dir);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  void write(const std::string& name, const std::string& text) const { std::ofstream(dir / name) << text; }
  config::Config load(const std::string& text) const {
    write("c.yaml", text);
    return config::load_config_file((dir / "c.yaml").string());
  }
  std::filesystem::path dir;
  static inline int counter = 0;
};

}  // namespace contour::test
