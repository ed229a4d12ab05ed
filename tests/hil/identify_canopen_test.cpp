// HIL (issue 16): `identify` through contourd on config/hil.yaml over vcan0, against
// contour-machine-sim's drives (velocity targets in counts/s, positions in counts, TPDO sampled
// at SYNC): K and tau within 2 % of the simulated drive, the transport delay exact; and against a
// simulator whose X drive is one cycle slower than the daemon's config says, which reads one cycle
// more and is named as a delay mismatch. Lockstep (bus.lockstep): no wall-clock assertions.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "tests/hil/canopen_hil_support.hpp"
#include "tests/support/daemon_process.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::string kHil = std::string(CONTOUR_SOURCE_DIR) + "/config/hil.yaml";

json identify_x(const std::string& tag) {
  contour::test::DaemonProcess d("hil_identify_" + tag, {kHil, {}, 6000, 3000});
  EXPECT_TRUE(d.connected()) << d.log();
  EXPECT_EQ(d.state(), "READY") << d.log();
  if (!d.connected()) return json::object();
  const json r = d.call({{"cmd", "identify"}, {"axis", "X"}});
  EXPECT_TRUE(r.value("ok", false)) << r.dump() << "\n" << d.log();
  return r.value("result", json::object());
}

TEST(IdentifyCanopen, RecoversTheSimulatedDriveOverCan) {
  contour::test::MachineSim sim;
  ASSERT_TRUE(sim.ready()) << sim.stop();
  const json r = identify_x("same");
  std::printf("[figure] identify X over vcan: K %.4f 1/s, tau %.4f ms, delay %d (confidence %.3f)\n",
              r.value("gain_per_s", 0.0), r.value("tau_ms", 0.0), r.value("delay_cycles", -1),
              r.value("delay_confidence", 0.0));
  EXPECT_NEAR(r.value("gain_per_s", 0.0), 120.0, 0.02 * 120.0) << r.dump();  // hil.yaml X
  EXPECT_NEAR(r.value("tau_ms", 0.0), 30.0, 0.02 * 30.0) << r.dump();
  EXPECT_EQ(r.value("delay_cycles", -1), 1) << r.dump();
  EXPECT_EQ(r.value("delay_matches", false), true) << r.dump();
}

TEST(IdentifyCanopen, ADriveOneCycleSlowerThanConfiguredReadsOneCycleMore) {
  // The simulator's X drive: delay_cycles 2; the daemon's config keeps 1.
  std::ifstream in(kHil);
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  const std::string x = "- {name: X,";
  const auto at = text.find("delay_cycles: 1", text.find(x));
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 15, "delay_cycles: 2");
  const fs::path cfg = fs::temp_directory_path() / ("hil_identify_slow_" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(cfg) << text;
  contour::test::MachineSim sim({}, cfg.string());
  ASSERT_TRUE(sim.ready()) << sim.stop();
  const json r = identify_x("slow");
  fs::remove(cfg);
  std::printf("[figure] identify X over vcan, drive one cycle slower: K %.4f 1/s, tau %.4f ms, delay %d\n",
              r.value("gain_per_s", 0.0), r.value("tau_ms", 0.0), r.value("delay_cycles", -1));
  EXPECT_NEAR(r.value("gain_per_s", 0.0), 120.0, 0.02 * 120.0) << r.dump();
  EXPECT_NEAR(r.value("tau_ms", 0.0), 30.0, 0.02 * 30.0) << r.dump();
  EXPECT_EQ(r.value("delay_cycles", -1), 2) << r.dump();
  EXPECT_EQ(r.value("delay_matches", true), false) << r.dump();
  EXPECT_NE(r.value("verdict", std::string()).find("delay differs"), std::string::npos) << r.dump();
}

}  // namespace
