// CiA 402 digital I/O over CANopen, in one process: the daemon's CanopenBus (master, mapping
// from the PLC's cia402 bindings) against contour-machine-sim's SimDrive, the same drive model
// the HIL tests run over vcan, connected by a loopback CanBus that delivers every frame at once
// (lockstep, no wall-clock dependence).
//   - drives no binding names keep their SDO configuration (and so their PDO mapping) bit for bit;
//     a drive with bindings gets TPDO2 {0x60FD:00} / RPDO2 {0x60FE:01} and 0x60FE:02 = the mask;
//   - the limit switches of the simulated drive arrive in the feedback, fresh, and follow the
//     axis; the outputs reach the drive's 0x60FE:01 (read back over SDO);
//   - a dropped TPDO is not presented as fresh;
//   - a drive without 0x60FD, and a one-PDO drive, stop the start-up naming node and object.
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

constexpr const char* kMachine = R"(loop: {period_us: 1000, tpdo_deadline_us: 800}
safety: {missed_tpdo_streak: 3, ferror_mm: 5.0, min_ferror_mm: 1.0}
machine:
  axes:
    - {name: X, node_id: 1, counts_per_mm: 2000, sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1},
       min_mm: -200, max_mm: 200, max_velocity_mm_min: 10000}
    - {name: Y, node_id: 2, counts_per_mm: 2000, sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1},
       min_mm: -200, max_mm: 200, max_velocity_mm_min: 10000}
bus:
  type: socketcan
  interface: vcan0
  lockstep: true
  master_heartbeat_ms: 0
  profiles: {one-pdo: {rpdos: 1, tpdos: 1}}
  drives: {mode: csv, heartbeat_ms: 50, heartbeat_timeout_ms: 200, rpdo: ["0x6040", "0x60FF"], tpdo: ["0x6041", "0x6064"]}
)";

constexpr const char* kPlc = R"(plc:
  programs: [{file: io.st}]
  signals:
    - {name: x_pos_limit, cia402: {axis: X, input: positive_limit}}
    - {name: x_cam, cia402: {axis: X, input: 17}}
    - {name: x_lamp, cia402: {axis: X, output: 16}}
    - {name: x_valve, cia402: {axis: X, output: 18}}
)";

struct Scratch : test::ScratchDir {
  Scratch() : ScratchDir("drive_io") {
    write("io.st", "PROGRAM io\n  x_lamp := x_pos_limit;\n  x_valve := x_cam;\nEND_PROGRAM\n");
  }
};

sim::SimDriveSetup drive(std::uint8_t node, const std::string& name) {
  sim::SimDriveSetup s = test::sim_drive_setup(node, name);
  // As contour-machine-sim's defaults, plus two cams: bit 16 on right away (above -1 mm), bit 17
  // once the axis passes +1 mm.
  s.switches = {
      {0, -202.0, false}, {1, 202.0, true}, {2, -199.5, false}, {16, -1.0, true}, {17, 1.0, true}};
  return s;
}

struct Bench : test::LoopbackBench {
  explicit Bench(const config::Config& c) : LoopbackBench(c) {
    can.add(drive(1, "X"));
    can.add(drive(2, "Y"));
  }
};

