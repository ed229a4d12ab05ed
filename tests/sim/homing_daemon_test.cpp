// Homing through the daemon (issue 18): config/sim.yaml's switch homing with homing required
// (machine.allow_unhomed: false) and the simulated axes powered up away from zero. Before homing,
// `run` and `mdi` are refused naming the axes; `contourctl home --all` prints the phases, exits 0,
// and status.homed maps every axis to true; afterwards the machine coordinates are the true ones
// and a program runs. A search that cannot find its switch fails with a clear reason (exit 1).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>

#include "tests/support/daemon_process.hpp"
#include "tests/support/run_cmd.hpp"
#include "tests/support/sim_config.hpp"

namespace {

using nlohmann::json;
const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";

// config/sim.yaml with homing required, power-up positions 19.5 / 15 / 9.5 mm above the home
// switches (closed below -199.5 / -199.5 / -99.5 true), and home positions near the switches
// (short moves: the test runs in real time). `search_mm`: home.search_distance_mm of X.
std::string homing_config(const std::string& tag, double x_search_mm = 0.0) {
  std::string y = contour::test::sim_yaml();
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
  sub("        home_position_mm: 0\n", "        home_position_mm: -190\n" +
      (x_search_mm > 0.0 ? "        search_distance_mm: " + std::to_string(x_search_mm) + "\n" : std::string()));
  sub("        home_position_mm: 0\n", "        home_position_mm: -190\n");
  sub("        home_position_mm: 0\n", "        home_position_mm: -95\n");
  const auto path = std::filesystem::temp_directory_path() /
                    ("contour_homing_" + tag + "_" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(path) << y;
  return path.string();
}

TEST(HomingDaemon, ProgramsWaitForHomingThenRunInMachineCoordinates) {
  const std::string cfg = homing_config("ok");
  contour::test::DaemonProcess d("homing", {cfg, {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  json st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["homed"], json({{"X", false}, {"Y", false}, {"Z", false}}));
  EXPECT_TRUE(st["homing"]["required"].get<bool>());

  const json run = d.call({{"cmd", "run"}, {"program", "G1 X1 F600\nM2\n"}});
  EXPECT_FALSE(run.value("ok", true));
  EXPECT_NE(run.value("error", std::string()).find("not homed: X, Y, Z"), std::string::npos) << run.dump();
  EXPECT_EQ(d.ok({{"cmd", "status"}})["loaded_job"], 0) << "a refused run must not leave a program loaded";
  const json mdi = d.call({{"cmd", "mdi"}, {"text", "G0 X1"}});
  EXPECT_NE(mdi.value("error", std::string()).find("not homed"), std::string::npos) << mdi.dump();
  // Unhomed jog: beyond the soft limit (its coordinates mean nothing yet), at the slow speed.
  const json jog = d.ok({{"cmd", "jog"}, {"axis", "Y"}, {"velocity_mm_min", 3000}, {"distance_mm", -250.0}});
  EXPECT_TRUE(jog["not_homed"].get<bool>()) << jog.dump();
  EXPECT_DOUBLE_EQ(jog["velocity_mm_min"].get<double>(), 600.0);
  d.wait_status([](const json& s) { return s["jogging"].get<bool>(); }, 300);
  d.ok({{"cmd", "stop"}});
  d.wait_status([](const json& s) { return !s["jogging"].get<bool>(); }, 300);
  const json bad = d.call({{"cmd", "home"}, {"axis", "X"}, {"position_mm", 0.0}});
  EXPECT_FALSE(bad.value("ok", true)) << "home no longer takes set-position's arguments";

  std::string out;
  const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home --all", &out);
  ASSERT_EQ(rc, 0) << out << d.log();
  EXPECT_NE(out.find("Z search"), std::string::npos) << out;
  EXPECT_NE(out.find("X done, Y done, Z done"), std::string::npos) << out;
  EXPECT_NE(out.find("homed [\"X\",\"Y\",\"Z\"]"), std::string::npos) << out;
  st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["homed"], json({{"X", true}, {"Y", true}, {"Z", true}})) << st.dump();
  EXPECT_EQ(st["homing"]["runs"], 1);
  EXPECT_TRUE(st["homing"]["failure"].is_null());
  // machine = encoder + shift; the encoders read 0 at power-up, so the shift is the power-up
  // position to the latch resolution: the release edge falls anywhere within one cycle's travel
  // at the 60 mm/min latch speed (1 um, more while the axis still settles onto the latch speed
  // after the back-off starts), plus the 0.5 um encoder's rounding. Y's
  // starting point depends on when the jog above was stopped (real time), so its phase at the
  // edge varies from run to run: -184.5005 .. -184.502 seen; 3 um bounds it.
  constexpr double kLatchTol_mm = 0.003;
  EXPECT_NEAR(st["homing"]["machine_minus_encoder_mm"]["X"].get<double>(), -180.0, kLatchTol_mm);
  EXPECT_NEAR(st["homing"]["machine_minus_encoder_mm"]["Y"].get<double>(), -184.5, kLatchTol_mm);
  EXPECT_NEAR(st["homing"]["machine_minus_encoder_mm"]["Z"].get<double>(), -90.0, kLatchTol_mm);
  EXPECT_NEAR(st["ref_mm"][0].get<double>(), -190.0, 1e-9);
  EXPECT_NE(d.log().find("axis 2 homed: latch at"), std::string::npos) << d.log();

  // Homed: soft limits hold in machine coordinates, and a program runs.
  const json far = d.call({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 600}, {"distance_mm", -20.0}});
  EXPECT_NE(far.value("error", std::string()).find("outside the soft limits"), std::string::npos) << far.dump();
  const auto prog = std::filesystem::path(cfg).replace_extension(".ngc");
  std::ofstream(prog) << "G1 X-189 F600\nM2\n";
  const int rc_run = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " run --wait " + prog.string(), &out);
  EXPECT_EQ(rc_run, 0) << out << d.log();
  std::filesystem::remove(prog);
  std::filesystem::remove(cfg);
}

TEST(HomingDaemon, ASwitchOutOfReachFailsWithItsReason) {
  // X may search 5 mm only; its switch is 19.5 mm away.
  const std::string cfg = homing_config("far", 5.0);
  contour::test::DaemonProcess d("homing_far", {cfg, {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  std::string out;
  const int rc = contour::test::run_cmd(kCtl + " --socket " + d.sock() + " home X", &out);
  EXPECT_EQ(rc, 1) << out;
  EXPECT_NE(out.find("homing failed: X: the home switch did not close within search_distance_mm"),
            std::string::npos) << out;
  const json st = d.ok({{"cmd", "status"}});
  EXPECT_FALSE(st["homed"]["X"].get<bool>());
  EXPECT_EQ(st["state"], "READY");
  EXPECT_NE(d.log().find("HOMING FAILED axis 0"), std::string::npos) << d.log();
  std::filesystem::remove(cfg);
}

}  // namespace
