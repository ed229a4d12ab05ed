// Issue 16: the run-time limit-cycle / chatter watchdog in the loop's supervise stage
// (safety.chatter, control::ChatterMonitor). Gains past the stability check (staged directly on the
// loop: the test-only path around `gains set`'s check) make X limit-cycle at standstill in READY:
// a warning event, then FAULT "limit cycle" naming the axis and the figure, and the cycles that
// judge it allocate nothing. The shipped gains at rest and the config keys stay quiet / validated.
#include <gtest/gtest.h>

#include <string>

#include "daemon/event_log.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/support/config_errors.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;
using test_rig::sim_config;

TEST(LimitCycleWatchdog, GainsPastTheCheckWarnThenFaultNamingTheAxisWithoutAllocating) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  r.step(200);
  auto p = r.loop.active_params();
  p.axis[0].kp = 50.0;  // `gains set axis.x.kp=50`, which the daemon's check now refuses
  r.loop.stage_gains(p);
  r.step(2);
  // An axis exactly at rest on the encoder grid has nothing to grow from: a short jog of X, after
  // which it stands (and, with these gains, limit-cycles).
  r.loop.post({CommandKind::kJog, 0, 10.0, 0.2});
  std::size_t allocs = 0;
  RtEvent e;
  for (int block = 0; block < 30 && r.loop.status().state != MachineState::kFault; ++block) {
    {
      test::AllocGuard g;
      for (int i = 0; i < 100; ++i) r.loop.cycle();
      allocs += g.counts().total();
    }
    while (r.loop.events().pop(e)) r.events.push_back(e);
  }
  EXPECT_EQ(allocs, 0u);
  ASSERT_EQ(r.loop.status().state, MachineState::kFault);
  EXPECT_EQ(r.loop.status().cause, FaultCause::kLimitCycle);
  EXPECT_EQ(r.loop.status().fault_axis, 0);
  std::size_t warn_at = 0, fault_at = 0;
  std::string warn_text, fault_text;
  for (std::size_t i = 0; i < r.events.size(); ++i) {
    const RtEvent& ev = r.events[i];
    if (ev.kind == EventKind::kLimitCycleWarning && warn_text.empty()) {
      warn_at = i;
      warn_text = describe(ev);
      EXPECT_EQ(ev.axis, 0);
    }
    if (ev.kind == EventKind::kFault && ev.cause == FaultCause::kLimitCycle) {
      fault_at = i;
      fault_text = describe(ev);
      EXPECT_EQ(ev.axis, 0);
      EXPECT_GT(ev.value, ev.limit);
    }
  }
  ASSERT_FALSE(warn_text.empty());
  ASSERT_FALSE(fault_text.empty());
  EXPECT_LT(warn_at, fault_at);
  std::printf("%s\n%s\n", warn_text.c_str(), fault_text.c_str());
  EXPECT_NE(fault_text.find("FAULT limit cycle axis 0: "), std::string::npos) << fault_text;
  EXPECT_NE(fault_text.find("(safety.chatter)"), std::string::npos) << fault_text;
  EXPECT_NE(warn_text.find("LIMIT CYCLE WARNING axis 0: "), std::string::npos) << warn_text;
}

TEST(LimitCycleWatchdog, ShippedGainsAtRestStayQuietAndTheWatchdogCanBeTurnedOff) {
  for (const bool enabled : {true, false}) {
    auto cfg = sim_config();
    cfg.safety.chatter.enable = enabled;
    Rig r(cfg);
    ASSERT_TRUE(r.enable());
    if (!enabled) {  // the same limit cycle as above, with the watchdog off: no event, no FAULT
      auto p = r.loop.active_params();
      p.axis[0].kp = 50.0;
      r.loop.stage_gains(p);
      r.step(2);
    }
    r.loop.post({CommandKind::kJog, 0, 10.0, 0.2});
    r.step(2000);
    if (!enabled) {
      EXPECT_GT(r.loop.status().accel_clamps, 500u);  // it does oscillate (clamped ~600 times/s)
    } else {
      EXPECT_EQ(r.loop.status().accel_clamps, 0u);
    }
    EXPECT_EQ(r.count(EventKind::kLimitCycleWarning), 0u) << enabled;
    EXPECT_EQ(r.loop.status().state, MachineState::kReady) << enabled;
    EXPECT_EQ(r.loop.status().chatter_level, 0) << enabled;
    if (enabled) {
      EXPECT_LT(r.loop.status().chatter_window_mm_s[0], 1.0);
    }
  }
}

TEST(LimitCycleWatchdog, ConfigKeysAreParsedAndValidated) {
  const std::string m = contour::test::kMachineYaml;
  auto c = config::load_config_string("safety:\n  chatter: {window_ms: 50, warn_mm_s: 3, fault_ms: 800}\n" + m);
  EXPECT_DOUBLE_EQ(c.safety.chatter.window_s, 0.05);
  EXPECT_DOUBLE_EQ(c.safety.chatter.warn_mm_s, 3.0);
  EXPECT_DOUBLE_EQ(c.safety.chatter.fault_s, 0.8);
  EXPECT_DOUBLE_EQ(c.safety.chatter.fault_mm_s, 40.0);  // default
  c = config::load_config_string("safety: {}\n" + m);
  EXPECT_TRUE(c.safety.chatter.enable);
  EXPECT_DOUBLE_EQ(c.safety.chatter.fault_clamps_per_s, 300.0);
  EXPECT_FALSE(contour::test::config_errors("safety:\n  chatter: {warn_mm_s: 50, fault_mm_s: 40}\n" + m).empty());
  EXPECT_FALSE(contour::test::config_errors("safety:\n  chatter: {bogus: 1}\n" + m).empty());
}

}  // namespace
}  // namespace contour::daemon
