// Spindle in the servo loop (issue 8): speed clamped to spindle.min/max_rpm and slewed at
// rate_rpm_s; a feed move after M3/M4/S waits at an exact stop until the spindle is at speed
// (SimBus spindle: first-order lag sim_tau_s), a stalled spindle faults after
// at_speed_timeout_s without the axes moving, rapids run while the spindle accelerates.
#include <gtest/gtest.h>

#include <cmath>

#include <chrono>
#include <thread>

#include "config/config.hpp"
#include "daemon/io_channels.hpp"
#include "daemon/servo_loop.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/support/sim_vfd.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;
using test_rig::sim_config;

config::Config spindle_config(double rate_rpm_s = 6000.0) {
  auto cfg = sim_config();
  EXPECT_EQ(cfg.spindle.type, "sim");  // config/sim.yaml has the simulated spindle
  cfg.spindle.limits.rate_rpm_s = rate_rpm_s;
  cfg.spindle.sim_tau_s = 0.2;
  return cfg;
}

// Rig whose SimBus has the configured spindle (make_sim_bus does this for contourd).
struct SpindleRig : Rig {
  explicit SpindleRig(const config::Config& c) : Rig(c) { bus.configure_spindle(c.spindle.sim_tau_s); }
};

struct Trace {
  int motion_cycle = -1;        // first cycle at which X moved
  double rpm_at_motion = 0.0;   // spindle speed then
  double min_rpm_waiting = 1e9; // slowest speed seen while the feed move waited
  bool waited = false;
};

Trace run_until_done(SpindleRig& r, int max_cycles) {
  Trace t;
  const double x0 = r.loop.status().ref_mm[0];
  double x_wait = 0.0;
  bool was_waiting = false;
  for (int k = 0; k < max_cycles && r.loop.status().finished_job == 0; ++k) {
    r.step();
    const auto st = r.loop.status();
    if (st.spindle_waiting) {
      t.waited = true;
      t.min_rpm_waiting = std::min(t.min_rpm_waiting, st.spindle_actual_rpm);
      if (!was_waiting) x_wait = st.ref_mm[0];
      EXPECT_EQ(st.ref_mm[0], x_wait) << "the path moved while waiting for the spindle, cycle " << k;
    }
    was_waiting = st.spindle_waiting;
    if (t.motion_cycle < 0 && st.ref_mm[0] != x0) {
      t.motion_cycle = k;
      t.rpm_at_motion = st.spindle_actual_rpm;
    }
    if (st.state == MachineState::kFault) break;
  }
  return t;
}

