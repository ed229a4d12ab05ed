// CiA 401 I/O modules over CANopen, in one process: the daemon's CanopenBus (master, module node
// from the PLC's cia401 bindings) against contour-machine-sim's SimDrive in its I/O-module mode
// (SimIoModule: the model the HIL test runs over vcan), over a loopback CanBus that delivers every
// frame at once (lockstep).
//   - bring-up: 0x1000 read (profile 401), each object the PLC uses read once, TPDO1/RPDO1 mapped
//     with exactly those objects in the CiA 301 order, the module's other PDOs off;
//   - each cycle the module's inputs arrive fresh in BusFeedback::io and AxisCommands::io reaches
//     its outputs (and, looped back by the simulated module, its inputs);
//   - a silent module's streak grows; a drive on the module's node-id and a module without an
//     object stop the start-up naming node and object.
#include <gtest/gtest.h>

#include <algorithm>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "daemon/canopen_bus.hpp"
#include "drivers/canopen/codec.hpp"
#include "tests/drive_io/loopback_bus.hpp"
#include "tools/contour-machine-sim/sim_drive.hpp"

namespace contour {
namespace {

namespace co = drivers::canopen;
using drivers::BusState;
using drivers::CanFrame;
using drivers::CanStats;
using drivers::SendResult;

using Loopback = test::SimLoopback;  // tests/drive_io/loopback_bus.hpp

constexpr const char* kConfig = R"(loop: {period_us: 1000, tpdo_deadline_us: 800}
safety: {missed_tpdo_streak: 3, ferror_mm: 5.0, min_ferror_mm: 1.0}
machine:
  axes:
    - {name: X, node_id: 1, counts_per_mm: 2000, sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1},
       min_mm: -200, max_mm: 200, max_velocity_mm_min: 10000}
bus:
  type: socketcan
  interface: vcan0
  lockstep: true
  master_heartbeat_ms: 0
  drives: {mode: csv, heartbeat_ms: 50, heartbeat_timeout_ms: 200, rpdo: ["0x6040", "0x60FF"], tpdo: ["0x6041", "0x6064"]}
plc:
  programs: [{file: io.st}]
  signals:
    - {name: clamp, cia401: {node: 5, digital_output: 1, bit: 2}}
    - {name: clamp_fb, cia401: {node: 5, digital_input: 1, bit: 2}}
    - {name: part, cia401: {node: 5, digital_input: 2, bit: 4}}
    - {name: valve, type: INT, cia401: {node: 5, analog_output: 2}}
    - {name: flow, type: INT, cia401: {node: 5, analog_input: 2}}
)";

struct Scratch : test::ScratchDir {
  Scratch() : ScratchDir("cia401_lb") {
    write("io.st", "PROGRAM io\n  clamp := part;\nEND_PROGRAM\n");
    write("c.yaml", kConfig);
  }
  config::Config load() const { return config::load_config_file((dir / "c.yaml").string()); }
};

sim::SimDriveSetup drive_x() { return test::sim_drive_setup(1, "X"); }

sim::SimDriveSetup module5() {
  sim::SimDriveSetup s;
  s.node_id = 5;
  s.name = "io5";
  s.period_s = 0.001;
  s.io.enabled = true;  // 2 DI bytes, 2 DO bytes, 2 AI, 2 AO (the defaults)
  s.io.fixed_inputs = {{2, 0x10}};
  return s;
}

struct Bench : test::LoopbackBench {
  explicit Bench(const config::Config& c, sim::SimDriveSetup m = module5()) : LoopbackBench(c) {
    can.add(drive_x());
    can.add(std::move(m));
  }
};

using W = Loopback::Write;
bool has(const std::vector<W>& v, W w) { return std::find(v.begin(), v.end(), w) != v.end(); }