TEST(DriveIoLoopback, NodesWithoutBindingsKeepTheirConfigurationBitForBit) {
  Scratch s;
  Bench plain(s.load(kMachine));
  plain.start();
  Bench with_io(s.load(std::string(kMachine) + kPlc));
  with_io.start();
  // Y is named by no binding: the same SDO writes, in the same order, with or without the PLC.
  const auto y_plain = plain.can.sdo_writes(2), y_io = with_io.can.sdo_writes(2);
  ASSERT_FALSE(y_plain.empty());
  EXPECT_EQ(y_plain, y_io);
  // Without bindings X is configured as Y is (TPDO2/RPDO2 switched off, nothing of 0x60FD/FE).
  const auto x_plain = plain.can.sdo_writes(1);
  ASSERT_EQ(x_plain.size(), y_plain.size());
  for (std::size_t k = 0; k < x_plain.size(); ++k) {
    EXPECT_EQ(x_plain[k].index, y_plain[k].index) << k;
    EXPECT_NE(x_plain[k].index, 0x60FE) << k;
  }
  using W = Loopback::Write;
  auto has = [](const std::vector<W>& v, W w) {
    return std::find(v.begin(), v.end(), w) != v.end();
  };
  EXPECT_TRUE(has(x_plain, W{0x1801, 1, 0x80000000u | 0x281}));  // TPDO2 off
  EXPECT_TRUE(has(x_plain, W{0x1401, 1, 0x80000000u | 0x301}));  // RPDO2 off
  // ... and never mapped: no write to the mapping of TPDO2/RPDO2, nor to 0x60FE.
  auto touches = [](const std::vector<W>& v, std::uint16_t index) {
    return std::any_of(v.begin(), v.end(), [&](const W& w) { return w.index == index; });
  };
  for (const auto* v : {&x_plain, &y_plain, &y_io}) {
    EXPECT_FALSE(touches(*v, 0x1A01));
    EXPECT_FALSE(touches(*v, 0x1601));
    EXPECT_FALSE(touches(*v, 0x60FE));
  }

  // X with bindings: TPDO1/RPDO1 as before, TPDO2 = {0x60FD:00, 32 bit} on 0x281, RPDO2 =
  // {0x60FE:01, 32 bit} on 0x301, 0x60FE:02 = bits 16 and 18.
  const auto x_io = with_io.can.sdo_writes(1);
  for (const W& w : x_plain) {
    if (w.index == 0x1801 || w.index == 0x1401) continue;
    EXPECT_TRUE(has(x_io, w)) << std::hex << w.index << ":" << int{w.sub} << " = " << w.value;
  }
  EXPECT_TRUE(has(x_io, W{0x1A01, 1, 0x60FD0020u}));
  EXPECT_TRUE(has(x_io, W{0x1A01, 0, 1}));
  EXPECT_TRUE(has(x_io, W{0x1801, 1, 0x281}));
  EXPECT_TRUE(has(x_io, W{0x1601, 1, 0x60FE0120u}));
  EXPECT_TRUE(has(x_io, W{0x1601, 0, 1}));
  EXPECT_TRUE(has(x_io, W{0x1401, 1, 0x301}));
  EXPECT_TRUE(has(x_io, W{0x60FE, 2, (1u << 16) | (1u << 18)}));
  EXPECT_TRUE(has(x_io, W{0x1802, 1, 0x80000000u | 0x381}));  // TPDO3 still off
}

