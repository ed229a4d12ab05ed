// HIL: homing by the drive (issue 18, home.method drive = CiA 402 homing mode 6) - the real
// contourd on config/hil.yaml with X homed by its drive, contour-machine-sim over vcan0 in
// lockstep. The master's non-blocking SDO client writes 0x6098/0x6099/0x609A and 0x6060 = 6 from
// the RT cycle, starts the homing with controlword bit 4, watches statusword bits 12/10/13 and
// switches back to CSV; the loop then moves X to home_position_mm.
//  - The homing succeeds and lands correctly: X homed, no fault, the machine position equal to
//    the simulated drive's true plant position (its summary at exit) within 2 um, and standing
//    still afterwards (no oscillation: the spread of 50 status samples under 2 um).
//  - A drive without homing support (contour-machine-sim --missing-object 1:0x6098): homing fails
//    at once with the error naming node 1 and object 0x6098:00; no fault, the axis never moved.
// No wall-clock assertions: the drives step once per SYNC and the master waits for every TPDO.
#include <gtest/gtest.h>

#include <algorithm>
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

// config/hil.yaml with X homed by its drive: method 21 (the simulated drive's home switch closes
// below min_mm + 0.5 = -19.5 mm true, X's min_mm is -20 here so that the plant, starting at 0,
// reaches it in 1 s at 20 mm/s; home where it opens moving up at 1 mm/s); home_offset_mm -19.5
// names the switch point, so machine coordinates are the true ones.
std::string hil_drive_homing_config(const std::string& tag) {
  return contour::test::hil_homing_config(
      "drive_" + tag,
      "{method: drive, drive_method: 21, search_vel_mm_min: 1200, latch_vel_mm_min: 60,\n"
      "              accel_mm_s2: 1000, home_offset_mm: -19.5, home_position_mm: -10}");
}


}  // namespace

TEST(DriveHomingHil, ModeSixOverVcanLandsOnTheTruePositionWithoutFault) {
  const std::string cfg = hil_drive_homing_config("ok");
  contour::test::MachineSim sim({}, cfg);
  ASSERT_TRUE(sim.ready()) << sim.stop();
  double act_x = 0.0;
  {
    contour::test::DaemonProcess d("hil_drive_homing", {cfg, {}, 6000, 3000});
    ASSERT_EQ(d.state(), "READY") << d.log();
    std::string out;
    const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home X", &out);
    ASSERT_EQ(rc, 0) << out << d.log() << sim.poll_output();
    EXPECT_NE(out.find("X drive"), std::string::npos) << out;
    json st = d.ok({{"cmd", "status"}});
    EXPECT_TRUE(st["homed"]["X"].get<bool>()) << st.dump();
    EXPECT_TRUE(st["homing"]["failure"].is_null()) << st.dump();
    EXPECT_EQ(st["state"], "READY") << st.dump();
    EXPECT_DOUBLE_EQ(st["homing"]["machine_minus_encoder_mm"]["X"].get<double>(), -19.5);
    EXPECT_NEAR(st["ref_mm"][0].get<double>(), -10.0, 1e-9);
    // The final move is a trapezoid (not jerk-limited, as LinuxCNC's): X rings about 25 um past
    // -10 mm and settles within ~0.3 s. Being within 2 um once can be mid-swing (seen), so wait
    // for rest: two samples at least 300 cycles apart, 1 um from each other and 2 um from -10.
    bool settled = false;
    for (int k = 0; k < 60 && !settled; ++k) {
      const json s1 = d.ok({{"cmd", "status"}});
      const auto c1 = s1["cycle"].get<std::uint64_t>();
      const json s2 = d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() >= c1 + 300; });
      const double x1 = s1["act_mm"][0].get<double>(), x2 = s2["act_mm"][0].get<double>();
      settled = std::abs(x2 - x1) < 0.001 && std::abs(x2 + 10.0) < 0.002;
    }
    ASSERT_TRUE(settled) << "X never came to rest at -10 mm\n" << d.log();
    // Standing still at home_position_mm: no oscillation after the mode switch back to CSV.
    double lo = 1e9, hi = -1e9;
    for (int k = 0; k < 50; ++k) {
      st = d.ok({{"cmd", "status"}});
      const double x = st["act_mm"][0].get<double>();
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    std::printf("[figure] X after homing by the drive over vcan: %.6f .. %.6f mm (spread %.3f um)\n", lo, hi,
                (hi - lo) * 1e3);
    EXPECT_LT(hi - lo, 0.002);
    act_x = st["act_mm"][0].get<double>();
    EXPECT_EQ(st["state"], "READY") << st.dump();
    EXPECT_EQ(d.log().find("FAULT"), std::string::npos) << d.log();
    EXPECT_NE(d.log().find("axis 0 homed"), std::string::npos) << d.log();
  }  // the daemon disables the drives and exits; the plant stays where it is
  const std::string out = sim.stop();
  const double true_x = contour::test::sim_summary_position_mm(out, 1);
  std::printf("[figure] machine X %.6f mm, plant X %.6f mm: %.3f um apart\n", act_x, true_x,
              (act_x - true_x) * 1e3);
  // The drive samples its switch each SYNC at 1 mm/s (1 um), the encoder count is 0.5 um.
  EXPECT_NEAR(act_x, true_x, 0.002) << out;
  std::filesystem::remove(cfg);
}

TEST(DriveHomingHil, ADriveWithoutHomingFailsAtOnceNamingNodeAndObject) {
  const std::string cfg = hil_drive_homing_config("nohoming");
  contour::test::MachineSim sim({"--missing-object", "1:0x6098"}, cfg);
  ASSERT_TRUE(sim.ready()) << sim.stop();
  {
    contour::test::DaemonProcess d("hil_drive_homing_none", {cfg, {}, 6000, 3000});
    ASSERT_EQ(d.state(), "READY") << d.log();
    std::string out;
    const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home X", &out);
    EXPECT_EQ(rc, 1) << out;
    EXPECT_NE(out.find("homing failed: X: the drive refused a homing object (SDO abort)"), std::string::npos)
        << out;
    EXPECT_NE(out.find("(node 1, object 0x6098:00)"), std::string::npos) << out;
    const json st = d.ok({{"cmd", "status"}});
    EXPECT_FALSE(st["homed"]["X"].get<bool>());
    EXPECT_EQ(st["state"], "READY") << st.dump();
    EXPECT_EQ(d.log().find("FAULT"), std::string::npos) << d.log();
    EXPECT_NE(d.log().find("HOMING FAILED axis 0"), std::string::npos) << d.log();
  }
  const std::string out = sim.stop();
  EXPECT_NEAR(contour::test::sim_summary_position_mm(out, 1), 0.0, 0.001) << out;  // never moved
  std::filesystem::remove(cfg);
}