TEST(Cia401Loopback, BringUpMapsExactlyTheObjectsThePlcUses) {
  Scratch s;
  Bench b(s.load());
  b.start();
  const auto w = b.can.sdo_writes(5);
  // TPDO1 {0x6000:01, 0x6000:02, 0x6401:02} on 0x185, RPDO1 {0x6200:01, 0x6411:02} on 0x205.
  EXPECT_TRUE(has(w, W{0x1800, 1, 0x80000000u | 0x185}));
  EXPECT_TRUE(has(w, W{0x1A00, 1, 0x60000108u}));
  EXPECT_TRUE(has(w, W{0x1A00, 2, 0x60000208u}));
  EXPECT_TRUE(has(w, W{0x1A00, 3, 0x64010210u}));
  EXPECT_TRUE(has(w, W{0x1A00, 0, 3}));
  EXPECT_TRUE(has(w, W{0x1800, 1, 0x185}));
  EXPECT_TRUE(has(w, W{0x1600, 1, 0x62000108u}));
  EXPECT_TRUE(has(w, W{0x1600, 2, 0x64110210u}));
  EXPECT_TRUE(has(w, W{0x1600, 0, 2}));
  EXPECT_TRUE(has(w, W{0x1400, 1, 0x205}));
  EXPECT_TRUE(has(w, W{0x1801, 1, 0x80000000u | 0x285}));  // the others off
  EXPECT_TRUE(has(w, W{0x1401, 1, 0x80000000u | 0x305}));
  EXPECT_TRUE(has(w, W{0x1017, 0, 50}));
  // Nothing of CiA 402 written to a module.
  for (const W& x : w) EXPECT_TRUE(x.index < 0x6000 || x.index > 0x6FFF) << std::hex << x.index;
  // The drive is configured as without the module (its first write is the heartbeat producer).
  EXPECT_FALSE(b.can.sdo_writes(1).empty());
}

TEST(Cia401Loopback, InputsArriveEachCycleAndOutputsReachTheModule) {
  Scratch s;
  Bench b(s.load());
  b.start();
  daemon::AxisCommands cmd;
  cmd.io[0].node_id = 5;
  cmd.io[0].digital[0] = 0x04;  // 0x6200:01 bit 2
  cmd.io[0].digital[1] = 0xFF;  // 0x6200:02: not mapped, never sent
  cmd.io[0].analog[1] = -1234;  // 0x6411:02
  daemon::BusFeedback fb;
  for (int k = 0; k < 5; ++k) fb = b.cycle(cmd);
  ASSERT_EQ(fb.io_modules, 1);
  const daemon::IoModuleFeedback& m = fb.io[0];
  EXPECT_EQ(m.node_id, 5);
  EXPECT_TRUE(m.fresh);
  EXPECT_EQ(m.missed_streak, 0u);
  EXPECT_EQ(m.digital[1], 0x10);  // pinned
  EXPECT_EQ(m.digital[0], 0x04);  // looped back from 0x6200:01
  EXPECT_EQ(m.analog[1], -1234);  // looped back from 0x6411:02
  const auto& mod = *b.can.drives[1];
  EXPECT_EQ(mod.io_values(0x6200), (std::vector<std::int64_t>{0x04, 0x00}));
  EXPECT_EQ(mod.io_values(0x6411), (std::vector<std::int64_t>{0, -1234}));
  EXPECT_TRUE(fb.axis[0].fresh);  // the drive as before

  // Silent module: the streak grows, the last values stay.
  b.can.drives[1]->drop_tpdos(4);
  for (int k = 0; k < 3; ++k) fb = b.cycle(cmd);
  EXPECT_FALSE(fb.io[0].fresh);
  EXPECT_EQ(fb.io[0].missed_streak, 3u);
  EXPECT_EQ(fb.io[0].digital[1], 0x10);
  EXPECT_TRUE(fb.axis[0].fresh);
  // stop(): the outputs go out as 0 before the nodes go pre-operational.
  b.bus->stop();
  EXPECT_EQ(mod.io_values(0x6200), (std::vector<std::int64_t>{0, 0}));
  EXPECT_EQ(mod.io_values(0x6411), (std::vector<std::int64_t>{0, 0}));
}

TEST(Cia401Loopback, ADriveOnTheModulesNodeIdIsRefusedNamingTheProfile) {
  Scratch s;
  sim::SimDriveSetup d = drive_x();
  d.node_id = 5;
  d.name = "not-a-module";
  Bench b(s.load(), d);
  try {
    b.start();
    FAIL() << "a CiA 402 drive taken for a CiA 401 module";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(
        std::string(e.what()).find("node 5 (I/O module): 0x1000 device type 0x00020192 is not "
                                   "a CiA 401 I/O module (profile 402)"),
        std::string::npos)
        << e.what();
  }
}

TEST(Cia401Loopback, AModuleWithoutAnObjectThePlcUsesIsRefusedNamingIt) {
  Scratch s;
  sim::SimDriveSetup m = module5();
  m.io.analog_inputs = 1;  // 0x6401:02 missing
  Bench b(s.load(), m);
  try {
    b.start();
    FAIL() << "started without 0x6401:02";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(
        std::string(e.what()).find("node 5 (I/O module): 0x6401:02 (analog input, needed by "
                                   "the PLC's cia401 bindings): the module does not provide it "
                                   "(SDO abort 0x06090011"),
        std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace contour
