// HIL: CiA 402 drive digital I/O over vcan0 (issue 20). contour-machine-sim's X drive has a cam
// on 0x60FD bit 16 (--input-switch 1:16:above:-1) and its default limit/home switches; the
// daemon's CanopenBus maps 0x60FD into X's TPDO2 and 0x60FE:01 into its RPDO2 because the
// config's PLC binds them. The input arrives fresh every cycle; the output reaches the drive's
// object dictionary, read back over SDO from the simulator; a drive the simulator starts without
// 0x60FD (--missing-object 1:0x60FD) stops the start-up naming the node and the object.
#include <filesystem>
#include <fstream>
#include <string>

#include "daemon/canopen_bus.hpp"
#include "drivers/canopen/codec.hpp"
#include "tests/hil/canopen_hil_support.hpp"

namespace {

namespace fs = std::filesystem;
using contour::daemon::AxisCommands;
using contour::daemon::BusFeedback;
using contour::daemon::CanopenBus;

// Two axes, no spindle: the bus load stays under the ceiling with TPDO2 and RPDO2 on X.
// master_heartbeat_ms 0: the cycles below run faster than real time (lockstep).
constexpr const char* kConfig = R"(loop: {period_us: 1000, tpdo_deadline_us: 800}
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
  drives: {mode: csv, heartbeat_ms: 50, heartbeat_timeout_ms: 200, rpdo: ["0x6040", "0x60FF"], tpdo: ["0x6041", "0x6064"]}
plc:
  programs: [{file: io.st}]
  signals:
    - {name: x_cam, cia402: {axis: X, input: 16}}
    - {name: x_lamp, cia402: {axis: X, output: 17}}
)";

struct Files {
  Files() {
    dir = fs::temp_directory_path() / ("drive_io_hil_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    std::ofstream(dir / "io.st") << "PROGRAM io\n  x_lamp := x_cam;\nEND_PROGRAM\n";
    std::ofstream(dir / "c.yaml") << kConfig;
  }
  ~Files() { fs::remove_all(dir); }
  [[nodiscard]] std::string config() const { return (dir / "c.yaml").string(); }
  fs::path dir;
};

// One test (the HIL budget): the mapped I/O, a TPDO2-only gap, then the start-up error with a
// third simulator.
TEST(DriveIoHil, CamInTpdo2OutputInRpdo2AndMissing60FDOverVcan) {
  Files f;
  const auto cfg = contour::config::load_config_file(f.config());
  {
    contour::test::MachineSim sim({"--input-switch", "1:16:above:-1"}, f.config());
    ASSERT_TRUE(sim.ready()) << sim.poll_output();
    CanopenBus bus(cfg, {});
    bus.set_event_thread(false);
    bus.start();
    AxisCommands cmd;
    cmd.digital_outputs[0] = 1u << 17;
    cmd.digital_output_mask[0] = 1u << 17;
    BusFeedback fb;
    int fresh = 0;
    for (int k = 0; k < 50; ++k) {
      bus.begin_cycle();
      bus.read(fb);
      bus.write(cmd);
      if (fb.axis[0].digital_inputs_fresh) {
        ++fresh;
        EXPECT_EQ(fb.axis[0].digital_inputs, 1u << 16) << k;  // the cam; no limit/home switch at 0
      }
    }
    EXPECT_EQ(fresh, 50);
    EXPECT_TRUE(fb.axis[0].digital_inputs_present);
    EXPECT_FALSE(fb.axis[1].digital_inputs_present);
    const auto out = bus.master()->sdo_upload(1, 0x60FE, 1);
    ASSERT_EQ(out.size(), 4u);
    EXPECT_EQ(contour::drivers::canopen::get_u32(out.data()), 1u << 17);
    const auto mask = bus.master()->sdo_upload(1, 0x60FE, 2);
    EXPECT_EQ(contour::drivers::canopen::get_u32(mask.data()), 1u << 17);
    const auto y = bus.master()->sdo_upload(2, 0x60FE, 1);
    EXPECT_EQ(contour::drivers::canopen::get_u32(y.data()), 0u);  // Y maps no outputs
    bus.stop();
  }
  {
    // A drive whose TPDO2 stops for 10 SYNCs while TPDO1 goes on: the position stays fresh, the
    // inputs are reported not fresh for exactly those cycles (the loop's missed-TPDO rule then
    // faults the machine: PlcDriveIo.LostDigitalInputsAlone... in the unit tests).
    contour::test::MachineSim sim({"--input-switch", "1:16:above:-1", "--drop-tpdo2", "1:20:10"},
                                  f.config());
    ASSERT_TRUE(sim.ready()) << sim.poll_output();
    CanopenBus bus(cfg, {});
    bus.set_event_thread(false);
    bus.start();
    AxisCommands cmd;
    BusFeedback fb;
    int position = 0, inputs = 0, gap_first = -1, gap_last = -1;
    for (int k = 0; k < 60; ++k) {
      bus.begin_cycle();
      bus.read(fb);
      bus.write(cmd);
      if (fb.axis[0].fresh) ++position;
      if (fb.axis[0].digital_inputs_fresh) {
        ++inputs;
      } else {
        if (gap_first < 0) gap_first = k;
        gap_last = k;
      }
    }
    EXPECT_EQ(position, 60);
    EXPECT_EQ(inputs, 50);
    EXPECT_EQ(gap_last - gap_first, 9) << gap_first << ".." << gap_last;  // one gap of 10
    EXPECT_EQ(fb.axis[0].digital_inputs, 1u << 16);  // back, the cam's value
    bus.stop();
  }
  contour::test::MachineSim sim({"--missing-object", "1:0x60FD"}, f.config());
  ASSERT_TRUE(sim.ready()) << sim.poll_output();
  CanopenBus bus(cfg, {});
  bus.set_event_thread(false);
  try {
    bus.start();
    FAIL() << "started without 0x60FD";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("node 1 (X)"), std::string::npos) << what;
    EXPECT_NE(what.find("0x60FD:00 digital inputs"), std::string::npos) << what;
  }
}

}  // namespace
