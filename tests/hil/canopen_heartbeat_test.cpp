// HIL (issue 16): the master's heartbeat is real time. contour-machine-sim with
// `--hb-consumer wall` times the master's heartbeat (0x1016 = 3 x bus.master_heartbeat_ms = 300 ms)
// on its own wall clock, as a real drive does; the daemon's CanopenBus runs in lockstep
// (bus.lockstep: heartbeat time counted in cycles) with each cycle taking 4 ms of real time, i.e.
// slower than real time as on a loaded host. A master that produced its heartbeat every 100
// CYCLES sent one every >= 400 ms: the drives timed out (EMCY 0x8130, fault). Produced on the wall
// clock, it holds.
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "daemon/canopen_bus.hpp"
#include "tests/hil/canopen_hil_support.hpp"

namespace {

using contour::daemon::AxisCommands;
using contour::daemon::BusFeedback;
using contour::daemon::CanopenBus;
using contour::daemon::DriveMode;

TEST(CanopenHeartbeat, SlowLockstepCyclesKeepAWallClockConsumerAlive) {
  const auto cfg = contour::test::hil_config();
  contour::test::MachineSim sim({"--hb-consumer", "wall"});
  ASSERT_TRUE(sim.ready()) << sim.stop();
  std::vector<std::string> log;
  CanopenBus bus(cfg, [&](const std::string& s) { log.push_back(s); });
  bus.set_event_thread(false);
  bus.start();
  AxisCommands c;
  c.mode = DriveMode::kEnabled;
  BusFeedback fb;
  auto cycle = [&] {
    bus.begin_cycle();
    bus.read(fb);
    bus.write(c);
  };
  int enabled_at = -1;
  for (int k = 0; k < 2000 && enabled_at < 0; ++k) {
    cycle();
    bool all = fb.axes == 3;
    for (int i = 0; i < fb.axes; ++i) all = all && fb.axis[static_cast<std::size_t>(i)].enabled;
    if (all) enabled_at = k;
  }
  ASSERT_GE(enabled_at, 0) << "drives did not enable";
  // 300 cycles of >= 4 ms each: >= 1.2 s of wall time, 300 ms of cycle time.
  const auto t0 = std::chrono::steady_clock::now();
  int faulted_at = -1;
  for (int k = 0; k < 300; ++k) {
    cycle();
    for (int i = 0; i < fb.axes; ++i) {
      const auto& ax = fb.axis[static_cast<std::size_t>(i)];
      if ((ax.fault || ax.emcy_code != 0 || !ax.enabled) && faulted_at < 0) faulted_at = k;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(4));
  }
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bus.drain_events([&](const std::string& s) { log.push_back(s); });
  std::string all;
  for (const auto& l : log) all += l + "\n";
  EXPECT_EQ(faulted_at, -1) << "a drive faulted after " << faulted_at << " slow cycles:\n" << all;
  EXPECT_EQ(all.find("0x8130"), std::string::npos) << all;
  EXPECT_GE(wall_s, 1.2);
  bus.stop();
}

}  // namespace
