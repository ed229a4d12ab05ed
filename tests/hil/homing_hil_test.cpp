// HIL: homing by switch and absolute homing over CAN (issue 18) - the real contourd on
// config/hil.yaml with X homed, contour-machine-sim over vcan0 in lockstep. (Homing by the drive,
// CiA 402 mode 6, is tests/hil/drive_homing_hil_test.cpp.)
//  - home.method switch: the home switch is the drive's 0x60FD bit 2, which the master maps into
//    TPDO2 for an axis homed on a switch (no PLC binding needed). contour-machine-sim's switch
//    closes below min_mm + 0.5 mm of the plant; X searches down at 20 mm/s, latches the release
//    edge moving up at 1 mm/s, and moves to home_position_mm. The machine position afterwards
//    equals the simulated plant's true position (its summary at exit) within 3 um: one SYNC at
//    the latch speed (1 um) plus the half-count encoder.
//  - home.method absolute: homed from the start, machine = encoder + home_offset_mm, no motion;
//    `home X` says so and changes nothing.
// No wall-clock assertions: the drives step once per SYNC and the master waits for every TPDO.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/hil/canopen_hil_support.hpp"
#include "tests/hil/homing_hil_support.hpp"
#include "tests/support/daemon_process.hpp"
#include "tests/support/run_cmd.hpp"

namespace {

using nlohmann::json;
const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";

// config/hil.yaml with X's home: section `home` (homing_hil_support.hpp). A switch-homed axis adds
// its TPDO2 (0x60FD) every cycle: 86 % worst case on hil.yaml's bus, over its 80 % ceiling.
std::string hil_homing_config(const std::string& tag, const std::string& home) {
  return contour::test::hil_homing_config(tag, home, 90);
}


using contour::test::wait_x_at_rest;

}  // namespace

TEST(HomingHil, SwitchOverVcanLatchesTheReleaseEdgeOnTheTruePosition) {
  const std::string cfg = hil_homing_config(
      "switch", "{method: switch, search_vel_mm_min: -1200, latch_vel_mm_min: 60, home_offset_mm: -19.5, "
                "home_position_mm: -10}");
  contour::test::MachineSim sim({}, cfg);
  ASSERT_TRUE(sim.ready()) << sim.stop();
  double act_x = 0.0;
  {
    contour::test::DaemonProcess d("hil_switch_homing", {cfg, {}, 6000, 3000});
    ASSERT_EQ(d.state(), "READY") << d.log() << sim.poll_output();
    json st = d.ok({{"cmd", "status"}});
    EXPECT_FALSE(st["homed"]["X"].get<bool>()) << st.dump();
    std::string out;
    const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home X", &out);
    ASSERT_EQ(rc, 0) << out << d.log() << sim.poll_output();
    st = d.ok({{"cmd", "status"}});
    EXPECT_TRUE(st["homed"]["X"].get<bool>()) << st.dump();
    EXPECT_FALSE(st["homed"]["Y"].get<bool>()) << st.dump();
    EXPECT_TRUE(st["homing"]["failure"].is_null()) << st.dump();
    EXPECT_EQ(st["state"], "READY") << st.dump();
    EXPECT_NEAR(st["ref_mm"][0].get<double>(), -10.0, 1e-9);
    st = wait_x_at_rest(d, -10.0);
    act_x = st["act_mm"][0].get<double>();
    EXPECT_EQ(d.log().find("FAULT"), std::string::npos) << d.log();
    EXPECT_NE(d.log().find("axis 0 homed"), std::string::npos) << d.log();
  }  // the daemon disables the drives and exits; the plant stays where it is
  const std::string out = sim.stop();
  const double true_x = contour::test::sim_summary_position_mm(out, 1);
  std::printf("[figure] switch homing over vcan: machine X %.6f mm, plant X %.6f mm: %.3f um apart\n", act_x,
              true_x, (act_x - true_x) * 1e3);
  EXPECT_NEAR(act_x, true_x, 0.003) << out;
  std::filesystem::remove(cfg);
}

TEST(HomingHil, AbsoluteOverVcanIsHomedFromTheStartAtTheEncoderPlusTheOffset) {
  const std::string cfg = hil_homing_config("absolute", "{method: absolute, home_offset_mm: 5}");
  contour::test::MachineSim sim({}, cfg);
  ASSERT_TRUE(sim.ready()) << sim.stop();
  {
    contour::test::DaemonProcess d("hil_absolute_homing", {cfg, {}, 6000, 3000});
    ASSERT_EQ(d.state(), "READY") << d.log() << sim.poll_output();
    // Homed at start-up: the encoder (the plant powers up at 0) plus home_offset_mm, no motion.
    const json st = d.ok({{"cmd", "status"}});
    EXPECT_TRUE(st["homed"]["X"].get<bool>()) << st.dump();
    EXPECT_FALSE(st["homed"]["Y"].get<bool>()) << st.dump();
    EXPECT_NEAR(st["act_mm"][0].get<double>(), 5.0, 0.001) << st.dump();
    // `home X` has nothing to do and says why (exit 1), the machine stays READY.
    std::string out;
    const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home X", &out);
    EXPECT_EQ(rc, 1) << out;
    EXPECT_NE(out.find("X has an absolute encoder (home.method absolute): it is homed from the start"),
              std::string::npos)
        << out;
    EXPECT_EQ(d.state(), "READY");
    EXPECT_EQ(d.log().find("FAULT"), std::string::npos) << d.log();
  }
  const std::string out = sim.stop();
  EXPECT_NEAR(contour::test::sim_summary_position_mm(out, 1), 0.0, 0.001) << out;  // never moved
  std::filesystem::remove(cfg);
}