TEST(DriveIoLoopback, InputsComeInTpdo2AndOutputsGoOutInRpdo2) {
  Scratch s;
  Bench b(s.load(std::string(kMachine) + kPlc));
  b.start();
  daemon::AxisCommands cmd;
  cmd.digital_outputs[0] = (1u << 16) | (1u << 17);  // 17 is not in the mask: never sent
  cmd.digital_output_mask[0] = (1u << 16) | (1u << 18);
  daemon::BusFeedback fb = b.cycle(cmd);
  fb = b.cycle(cmd);
  ASSERT_TRUE(fb.axis[0].fresh);
  EXPECT_TRUE(fb.axis[0].digital_inputs_present);
  EXPECT_TRUE(fb.axis[0].digital_inputs_fresh);
  EXPECT_EQ(fb.axis[0].digital_inputs, 1u << 16);   // at 0 mm: only the cam below it
  EXPECT_FALSE(fb.axis[1].digital_inputs_present);  // Y maps no 0x60FD
  EXPECT_FALSE(fb.axis[1].digital_inputs_fresh);
  EXPECT_EQ(b.can.drives[0]->digital_outputs(), 1u << 16);
  EXPECT_EQ(b.can.drives[1]->digital_outputs(), 0u);

  // Enable and move X at 20 mm/s: the cam at +1 mm switches bit 17 on.
  cmd.mode = daemon::DriveMode::kEnabled;
  int k = 0;
  for (; k < 40 && !fb.axis[0].enabled; ++k) fb = b.cycle(cmd);
  ASSERT_TRUE(fb.axis[0].enabled);
  cmd.velocity_mm_s[0] = 20.0;
  bool seen = false;
  for (k = 0; k < 200 && !seen; ++k) {
    fb = b.cycle(cmd);
    ASSERT_TRUE(fb.axis[0].digital_inputs_fresh) << k;
    if ((fb.axis[0].digital_inputs & (1u << 17)) != 0) {
      seen = true;
      EXPECT_GT(fb.axis[0].position_mm, 0.95);  // the cam, seen through the TPDO's delay
      EXPECT_LT(fb.axis[0].position_mm, 1.1);
    } else {
      EXPECT_LT(fb.axis[0].position_mm, 1.0);
    }
  }
  EXPECT_TRUE(seen);

  // A new output value reaches the drive one SYNC later; 0x60FE:01 reads back over SDO.
  cmd.velocity_mm_s[0] = 0.0;
  cmd.digital_outputs[0] = 1u << 18;
  b.cycle(cmd);
  b.cycle(cmd);
  EXPECT_EQ(b.can.drives[0]->digital_outputs(), 1u << 18);
  const auto v = b.bus->master()->sdo_upload(1, 0x60FE, 1);
  ASSERT_EQ(v.size(), 4u);
  EXPECT_EQ(co::get_u32(v.data()), 1u << 18);
  const auto m = b.bus->master()->sdo_upload(1, 0x60FE, 2);
  EXPECT_EQ(co::get_u32(m.data()), (1u << 16) | (1u << 18));

  // Dropped TPDOs: neither the position nor the inputs are fresh; the last value is kept.
  b.can.drives[0]->drop_tpdos(2);
  fb = b.cycle(cmd);
  EXPECT_FALSE(fb.axis[0].fresh);
  EXPECT_FALSE(fb.axis[0].digital_inputs_fresh);
  EXPECT_TRUE(fb.axis[0].digital_inputs_present);
  EXPECT_EQ(fb.axis[0].digital_inputs, (1u << 16) | (1u << 17));
  fb = b.cycle(cmd);
  EXPECT_FALSE(fb.axis[0].digital_inputs_fresh);
  fb = b.cycle(cmd);
  EXPECT_TRUE(fb.axis[0].digital_inputs_fresh);
  b.bus->stop();
  EXPECT_EQ(b.can.drives[0]->digital_outputs(), 0u);  // off with the drives
}

TEST(DriveIoLoopback, DriveWithout60FDStopsTheStartUpNamingNodeAndObject) {
  Scratch s;
  Bench b(s.load(std::string(kMachine) + kPlc));
  b.can.drives.clear();
  auto x = drive(1, "X");
  x.quirks.missing.push_back({0x60FD, -1});
  b.can.add(x);
  b.can.add(drive(2, "Y"));
  try {
    b.start();
    FAIL() << "started without 0x60FD";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("node 1 (X)"), std::string::npos) << what;
    EXPECT_NE(what.find("0x60FD:00 digital inputs"), std::string::npos) << what;
    EXPECT_NE(what.find("0x06020000"), std::string::npos) << what;
  }
  // Without the binding the same drive starts (0x60FD is not needed then).
  Bench plain(s.load(kMachine));
  plain.can.drives.clear();
  plain.can.add(x);
  plain.can.add(drive(2, "Y"));
  EXPECT_NO_THROW(plain.start());
}

TEST(DriveIoLoopback, OnePdoDriveIsRefusedNamingNodeAndPdo) {
  Scratch s;
  Bench b(s.load(std::string(kMachine) + "  nodes: [{node_id: 1, profile: one-pdo}]\n" + kPlc));
  try {
    b.start();
    FAIL() << "a one-PDO drive took the digital inputs";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("node 1 (X)"), std::string::npos) << what;
    EXPECT_NE(what.find("0x60FD"), std::string::npos) << what;
    EXPECT_NE(what.find("TPDO2"), std::string::npos) << what;
    EXPECT_NE(what.find("one-pdo"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace contour
