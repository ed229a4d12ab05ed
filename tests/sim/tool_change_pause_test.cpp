// A CAM program that starts with `T1 M6` (issue 18): `run` starts it and it pauses at once for the
// manual tool change instead of being refused ("run refused by the loop (state HOLD)"); status
// says what it waits for (`hold`, `tool_change`), the events name the pause, and `contourctl run
// --wait` announces it, keeps waiting, and exits 0 when the program completes after `resume`.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "tests/support/daemon_process.hpp"
#include "tests/support/run_cmd.hpp"
#include "tests/support/sim_config.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";
const std::string kProgram =
    "%\n(CAM-style header)\nG21 G90 G17\nT1 M6\nS3000 M3\nG0 X5 Y5\nG1 X20 F1500\nG1 Y15\nM5\nM2\n%\n";

using contour::test::run_cmd;

// config/sim.yaml with its machine logic's tool changer switched off (plc.tool_change enabled:
// false): M6 is the operator's manual change, the pause this file tests. With the shipped
// carousel M6 runs the PLC sequence instead (tests/sim/plc_daemon_test.cpp).
std::string manual_tool_change_config() {
  const fs::path p = fs::temp_directory_path() / ("contour_manual_tc_" + std::to_string(::getpid()) + ".yaml");
  return contour::test::write_sim_yaml(p.string(), contour::test::SimPlc::kManualToolChange);
}

TEST(ToolChangePause, RunStartsAProgramThatBeginsWithAToolChangeAndResumeCompletesIt) {
  contour::test::DaemonProcess d("toolchange", {manual_tool_change_config(), {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const json r = d.ok({{"cmd", "run"}, {"program", kProgram}, {"name", "cam.ngc"}});
  ASSERT_TRUE(r.contains("job")) << r.dump();
  const auto job = r["job"].get<std::uint64_t>();
  const json st = d.wait_status([](const json& s) { return s.contains("tool_change"); }, 3000);
  ASSERT_TRUE(st.contains("tool_change")) << st.dump();
  EXPECT_EQ(st["state"], "HOLD");
  EXPECT_EQ(st["program_hold"], true);
  EXPECT_EQ(st["tool_change"]["tool"], 1);
  EXPECT_EQ(st["tool_change"]["line"], 4);
  EXPECT_NE(st["tool_change"]["message"].get<std::string>().find("tool 1"), std::string::npos);
  d.ok({{"cmd", "resume"}});
  const json res = d.wait_finished(job);
  const json fin = d.ok({{"cmd", "status"}});
  EXPECT_EQ(fin["finished_ok"], true) << fin.dump();
  EXPECT_FALSE(fin.contains("hold"));
  EXPECT_NEAR(fin["ref_mm"][0].get<double>(), 20.0, 1e-6);
  EXPECT_NEAR(fin["ref_mm"][1].get<double>(), 15.0, 1e-6);
  EXPECT_NE(d.log().find("program paused at line 4"), std::string::npos) << d.log();
}

TEST(ToolChangePause, ContourctlRunWaitAnnouncesThePauseAndExitsZeroAfterResume) {
  contour::test::DaemonProcess d("toolchange_ctl", {manual_tool_change_config(), {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const fs::path prog = fs::path(d.sock()).parent_path() / "cam.ngc";
  std::ofstream(prog) << kProgram;
  auto ctl = std::async(std::launch::async, [&] {
    std::string out;
    const int rc = run_cmd(kCtl + " --socket " + d.sock() + " run " + prog.string() +
                               " --wait --timeout 120",
                           &out);
    return std::make_pair(rc, out);
  });
  const json st = d.wait_status([](const json& s) { return s.contains("tool_change"); }, 3000);
  ASSERT_TRUE(st.contains("tool_change")) << st.dump();
  // Give contourctl (polling status) time to see the pause: a tolerance, not a timing check.
  std::this_thread::sleep_for(std::chrono::seconds(2));
  d.ok({{"cmd", "resume"}});
  const auto [rc, out] = ctl.get();
  EXPECT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("paused at line 4: manual tool change: insert tool 1"), std::string::npos)
      << out;
}

}  // namespace
