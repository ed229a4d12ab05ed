// Issue 18, "Coordinates, offsets, tools" + MDI on the real contourd (sim machine, lockstep):
// the .var / .tbl files the daemon owns (program.var_file, program.tool_table), the `offsets`,
// `tools`, `touch-off` and `mdi` commands and the status fields tool / work_offset /
// work_offset_mm / work_ref_mm. Every file lives in the test's temporary directory.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::string kSrc = CONTOUR_SOURCE_DIR;

// config/sim.yaml with the var file and a copy of config/sim.tbl in `dir`.
std::string make_config(const fs::path& dir) {
  fs::create_directories(dir);
  std::string y = contour::test::sim_yaml();
  const std::string tbl =
      "  tools:\n    - {number: 1, length_mm: 0}\n    - {number: 2, length_mm: 12.5}\n"
      "    - {number: 3, length_mm: 25}\n    - {number: 4, length_mm: 40}\n";
  const std::string var = "var_file: ${STATE_DIRECTORY:-/tmp}/contourd-sim.var";
  EXPECT_NE(y.find(tbl), std::string::npos);
  EXPECT_NE(y.find(var), std::string::npos);
  y.replace(y.find(tbl), tbl.size(), "  tool_table: tools.tbl\n");
  y.replace(y.find(var), var.size(), "var_file: state/machine.var");
  fs::copy_file(kSrc + "/config/sim.tbl", dir / "tools.tbl", fs::copy_options::overwrite_existing);
  std::ofstream(dir / "machine.yaml") << y;
  return (dir / "machine.yaml").string();
}

