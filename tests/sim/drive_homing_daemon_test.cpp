// Homing by the drive through the daemon (issue 18, home.method drive = CiA 402 homing mode 6):
// config/sim.yaml with homing required, X homed by its simulated drive (method 21: the negative
// home switch, home where it opens moving up), Y and Z by the switch method, all powered up away
// from zero. `contourctl home --all` exits 0 and shows X's `drive` phase; status.homed maps every
// axis to true and the machine position of every axis equals the plant's true position
// (status.sim_true_mm) within 2 um: the drive samples its switch every 1 ms period at the latch
// speed of 1 mm/s (1 um) and the encoder's BLU is 0.5 um. A drive without homing support cannot be
// configured on the in-process machine through YAML; that failure is the HIL test's
// (tests/hil/drive_homing_hil_test.cpp) and the unit test's (tests/unit/daemon/drive_homing_test.cpp).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/run_cmd.hpp"

namespace {

using nlohmann::json;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";

// config/sim.yaml, homing required, power-up 19.5 / 15 / 9.5 mm above the home switches, X homed
// by its drive with `x_home` (the keys after `method: drive`).
std::string drive_homing_config(const std::string& tag, const std::string& x_home) {
  std::string y = contour::test::sim_yaml(contour::test::SimPlc::kNone);
  auto sub = [&y](const std::string& from, const std::string& to) {
    const auto at = y.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) y.replace(at, from.size(), to);
  };
  sub("  allow_unhomed: true", "  allow_unhomed: false");
  const std::string sim_xy = "sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1}";
  sub(sim_xy, "sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1, power_up_mm: -180}");
  sub(sim_xy, "sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1, power_up_mm: -184.5}");
  sub("sim: {gain_per_s: 115, tau_ms: 25, blu_um: 0.5, delay_cycles: 1}",
      "sim: {gain_per_s: 115, tau_ms: 25, blu_um: 0.5, delay_cycles: 1, power_up_mm: -90}");
  // X (the first home: section): by its drive; its speeds become 0x6099:01/02 magnitudes.
  sub("        method: switch\n", "        method: drive\n" + x_home);
  sub("        home_position_mm: 0\n", "        home_position_mm: -190\n");
  sub("        home_position_mm: 0\n", "        home_position_mm: -190\n");
  sub("        home_position_mm: 0\n", "        home_position_mm: -95\n");
  const auto path = std::filesystem::temp_directory_path() /
                    ("contour_drive_homing_" + tag + "_" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(path) << y;
  return path.string();
}

TEST(DriveHomingDaemon, HomeAllWithOneAxisHomedByItsDriveLandsOnTheTruePositions) {
  const std::string cfg = drive_homing_config("ok", "        drive_method: 21\n        accel_mm_s2: 500\n");
  contour::test::DaemonProcess d("drive_homing", {cfg, {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  json st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["homed"], json({{"X", false}, {"Y", false}, {"Z", false}}));
  ASSERT_TRUE(st.contains("sim_true_mm")) << st.dump();
  EXPECT_NEAR(st["sim_true_mm"][0].get<double>(), -180.0, 1e-9);

  std::string out;
  const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home --all", &out);
  ASSERT_EQ(rc, 0) << out << d.log();
  EXPECT_NE(out.find("X drive"), std::string::npos) << out;
  EXPECT_NE(out.find("X done, Y done, Z done"), std::string::npos) << out;
  st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["homed"], json({{"X", true}, {"Y", true}, {"Z", true}})) << st.dump();
  EXPECT_TRUE(st["homing"]["failure"].is_null()) << st.dump();
  EXPECT_EQ(st["state"], "READY");
  // The drive reads 0 at its home point, which becomes home_offset_mm: machine = drive + offset.
  EXPECT_DOUBLE_EQ(st["homing"]["machine_minus_encoder_mm"]["X"].get<double>(), -199.5);
  EXPECT_NEAR(st["ref_mm"][0].get<double>(), -190.0, 1e-9);
  // Standing at home_position_mm: each machine position is the plant's true one.
  d.wait_status([](const json& s) { return std::abs(s["act_mm"][0].get<double>() + 190.0) < 0.002; }, 2000);
  st = d.ok({{"cmd", "status"}});
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(st["act_mm"][i].get<double>(), st["sim_true_mm"][i].get<double>(), 0.002)
        << "axis " << i << ": " << st.dump();
  }
  EXPECT_NE(d.log().find("axis 0 homed"), std::string::npos) << d.log();
  EXPECT_EQ(d.log().find("FAULT"), std::string::npos) << d.log();
  std::filesystem::remove(cfg);
}

TEST(DriveHomingDaemon, ADriveThatRunsIntoItsLimitFailsWithTheDrivesHomingError) {
  // Method 19 looks for a home switch on the positive side: the simulated drive has none there,
  // runs into its positive limit switch (1 mm above max_mm... 2 mm: 202 true) and reports a homing
  // error. X powers up at -180: 382 mm at 20 mm/s is 19 s; a short machine makes it quick.
  std::string cfg = drive_homing_config("limit", "        drive_method: 19\n        accel_mm_s2: 500\n");
  {
    std::string y = contour::test::slurp(cfg);
    const auto at = y.find("      max_mm: 200\n");
    ASSERT_NE(at, std::string::npos);
    y.replace(at, 18, "      max_mm: -170\n");
    std::ofstream(cfg) << y;
  }
  contour::test::DaemonProcess d("drive_homing_limit", {cfg, {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  std::string out;
  const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home X", &out);
  EXPECT_EQ(rc, 1) << out;
  EXPECT_NE(out.find("homing failed: X: the drive reported a homing error (CiA 402 statusword bit 13)"),
            std::string::npos) << out;
  const json st = d.ok({{"cmd", "status"}});
  EXPECT_FALSE(st["homed"]["X"].get<bool>());
  EXPECT_EQ(st["state"], "READY") << st.dump();
  EXPECT_GT(st["sim_true_mm"][0].get<double>(), -168.0);  // it went up to the limit switch
  EXPECT_NE(d.log().find("HOMING FAILED axis 0"), std::string::npos) << d.log();
  std::filesystem::remove(cfg);
}

}  // namespace
