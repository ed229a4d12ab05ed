// `contourctl identify AXIS` against contourd on config/sim.yaml (issue 16): the daemon plays the
// excitation on the simulated drive and the reply recovers its gain and time constant within 2 %
// and its delay exactly; the plot is written; a refusal (a program loaded) is a clear error and
// exit 1. Bounded waits only.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/daemon_process.hpp"
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

}  // namespace
