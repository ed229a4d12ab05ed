// Issue 18 "Done when": a CAM-style program with `T2 M6`, `G43 H2`, `G54`, `G28 G91 Z0`, spindle
// and coolant words runs end to end through the daemon (sim machine) with a tool-change pause and
// resume, and lands where LinuxCNC would: the daemon's final machine position is compared with
// LinuxCNC 2.9's interpreter on the same program, .var (G54 and G28 positions) and tool table
// (tools/gcode-conformance, `contour-gcode-diff --final`: the end of LinuxCNC's last move with its
// G5x, G92 and tool offsets applied). Without LinuxCNC's interpreter (package linuxcnc-uspace,
// tools/deps.d/linuxcnc.list) the test is skipped and says why.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/run_cmd.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kDiff = std::string(CONTOUR_BINARY_DIR) + "/tools/gcode-conformance/contour-gcode-diff";

// As a Fusion 360 / Vectric post writes it: safe start line, retract with G28 G91 Z0, tool
// change, spindle and coolant on, G54, tool length offset on the first Z move, a pocket outline
// with arcs, retract, everything off, G28 G91 Z0 again, M30.
const char* kProgram = R"(%
(contourd end-to-end: a CAM-style program)
G90 G94 G17
G21
G28 G91 Z0
G90
T2 M6
S6000 M3
G54
M8
G0 X0 Y0
G43 Z15 H2
G0 Z5
G1 Z-1 F1000
G1 X20 F3000
G3 X30 Y10 I0 J10
G1 Y20
G2 X20 Y30 I-10 J0
G1 X0
G1 Y0
G0 Z15
M9
M5
G28 G91 Z0
G90
M30
%
)";

// G54 = (12.5, -7.25, -30) active; G28 position (-50, 60, 40); G30 (0, 0, 50).
const char* kVar =
    "5161\t-50.000000\n5162\t60.000000\n5163\t40.000000\n5181\t0.000000\n5182\t0.000000\n"
    "5183\t50.000000\n5220\t1.000000\n5221\t12.500000\n5222\t-7.250000\n5223\t-30.000000\n";

}  // namespace

TEST(CamEndToEnd, ToolChangePauseResumeAndTheFinalMachinePositionIsLinuxCncs) {
  const fs::path dir = fs::temp_directory_path() / ("contour_cam_e2e_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream(dir / "machine.var") << kVar;
  std::ofstream(dir / "cam.ngc") << kProgram;
  // LinuxCNC's side first (skip without it).
  ASSERT_TRUE(fs::exists(kDiff)) << kDiff << " not built (target contour-gcode-diff)";
  std::string out;
  const int rc = contour::test::run_cmd(kDiff + " --final --var " + (dir / "machine.var").string() +
                                            " --tbl " + kSrc + "/config/sim.tbl " + (dir / "cam.ngc").string(),
                                        &out);
  if (rc == 77) GTEST_SKIP() << "LinuxCNC's interpreter is not installed: " << out;
  // contourd's interpreter emits the same moves as LinuxCNC's (machine coordinates, 1e-6 mm).
  ASSERT_EQ(rc, 0) << out;
  double lx = 0, ly = 0, lz = 0;
  {
    const auto at = out.find("FINAL ");
    ASSERT_NE(at, std::string::npos) << out;
    std::istringstream in(out.substr(at + 6));
    std::string name;
    in >> name >> lx >> ly >> lz;
    ASSERT_FALSE(in.fail()) << out;
  }
  // Where LinuxCNC ends: X, Y at the work origin through G54; Z at the G28 position.
  EXPECT_NEAR(lx, 12.5, 1e-6) << out;
  EXPECT_NEAR(ly, -7.25, 1e-6) << out;
  EXPECT_NEAR(lz, 40.0, 1e-6) << out;

  // The daemon: config/sim.yaml (its tool table is config/sim.tbl's) with this .var file, and M6
  // as a manual tool change (the pause this test is about; the carousel runs M6 in
  // PlcCarouselDaemon).
  std::string y = contour::test::sim_yaml(contour::test::SimPlc::kManualToolChange);
  const std::string var = "var_file: ${STATE_DIRECTORY:-/tmp}/contourd-sim.var";
  ASSERT_NE(y.find(var), std::string::npos);
  y.replace(y.find(var), var.size(), "var_file: " + (dir / "machine.var").string());
  std::ofstream(dir / "machine.yaml") << y;
  contour::test::DaemonProcess d("cam_e2e", {(dir / "machine.yaml").string(), {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const json r = d.ok({{"cmd", "run"}, {"program", kProgram}, {"name", "cam.ngc"}});
  ASSERT_TRUE(r.contains("job")) << r.dump() << d.log();
  const auto job = r["job"].get<std::uint64_t>();
  const json st = d.wait_status([](const json& s) { return s.contains("tool_change"); }, 3000);
  ASSERT_TRUE(st.contains("tool_change")) << st.dump();
  EXPECT_EQ(st["state"], "HOLD");
  EXPECT_EQ(st["tool_change"]["tool"], 2);
  EXPECT_EQ(st["tool_change"]["line"], 7);
  d.ok({{"cmd", "resume"}});
  // Mid-program: spindle on at 6000 rpm, flood coolant, tool 2 with its length.
  const json cut = d.wait_status(
      [](const json& s) { return s.value("state", "") == "RUNNING" && s.value("line", 0) >= 16; }, 3000);
  EXPECT_EQ(cut.value("tool", -1), 2) << cut.dump();
  EXPECT_NEAR(cut["spindle"].value("target_rpm", 0.0), 6000.0, 1e-6) << cut.dump();
  const json res = d.wait_finished(job);
  EXPECT_EQ(res["completed"], true) << res.dump() << d.log();
  const json fin = d.ok({{"cmd", "status"}});
  EXPECT_EQ(fin["finished_ok"], true) << fin.dump();
  // The daemon's final machine position is LinuxCNC's.
  EXPECT_NEAR(fin["ref_mm"][0].get<double>(), lx, 1e-6) << fin.dump();
  EXPECT_NEAR(fin["ref_mm"][1].get<double>(), ly, 1e-6) << fin.dump();
  EXPECT_NEAR(fin["ref_mm"][2].get<double>(), lz, 1e-6) << fin.dump();
  std::printf("[figure] CAM end to end: LinuxCNC ends at (%.6f, %.6f, %.6f), contourd at (%.6f, %.6f, %.6f)\n",
              lx, ly, lz, fin["ref_mm"][0].get<double>(), fin["ref_mm"][1].get<double>(),
              fin["ref_mm"][2].get<double>());
  fs::remove_all(dir);
}
