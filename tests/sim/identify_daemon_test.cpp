// `contourctl identify AXIS` against contourd on config/sim.yaml (issue 16): the daemon plays the
// excitation on the simulated drive and the reply recovers its gain and time constant within 2 %
// and its delay exactly; the plot is written; a refusal (a program loaded) is a clear error and
// exit 1. Bounded waits only.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <fstream>
#include <sstream>
#include <string>

#include "config/config.hpp"
#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/run_cmd.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";

using contour::test::run_cmd;

TEST(IdentifyDaemon, ContourctlIdentifyRecoversTheSimulatedDrive) {
  contour::test::DaemonProcess d("identify", {kSrc + "/config/sim.yaml", {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  const fs::path png = fs::temp_directory_path() / ("identify_" + std::to_string(::getpid()) + ".png");
  std::string out;
  const int rc = run_cmd(kCtl + " --socket " + d.sock() + " --json identify Z --plot " + png.string(), &out);
  ASSERT_EQ(rc, 0) << out << d.log();
  const json r = json::parse(out.substr(out.find('{')));
  EXPECT_EQ(r["axis"], "Z");
  EXPECT_NEAR(r["gain_per_s"].get<double>(), 115.0, 0.02 * 115.0) << out;  // config/sim.yaml Z
  EXPECT_NEAR(r["tau_ms"].get<double>(), 25.0, 0.02 * 25.0) << out;
  EXPECT_EQ(r["delay_cycles"], 1) << out;
  EXPECT_EQ(r["delay_matches"], true);
  EXPECT_GT(fs::file_size(png), 1000U);
  fs::remove(png);
  EXPECT_EQ(d.state(), "READY");

  // With a program loaded the machine is not "at rest for commissioning": refused, exit 1.
  d.ok({{"cmd", "load"}, {"program", "G1 X1 F100\nM2\n"}, {"name", "p.ngc"}});
  out.clear();
  EXPECT_EQ(run_cmd(kCtl + " --socket " + d.sock() + " identify X", &out), 1) << out;
  EXPECT_NE(out.find("unload the program"), std::string::npos) << out;
}

// `gains save` stores what identify measured (issue 16): the axis' drive model (sim:) becomes the
// measured one and the measurement is recorded (identified:); the other axes and the file's
// comments stay. A later start with a configured delay that contradicts the measurement warns,
// naming the axis, in the log and in status.config.warnings.
TEST(IdentifyDaemon, GainsSaveStoresTheMeasuredModelAndStartUpWarnsOnADelayMismatch) {
  const fs::path dir = fs::temp_directory_path() / ("identify_save_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path cfg = dir / "machine.yaml";
  contour::test::write_sim_yaml(cfg.string());  // sim.yaml, its PLC program paths absolute
  std::string saved_text;
  double k = 0.0, tau_ms = 0.0;
  {
    contour::test::DaemonProcess d("identify_save", {cfg.string(), {}, 1000, 500});
    ASSERT_TRUE(d.connected()) << d.log();
    ASSERT_EQ(d.state(), "READY") << d.log();
    std::string out;
    ASSERT_EQ(run_cmd(kCtl + " --socket " + d.sock() + " --json identify X", &out), 0) << out << d.log();
    const json r = json::parse(out.substr(out.find('{')));
    k = r["gain_per_s"].get<double>();
    tau_ms = r["tau_ms"].get<double>();
    const json g = d.ok({{"cmd", "gains"}});
    ASSERT_TRUE(g["identified"].contains("X")) << g.dump();
    EXPECT_FALSE(g["identified"].contains("Y")) << g.dump();
    EXPECT_EQ(g["identified"]["X"]["delay_cycles"], r["delay_cycles"]);
    out.clear();
    ASSERT_EQ(run_cmd(kCtl + " --socket " + d.sock() + " gains save --file " + cfg.string(), &out), 0)
        << out;
    EXPECT_NE(out.find("axis X: measured drive model stored"), std::string::npos) << out;
    saved_text = contour::test::slurp(cfg.string());
  }
  const auto c = contour::config::load_config_string(saved_text, cfg.string());
  const auto& x = c.machine.axes[0];
  EXPECT_NEAR(x.drive.gain_per_s, k, 1e-9 * k);
  EXPECT_NEAR(x.drive.tau_s * 1e3, tau_ms, 1e-9 * tau_ms);
  EXPECT_EQ(x.drive.delay_cycles, 1);
  ASSERT_TRUE(x.identified.present);
  EXPECT_EQ(x.identified.delay_cycles, 1);
  EXPECT_FALSE(x.identified.date.empty());
  EXPECT_FALSE(c.machine.axes[1].identified.present);
  EXPECT_DOUBLE_EQ(c.machine.axes[1].drive.gain_per_s, 120.0);  // Y untouched
  EXPECT_NE(saved_text.find("# contourd embedded default"), std::string::npos);
  EXPECT_TRUE(contour::config::identification_warnings(c.machine).empty());

  // Hand edit: the recorded measurement says 2 cycles, sim.delay_cycles still 1.
  std::istringstream in(saved_text);
  std::string line, edited;
  int changed = 0;
  while (std::getline(in, line)) {
    if (line.find("identified:") != std::string::npos) {
      const auto p = line.find("delay_cycles: 1");
      if (p != std::string::npos) {
        line.replace(p, 15, "delay_cycles: 2");
        ++changed;
      }
    }
    edited += line + "\n";
  }
  ASSERT_EQ(changed, 1) << saved_text;
  std::ofstream(cfg) << edited;
  contour::test::DaemonProcess d("identify_warn", {cfg.string(), {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const json st = d.ok({{"cmd", "status"}});
  ASSERT_TRUE(st.contains("config") && st["config"].contains("warnings")) << st.dump();
  const json& w = st["config"]["warnings"];
  ASSERT_TRUE(w.is_array() && w.size() == 1U) << st["config"].dump();
  EXPECT_NE(w[0].get<std::string>().find("machine.axes[0] (X)"), std::string::npos) << w.dump();
  EXPECT_NE(w[0].get<std::string>().find("measured as 2 cycles"), std::string::npos) << w.dump();
  EXPECT_NE(d.log().find("measured as 2 cycles"), std::string::npos) << d.log();
  fs::remove_all(dir);
}

}  // namespace
