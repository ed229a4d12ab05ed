// The `identify` command's body (daemon/identify.hpp) against the loop running on its own thread
// (the command thread waits for the experiment as it does in contourd): the reply's fitted model,
// the comparison with the configuration, and the refusals. Bounded waits only; no timing asserted.
#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "daemon/command_protocol.hpp"
#include "daemon/identify.hpp"
#include "loop_rig.hpp"

namespace contour::daemon {
namespace {

struct Running {
  Running(const config::Config& c, std::vector<control::FeedDriveParams> plant)
      : cfg(c), bus(std::move(plant)), loop(cfg, bus) {
    thread = std::thread([this] {
      RtEvent e;
      while (!quit.load()) {
        loop.cycle();
        while (loop.events().pop(e)) {}
        std::this_thread::sleep_for(std::chrono::microseconds(50));
      }
    });
  }
  ~Running() {
    quit.store(true);
    thread.join();
  }
  void enable() {
    loop.post({CommandKind::kEnable});
    for (int i = 0; i < 2000 && loop.status().state != MachineState::kReady; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ASSERT_EQ(loop.status().state, MachineState::kReady);
  }
  config::Config cfg;
  SimBus bus;
  ServoLoop loop;
  std::atomic<bool> quit{false};
  std::thread thread;
};

TEST(IdentifyCommand, ReplyHasTheModelTheConfigAndTheRecord) {
  const config::Config cfg = test_rig::sim_config();
  Running r(cfg, test_rig::drives(cfg));
  r.enable();
  const auto j = identify_on_loop(r.loop, cfg, 1, [] { return false; });
  EXPECT_EQ(j["axis"], "Y");
  EXPECT_NEAR(j["gain_per_s"].get<double>(), 120.0, 2.4);
  EXPECT_NEAR(j["tau_ms"].get<double>(), 30.0, 0.6);
  EXPECT_EQ(j["delay_cycles"], 1);
  EXPECT_EQ(j["delay_matches"], true);
  EXPECT_EQ(j["verdict"], "matches the configuration");
  EXPECT_EQ(j["record"]["v_cmd_mm_s"].size(), r.loop.identify_excitation().size());
  EXPECT_EQ(j["record"]["position_mm"].size(), r.loop.identify_excitation().size());
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(IdentifyCommand, ADelayThatDiffersFromTheConfigIsNamed) {
  const config::Config cfg = test_rig::sim_config();
  auto plant = test_rig::drives(cfg);
  plant[2].delay_cycles = 2;  // the file says 1
  Running r(cfg, plant);
  r.enable();
  const auto j = identify_on_loop(r.loop, cfg, 2, [] { return false; });
  EXPECT_EQ(j["delay_cycles"], 2);
  EXPECT_EQ(j["delay_matches"], false);
  EXPECT_NE(j["verdict"].get<std::string>().find("delay differs"), std::string::npos) << j["verdict"];
}

TEST(IdentifyCommand, RefusedUnlessReady) {
  const config::Config cfg = test_rig::sim_config();
  Running r(cfg, test_rig::drives(cfg));
  try {
    (void)identify_on_loop(r.loop, cfg, 0, [] { return false; });
    FAIL() << "identify ran while DISABLED";
  } catch (const CommandError& e) {
    EXPECT_NE(std::string(e.what()).find("READY"), std::string::npos) << e.what();
  }
  r.enable();
  EXPECT_THROW((void)identify_on_loop(r.loop, cfg, 5, [] { return false; }), CommandError);
}

}  // namespace
}  // namespace contour::daemon