fs::path test_dir(const std::string& tag) {
  const fs::path d = fs::temp_directory_path() /
                     ("contour_offsets_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  return d;
}

// The value of parameter `n` in a .var file (NaN when absent).
double var_value(const fs::path& file, int n) {
  std::ifstream in(file);
  int k = 0;
  double v = 0.0;
  while (in >> k >> v) {
    if (k == n) return v;
  }
  return std::nan("");
}

json run_and_wait(contour::test::DaemonProcess& d, const std::string& program) {
  const json r = d.ok({{"cmd", "run"}, {"program", program}});
  EXPECT_TRUE(r.contains("job")) << r.dump();
  const json res = d.wait_finished(r["job"].get<std::uint64_t>());
  EXPECT_EQ(res["completed"], true) << res.dump() << d.log();
  return d.ok({{"cmd", "status"}});
}

TEST(OffsetsDaemon, OffsetsSurviveARestartThroughTheVarFile) {
  const fs::path dir = test_dir("restart");
  const std::string cfg = make_config(dir);
  {
    contour::test::DaemonProcess d("offsets_restart1", {cfg, {}, 1000, 500});
    ASSERT_TRUE(d.connected()) << d.log();
    const json r = d.ok({{"cmd", "offsets"}, {"set", "G55"}, {"X", 12.5}, {"Z", -3.25}});
    EXPECT_DOUBLE_EQ(r["offsets"]["G55"][0].get<double>(), 12.5) << r.dump();
    d.ok({{"cmd", "offsets"}, {"set", "G28"}, {"Y", 7.0}});
  }
  EXPECT_DOUBLE_EQ(var_value(dir / "state/machine.var", 5241), 12.5);
  EXPECT_DOUBLE_EQ(var_value(dir / "state/machine.var", 5243), -3.25);
  contour::test::DaemonProcess d("offsets_restart2", {cfg, {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const json o = d.ok({{"cmd", "offsets"}})["offsets"];
  EXPECT_DOUBLE_EQ(o["G55"][0].get<double>(), 12.5) << o.dump();
  EXPECT_DOUBLE_EQ(o["G55"][2].get<double>(), -3.25) << o.dump();
  EXPECT_DOUBLE_EQ(o["G28"][1].get<double>(), 7.0) << o.dump();
  // A program in G55 sees them: X0 in G55 is machine X 12.5.
  const json st = run_and_wait(d, "G55 G0 X0 Y0\nM2\n");
  EXPECT_NEAR(st["ref_mm"][0].get<double>(), 12.5, 1e-6) << st.dump();
  fs::remove_all(dir);
}

TEST(OffsetsDaemon, G10L20InAProgramIsWrittenToTheVarFileAndTouchOffMakesTheAxisReadTheValue) {
  const fs::path dir = test_dir("g10");
  const std::string cfg = make_config(dir);
  contour::test::DaemonProcess d("offsets_g10", {cfg, {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  // G10 L20: the current position (X 10 after the move) reads X 4 in G54: origin X = 6.
  run_and_wait(d, "G54 G0 X10 Y5\nG10 L20 P1 X4\nM2\n");
  EXPECT_NEAR(var_value(dir / "state/machine.var", 5221), 6.0, 1e-9)
      << contour::test::slurp((dir / "state/machine.var").string());
  json st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["work_offset"], "G54");
  EXPECT_NEAR(st["work_offset_mm"][0].get<double>(), 6.0, 1e-9) << st.dump();
  EXPECT_NEAR(st["work_ref_mm"][0].get<double>(), 4.0, 1e-6) << st.dump();
  // touch-off Y 2 in G54: the commanded Y (5) reads 2.
  const json t = d.ok({{"cmd", "touch-off"}, {"axis", "Y"}, {"value", 2.0}, {"offset", "G54"}});
  EXPECT_NEAR(t["offsets"]["G54"][1].get<double>(), 3.0, 1e-9) << t.dump();
  st = d.ok({{"cmd", "status"}});
  EXPECT_NEAR(st["work_ref_mm"][1].get<double>(), 2.0, 1e-6) << st.dump();
  EXPECT_NEAR(var_value(dir / "state/machine.var", 5222), 3.0, 1e-9);
  fs::remove_all(dir);
}

TEST(OffsetsDaemon, MdiMovesAndItsModalStateCarriesIntoTheNextBlock) {
  const fs::path dir = test_dir("mdi");
  const std::string cfg = make_config(dir);
  contour::test::DaemonProcess d("offsets_mdi", {cfg, {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const json st0 = d.ok({{"cmd", "status"}});
  const double x0 = st0["ref_mm"][0].get<double>();
  json r = d.ok({{"cmd", "mdi"}, {"text", "G91"}});
  EXPECT_EQ(r["blocks"], 0) << r.dump();
  for (int i = 0; i < 2; ++i) {
    r = d.ok({{"cmd", "mdi"}, {"text", "G0 X5"}});
    ASSERT_TRUE(r.contains("job")) << r.dump();
    const json res = d.wait_finished(r["job"].get<std::uint64_t>());
    EXPECT_EQ(res["completed"], true) << res.dump();
  }
  // G91 from the first block: two incremental moves of 5 mm.
  const json st = d.ok({{"cmd", "status"}});
  EXPECT_NEAR(st["ref_mm"][0].get<double>(), x0 + 10.0, 1e-6) << st.dump();
  // MDI is refused with a program loaded.
  d.ok({{"cmd", "load"}, {"program", "G90 G1 X0 F600\nM2\n"}});
  const json refused = d.call({{"cmd", "mdi"}, {"text", "G0 X1"}});
  EXPECT_FALSE(refused.value("ok", true)) << refused.dump();
  EXPECT_NE(refused.value("error", std::string()).find("not while a program is loaded"),
            std::string::npos) << refused.dump();
  fs::remove_all(dir);
}

TEST(OffsetsDaemon, ToolsSetThenAProgramsG43UsesTheNewLength) {
  const fs::path dir = test_dir("tools");
  const std::string cfg = make_config(dir);
  contour::test::DaemonProcess d("offsets_tools", {cfg, {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  json r = d.ok({{"cmd", "tools"}});
  ASSERT_EQ(r["tools"].size(), 4U) << r.dump();
  EXPECT_DOUBLE_EQ(r["tools"][1]["length_mm"].get<double>(), 12.5);
  r = d.ok({{"cmd", "tools"}, {"set", 2}, {"length_mm", 7.5}, {"comment", "probe"}});
  EXPECT_DOUBLE_EQ(r["tools"][1]["length_mm"].get<double>(), 7.5) << r.dump();
  EXPECT_NE(contour::test::slurp((dir / "tools.tbl").string()).find("Z+7.5"), std::string::npos)
      << contour::test::slurp((dir / "tools.tbl").string());
  // M61 Q2: tool 2 in the spindle without a change; G43 H2: Z0 is machine Z 7.5.
  const json st = run_and_wait(d, "M61 Q2\nG43 H2\nG90 G0 Z0\nM2\n");
  EXPECT_NEAR(st["ref_mm"][2].get<double>(), 7.5, 1e-6) << st.dump();
  EXPECT_EQ(st["tool"], 2) << st.dump();
  fs::remove_all(dir);
}

int start_exit_code(const std::string& cfg, const fs::path& dir, std::string* out) {
  const std::string cmd = "timeout 60 " + contour::test::contourd_binary() + " --config " + cfg +
                          " --socket " + (dir / "c.sock").string() + " 2>&1";
  FILE* f = ::popen(cmd.c_str(), "r");
  if (f == nullptr) return -1;
  char buf[512];
  while (std::fgets(buf, sizeof buf, f) != nullptr) *out += buf;
  const int st = ::pclose(f);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

TEST(OffsetsDaemon, ACorruptVarOrTblFileIsAStartUpErrorNamingFileAndLine) {
  const fs::path dir = test_dir("corrupt");
  const std::string cfg = make_config(dir);
  fs::create_directories(dir / "state");
  std::ofstream(dir / "state/machine.var") << "5161\t0.0\n5162 oops\n";
  std::string out;
  EXPECT_EQ(start_exit_code(cfg, dir, &out), 78) << out;
  EXPECT_NE(out.find((dir / "state/machine.var").string() + ":2"), std::string::npos) << out;
  fs::remove(dir / "state/machine.var");
  std::ofstream(dir / "tools.tbl") << "T1 P1\nT2 P2 K5\n";
  out.clear();
  EXPECT_EQ(start_exit_code(cfg, dir, &out), 78) << out;
  EXPECT_NE(out.find((dir / "tools.tbl").string() + ":2"), std::string::npos) << out;
  fs::remove_all(dir);
}

}  // namespace