TEST(SpindleLoop, FeedMoveWaitsUntilTheSpindleIsAtSpeed) {
  const auto cfg = spindle_config();
  SpindleRig r(cfg);
  ASSERT_TRUE(r.enable());
  r.load("G21 G90\nM3 S6000\nG01 X5 F600\nM5\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  const Trace t = run_until_done(r, 20000);
  const auto st = r.loop.status();
  ASSERT_TRUE(st.finished_ok) << to_string(st.state) << " " << to_string(st.cause);
  ASSERT_TRUE(t.waited);
  EXPECT_LT(t.min_rpm_waiting, 100.0);  // it waited from standstill
  // At speed: within max(50 rpm, 2 % of 6000) = 120 rpm.
  EXPECT_GE(t.rpm_at_motion, 6000.0 - 120.0);
  EXPECT_EQ(st.spindle_waits, 1u);
  // Expected wait, closed form: the command ramps 0 -> 6000 rpm in 1 s (6000 rpm/s), the spindle
  // follows with a first-order lag tau = 0.2 s. At the ramp's end it lags by
  // R tau (1 - e^(-Tr/tau)) = 1192 rpm, then decays with tau to 120 rpm: 0.2 ln(1192/120) s.
  const double tau = 0.2, R = 6000.0, Tr = 1.0;
  const double lag = R * tau * (1.0 - std::exp(-Tr / tau));
  const double expected_s = Tr + tau * std::log(lag / 120.0);
  std::printf("[figure] spindle 0 -> 6000 rpm at 6000 rpm/s, tau 0.2 s: feed waited %.3f s "
              "(closed form %.3f s), speed at feed start %.1f rpm\n",
              st.spindle_last_wait_s, expected_s, t.rpm_at_motion);
  EXPECT_NEAR(st.spindle_last_wait_s, expected_s, 0.005);  // a few cycles of transport delay
}

TEST(SpindleLoop, NoAllocationWhileWaitingForTheSpindleAndCutting) {
  SpindleRig r(spindle_config());
  ASSERT_TRUE(r.enable());
  r.load("G21 G90\nM3 S6000\nG01 X5 F1200\nS8000\nG01 X10\nM5\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  r.step(3);
  ASSERT_TRUE(r.loop.status().spindle_waiting);
  RtEvent e;
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int i = 0; i < 8000; ++i) {
      r.loop.cycle();
      while (r.loop.events().pop(e)) {}
      TelemetrySample s;
      while (r.loop.telemetry().pop(s)) {}
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  EXPECT_TRUE(r.loop.status().finished_ok);
  EXPECT_EQ(r.loop.status().spindle_waits, 2u);
}

TEST(SpindleLoop, SpindleDriveFaultStopsTheMachineAndResetNeedsItGone) {
  SpindleRig r(spindle_config());
  ASSERT_TRUE(r.enable());
  r.bus.inject_spindle_fault(true);
  r.step(2);
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
  EXPECT_EQ(r.loop.status().cause, FaultCause::kSpindleFault);
  r.loop.post({CommandKind::kReset});
  r.step(300);  // the reset window (250 cycles) passes: refused
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
  r.bus.inject_spindle_fault(false);
  r.loop.post({CommandKind::kReset});
  r.step(20);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(SpindleLoop, StalledSpindleFaultsAfterTheTimeoutWithoutMovingTheAxes) {
  auto cfg = spindle_config();
  cfg.spindle.at_speed_timeout_s = 1.0;
  SpindleRig r(cfg);
  ASSERT_TRUE(r.enable());
  r.bus.inject_spindle_stall(true);
  r.load("G21 G90\nM3 S3000\nG01 X5 F600\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  const Trace t = run_until_done(r, 5000);
  const auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kSpindleNotAtSpeed);
  EXPECT_EQ(st.fault_limit, 3000.0);  // the target it waited for
  EXPECT_EQ(t.motion_cycle, -1) << "an axis moved";
  EXPECT_NEAR(st.act_mm[0], 0.0, 1e-3);
  // Reset, spindle repaired, run again: it waits (0.7 s to 1000 rpm, within the 1 s) and cuts.
  r.bus.inject_spindle_stall(false);
  r.loop.post({CommandKind::kReset});
  r.step(20);
  ASSERT_EQ(r.loop.status().state, MachineState::kReady);
  r.load("G21 G90\nM3 S1000\nG01 X5 F600\nM2\n", 2);
  r.loop.post({CommandKind::kRun});
  for (int k = 0; k < 20000 && r.loop.status().finished_job != 2; ++k) r.step();
  EXPECT_TRUE(r.loop.status().finished_ok)
      << to_string(r.loop.status().state) << " " << to_string(r.loop.status().cause);
}

TEST(SpindleLoop, RapidRunsWhileTheSpindleAcceleratesThenTheFeedMoveWaits) {
  const auto cfg = spindle_config(3000.0);  // 2 s ramp to 6000 rpm
  SpindleRig r(cfg);
  ASSERT_TRUE(r.enable());
  r.load("G21 G90\nM3 S6000\nG00 X2\nG01 X5 F600\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  const Trace t = run_until_done(r, 20000);
  const auto st = r.loop.status();
  ASSERT_TRUE(st.finished_ok);
  ASSERT_GE(t.motion_cycle, 0);
  EXPECT_LT(t.rpm_at_motion, 1000.0) << "the rapid should start with the spindle still slow";
  EXPECT_EQ(st.spindle_waits, 1u);
  EXPECT_TRUE(t.waited);
}

TEST(SpindleLoop, AtSpeedWaitForceOnlyDoesNotWaitWithoutForceControl) {
  auto cfg = spindle_config();
  cfg.spindle.at_speed_wait = config::SpindleConfig::Wait::kForce;
  SpindleRig r(cfg);
  ASSERT_TRUE(r.enable());
  r.load("G21 G90\nM3 S6000\nG01 X5 F600\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  const Trace t = run_until_done(r, 20000);
  EXPECT_TRUE(r.loop.status().finished_ok);
  EXPECT_FALSE(t.waited);
  EXPECT_EQ(r.loop.status().spindle_waits, 0u);
  EXPECT_LT(t.rpm_at_motion, 1000.0);
}

TEST(SpindleLoop, SpeedIsClampedToTheLimitsAndRateLimited) {
  auto cfg = spindle_config(6000.0);
  cfg.spindle.limits.max_rpm = 8000.0;
  cfg.spindle.limits.min_rpm = 500.0;
  SpindleRig r(cfg);
  ASSERT_TRUE(r.enable());
  r.load("G21 G90\nM3 S20000\nG01 X1 F600\nS100\nG01 X2\nM4 S3000\nG01 X3\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  double max_step = 0.0, prev = 0.0, max_target = 0.0, min_target = 1e9, neg = 0.0;
  for (int k = 0; k < 40000 && r.loop.status().finished_job != 1; ++k) {
    r.step();
    const auto st = r.loop.status();
    max_step = std::max(max_step, std::abs(st.spindle_rpm_cmd - prev));
    prev = st.spindle_rpm_cmd;
    if (st.spindle_target_rpm > 0.0) {
      max_target = std::max(max_target, st.spindle_target_rpm);
      min_target = std::min(min_target, st.spindle_target_rpm);
    }
    neg = std::min(neg, st.spindle_target_rpm);
  }
  EXPECT_TRUE(r.loop.status().finished_ok);
  EXPECT_EQ(max_target, 8000.0);  // S20000 -> max_rpm
  EXPECT_EQ(min_target, 500.0);   // S100 -> min_rpm
  EXPECT_EQ(neg, -3000.0);        // M4: negative
  EXPECT_LE(max_step, 6000.0 * 0.001 + 1e-9);  // rate_rpm_s per 1 ms cycle, also through 0
  EXPECT_EQ(r.loop.status().spindle_waits, 3u);
}

// Spindle override (`override spindle_percent`): scales the programmed S, within the configured
// range (config/sim.yaml: 50..150 %); the at-speed wait is judged on the overridden speed; a
// change mid-program retargets the spindle at its rate limit.
TEST(SpindleLoop, SpindleOverrideScalesTheProgrammedSpeedAndTheWaitUsesIt) {
  auto cfg = spindle_config(6000.0);
  ASSERT_EQ(cfg.spindle.override_max_percent, 150.0);
  SpindleRig r(cfg);
  ASSERT_TRUE(r.enable());
  r.loop.post({CommandKind::kSetOverride, kOverrideSpindle, 3.0, 0.0});  // clamped to 150 %
  r.step();
  EXPECT_EQ(r.loop.status().spindle_override, 1.5);
  r.loop.post({CommandKind::kSetOverride, kOverrideSpindle, 0.1, 0.0});  // clamped to 50 %
  r.step();
  EXPECT_EQ(r.loop.status().spindle_override, 0.5);
  r.loop.post({CommandKind::kSetOverride, kOverrideSpindle, 1.2, 0.0});
  const auto job1 = r.load("G21 G90\nM3 S4000\nG01 X5 F600\nM5\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  r.step(400);  // into the wait (the ramp to 4800 rpm takes 0.8 s)
  EXPECT_TRUE(r.loop.status().spindle_waiting);
  EXPECT_EQ(r.loop.status().spindle_target_rpm, 4800.0);  // 4000 x 120 %
  const Trace t2 = run_until_done(r, 20000);
  auto st = r.loop.status();
  ASSERT_TRUE(st.finished_ok) << to_string(st.state) << " " << to_string(st.cause);
  // The feed started at the overridden speed: within max(50, 2 % of 4800) = 96 rpm of 4800.
  EXPECT_GE(t2.rpm_at_motion, 4800.0 - 96.0);
  EXPECT_EQ(st.spindle_waits, 1u);
  // Mid-program change: 60 % of S3000 while cutting.
  const auto job2 = r.load("G21 G90\nM3 S3000\nG01 X0 F100\nM5\nM2\n", 2);
  r.loop.post({CommandKind::kRun});
  r.step(1500);
  ASSERT_EQ(r.loop.status().attached_job, 2u);
  ASSERT_EQ(r.loop.status().spindle_target_rpm, 3600.0);
  r.loop.post({CommandKind::kSetOverride, kOverrideSpindle, 0.6, 0.0});
  r.step();
  r.step();
  st = r.loop.status();
  EXPECT_EQ(st.spindle_target_rpm, 1800.0);
  EXPECT_EQ(st.spindle_override, 0.6);
}

TEST(SpindleLoop, VfdSpindleOverModbusGetsTheCommandAndGatesTheFeed) {
  // spindle.type modbus_vfd: the loop's rate-limited command goes to the VFD thread (IoChannels),
  // the VFD's actual-speed register gates the feed move; a stalled VFD faults at the timeout.
  contour::test::SimVfd vfd;
  auto cfg = spindle_config();
  cfg.spindle.type = "modbus_vfd";
  cfg.spindle.at_speed_timeout_s = 2.0;
  auto& v = cfg.spindle.vfd;
  v.transport.transport = drivers::modbus::Transport::kTcp;
  v.transport.host = "127.0.0.1";
  v.transport.port = vfd.port();
  v.setpoint_register = 0;
  v.run_address = 1;
  v.actual_register = 2;
  v.setpoint_counts_per_rpm = 0.5;
  v.actual_counts_per_rpm = 0.5;
  v.update_rate_hz = 100;
  IoChannels io(cfg);
  io.start({});
  Rig r(cfg, &io);  // no SimBus spindle: the only speed feedback is the VFD's register
  ASSERT_TRUE(r.enable());
  r.load("G21 G90\nM3 S3000\nG01 X5 F600\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  int motion = -1;
  double vfd_rpm_at_motion = 0.0;
  for (int k = 0; k < 20000 && r.loop.status().finished_job != 1; ++k) {
    r.step();
    const auto st = r.loop.status();
    if (motion < 0 && st.ref_mm[0] != 0.0) {
      motion = k;
      vfd_rpm_at_motion = vfd.setpoint.load() / 0.5;
      EXPECT_GE(st.spindle_actual_rpm, 3000.0 - 60.0);
    }
    std::this_thread::sleep_for(std::chrono::microseconds(500));  // the VFD thread runs on wall time
  }
  const auto st = r.loop.status();
  EXPECT_TRUE(st.finished_ok) << to_string(st.state) << " " << to_string(st.cause);
  EXPECT_GT(motion, 0);
  // The VFD register (its own ramp, polled at 100 Hz) within the at-speed band of 3000 rpm.
  EXPECT_GE(vfd_rpm_at_motion, 3000.0 - 60.0);
  EXPECT_EQ(vfd.run_cmd.load(), 1);      // forward
  EXPECT_EQ(st.spindle_waits, 1u);
  EXPECT_TRUE(st.spindle_feedback);
  // Stalled: the next feed move after a speed change times out.
  vfd.stall = true;
  r.load("G21 G90\nM3 S4000\nG01 X0 F600\nM2\n", 2);
  r.loop.post({CommandKind::kRun});
  for (int k = 0; k < 4000 && r.loop.status().state != MachineState::kFault; ++k) {
    r.step();
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
  EXPECT_EQ(r.loop.status().cause, FaultCause::kSpindleNotAtSpeed);
  io.stop();
  EXPECT_EQ(vfd.run_cmd.load(), 0);  // shutdown stops the spindle
}

}  // namespace
}  // namespace contour::daemon
