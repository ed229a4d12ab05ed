// Homing by the drive (issue 18, home.method drive = CiA 402 homing mode 6): HomingSource's
// `drive` phase against a scripted drive (fake feedback), and the servo loop homing the
// simulated machine whose drives perform mode 6 themselves (SimBus::configure_drive_homing).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

constexpr double kT = 0.001;

LiveLimits limits() {
  LiveLimits l;
  l.max_velocity_mm_s = {100.0, 100.0, 50.0};
  l.max_accel_mm_s2 = {1000.0, 1000.0, 500.0};
  return l;
}

HomingSource::AxisPlan drive_plan(int sequence, double offset, double position, double timeout_s = 60.0) {
  HomingSource::AxisPlan p;
  p.home = true;
  p.sequence = sequence;
  p.search_mm_s = 20.0;
  p.latch_mm_s = 1.0;
  p.offset_mm = offset;
  p.position_mm = position;
  p.search_distance_mm = 100.0;
  p.drive = true;
  p.drive_timeout_s = timeout_s;
  return p;
}

// A drive that homes itself when asked: it moves at -10 mm/s for `run_cycles`, then its position
// jumps so that it reads 0 at the home point, which is `home_true_mm` of true travel, and it
// reports `result` (the loop's coordinates are the bus' plus `shift`).
struct ScriptedDrive {
  int run_cycles = 300;
  double home_true_mm = -2.5;
  DriveHoming result = DriveHoming::kAttained;
  double true_mm = 0.0;
  double zero_mm = 0.0;  // true position where the drive's position reads 0
  double shift = 0.0;
  int running = 0;
  bool requested = false;
  Feedback fb;
  ScriptedDrive() {
    fb.bus.axis[0].drive_homing_present = true;
    fb.bus.axis[0].fresh = true;
  }
  // One SYNC: the request of the last cycle acts; feedback of the new position.
  void step(bool request) {
    AxisFeedback& ax = fb.bus.axis[0];
    if (request && !requested) running = run_cycles;
    requested = request;
    ax.velocity_mm_s = 0.0;
    if (!request) {
      ax.drive_homing = DriveHoming::kIdle;
    } else if (running > 0) {
      --running;
      true_mm -= 10.0 * kT;
      ax.velocity_mm_s = -10.0;
      ax.drive_homing = DriveHoming::kRunning;
      if (running == 0) {
        ax.drive_homing = result;
        if (result == DriveHoming::kAttained) zero_mm = home_true_mm;
      }
    }
    ax.position_mm = true_mm - zero_mm;
    fb.act_mm[0] = ax.position_mm + shift;
  }
};

TEST(DriveHomingSource, TheReferenceFollowsTheDriveThenItsHomePointBecomesTheOffset) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = drive_plan(0, -199.5, -190.0);
  ScriptedDrive d;
  d.shift = 7.0;  // a previous homing's shift: the latch is in the loop's coordinates
  d.step(false);
  h.start(p, 3, d.fb.act_mm);
  ASSERT_TRUE(h.active());
  EXPECT_EQ(h.phase(0), HomingSource::Phase::kDrive);
  bool shifted = false;
  double max_err = 0.0;
  int requested_cycles = 0;
  Eigen::Vector3d ref = d.fb.act_mm;
  for (int n = 0; n < 100000 && h.active(); ++n) {
    const bool req = h.drive_home_request(0);
    requested_cycles += req ? 1 : 0;
    d.step(req);
    RefPoint r = h.step(d.fb, limits(), kT);
    if (h.phase(0) == HomingSource::Phase::kDrive) {
      // The loop never fights the drive: its reference is where the drive is.
      max_err = std::max(max_err, std::abs(r.position_mm[0] - d.fb.act_mm[0]));
      EXPECT_TRUE(h.drive_moves(0));
    }
    if (h.shift_pending()) {
      // The drive reads 0 at its home point: that point, in loop coordinates, is the latch.
      EXPECT_NEAR(h.latch_mm(0), d.shift, 1e-12);
      const double s = h.offset_mm(0) - h.latch_mm(0);
      d.shift += s;
      r.position_mm[0] += s;
      d.fb.act_mm[0] += s;
      h.shifted(r.position_mm);
      shifted = true;
      // Machine position = the drive's position + home_offset_mm: the true home point reads -199.5.
      EXPECT_NEAR(d.fb.act_mm[0], (d.true_mm - d.home_true_mm) - 199.5, 1e-9);
    }
    ref = r.position_mm;
    // An ideal axis for the final move: it is where the reference was.
    if (!h.drive_moves(0) && shifted) d.true_mm = ref[0] - d.shift + d.zero_mm;
  }
  EXPECT_FALSE(h.active());
  EXPECT_FALSE(h.failed());
  EXPECT_TRUE(shifted);
  EXPECT_EQ(max_err, 0.0);
  EXPECT_EQ(requested_cycles, d.run_cycles);  // the request drops at "attained"
  EXPECT_EQ(h.phase(0), HomingSource::Phase::kDone);
  EXPECT_NEAR(ref[0], -190.0, 1e-9);
}

struct FailCase {
  DriveHoming result;
  bool present;
  double timeout_s;
  std::uint8_t code;
};

TEST(DriveHomingSource, DriveErrorsTimeoutsAndBusesThatCannotFailWithTheirCode) {
  const FailCase cases[] = {
      {DriveHoming::kError, true, 60.0, 10},        // statusword bit 13
      {DriveHoming::kUnsupported, true, 60.0, 11},  // SDO abort on a homing object
      {DriveHoming::kRunning, true, 0.2, 9},        // never attained: the timeout
      {DriveHoming::kAttained, false, 60.0, 8},     // the bus cannot ask the drive
  };
  for (const FailCase& c : cases) {
    HomingSource h;
    std::array<HomingSource::AxisPlan, kMaxAxes> p{};
    p[0] = drive_plan(0, 0.0, 0.0, c.timeout_s);
    ScriptedDrive d;
    d.result = c.result;
    d.run_cycles = c.result == DriveHoming::kRunning ? 1000000 : 50;
    d.fb.bus.axis[0].drive_homing_present = c.present;
    if (c.result == DriveHoming::kUnsupported) d.fb.bus.axis[0].drive_homing_detail = 0x609800;
    d.step(false);
    h.start(p, 3, d.fb.act_mm);
    bool stop_phase = false;
    int n = 0;
    for (; n < 100000 && h.active(); ++n) {
      d.step(h.drive_home_request(0));
      const RefPoint r = h.step(d.fb, limits(), kT);
      // Following the drive to rest after the failure, never a reference of its own.
      if (h.phase(0) == HomingSource::Phase::kDriveStop) {
        stop_phase = true;
        EXPECT_FALSE(h.drive_home_request(0));
        EXPECT_EQ(r.position_mm[0], d.fb.act_mm[0]);
      }
    }
    EXPECT_FALSE(h.active()) << int(c.code);
    ASSERT_TRUE(h.failed()) << int(c.code);
    EXPECT_EQ(h.failure_code(), c.code);
    EXPECT_EQ(h.failed_axis(), 0);
    if (c.code == 11) {
      EXPECT_EQ(h.failure_value(), static_cast<double>(0x609800));
    }
    if (c.code == 9) {
      EXPECT_GT(h.failure_value(), 0.2);
      EXPECT_LT(n, 260);
    }
    EXPECT_TRUE(stop_phase || c.code == 8) << int(c.code);
    EXPECT_NE(std::string(homing_failure_text(c.code)), homing_failure_text(5));
  }
  EXPECT_NE(std::string(homing_failure_text(11)).find("SDO abort"), std::string::npos);
  EXPECT_NE(std::string(homing_failure_text(10)).find("bit 13"), std::string::npos);
  EXPECT_NE(std::string(homing_failure_text(9)).find("drive_timeout_s"), std::string::npos);
}

TEST(DriveHomingSource, AbortWhileTheDriveMovesFollowsItToRest) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = drive_plan(0, 0.0, 0.0);
  ScriptedDrive d;
  d.run_cycles = 100000;
  d.step(false);
  h.start(p, 3, d.fb.act_mm);
  for (int n = 0; n < 100; ++n) {
    d.step(h.drive_home_request(0));
    h.step(d.fb, limits(), kT);
  }
  h.abort();
  EXPECT_EQ(h.phase(0), HomingSource::Phase::kDriveStop);
  // The drive still reports motion for a few cycles after the request dropped.
  d.step(false);
  d.fb.bus.axis[0].velocity_mm_s = -5.0;
  h.step(d.fb, limits(), kT);
  EXPECT_TRUE(h.active());
  d.step(false);
  h.step(d.fb, limits(), kT);
  EXPECT_FALSE(h.active());
  EXPECT_FALSE(h.failed());
  EXPECT_EQ(h.phase(0), HomingSource::Phase::kIdle);
}

TEST(DriveHomingSource, NoAllocationInStep) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = drive_plan(0, 0.0, 0.0);
  ScriptedDrive d;
  d.run_cycles = 1000;
  d.step(false);
  h.start(p, 3, d.fb.act_mm);
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 3000; ++n) {
      d.step(h.drive_home_request(0));
      h.step(d.fb, limits(), kT);
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

// ---- The loop on config/sim.yaml's machine, X homed by its drive (mode 6).

config::Config drive_config(int method) {
  config::Config c = test_rig::sim_config();
  c.machine.allow_unhomed = false;
  c.machine.axes[0].sim_power_up_mm = -150.0;
  c.machine.axes[1].sim_power_up_mm = 120.0;
  c.machine.axes[2].sim_power_up_mm = -80.0;
  config::HomeConfig& h = c.machine.axes[0].home;
  h.method = config::HomeConfig::Method::kDrive;
  h.drive_method = method;
  h.search_vel_mm_s = 20.0;
  h.latch_vel_mm_s = 1.0;
  h.drive_accel_mm_s2 = 500.0;
  h.drive_timeout_s = 60.0;
  h.home_offset_mm = -199.5;  // the home switch's release point, true (sim: min_mm + 0.5)
  h.home_position_mm = -190.0;
  return c;
}

struct LoopRun {
  bool ended = false;
  bool saw_drive_phase = false;
  double max_abs_cmd_x = 0.0;  // velocity the loop commanded on X while the drive homed
  double max_err_x = 0.0;      // |ref - act| on X while the drive homed
};

LoopRun home_all(test_rig::Rig& rig, int axis = -1) {
  LoopRun out;
  rig.loop.post({CommandKind::kHome, axis});
  rig.step(3);
  for (int n = 0; n < 400000 && rig.loop.status().homing; ++n) {
    rig.step(1);
    const LoopStatus st = rig.loop.status();
    const auto ph = static_cast<HomingSource::Phase>(st.home_phase[0]);
    if (ph == HomingSource::Phase::kDrive) {
      out.saw_drive_phase = true;
      out.max_abs_cmd_x = std::max(out.max_abs_cmd_x, std::abs(st.cmd_mm_s[0]));
      out.max_err_x = std::max(out.max_err_x, std::abs(st.ref_mm[0] - st.act_mm[0]));
    }
  }
  out.ended = !rig.loop.status().homing;
  return out;
}

TEST(DriveHomingLoop, ModeSixOnTheHomeSwitchLandsOnTheTruePosition) {
  // 21: negative home switch, home where it opens moving up (the sim's switch closes below
  // min_mm + 0.5 = -199.5 true): the same point as method switch's release latch.
  const config::Config cfg = drive_config(21);
  test_rig::Rig rig{cfg};
  configure_sim_machine(rig.bus, cfg);
  ASSERT_TRUE(rig.enable());
  const LoopRun r = home_all(rig);
  ASSERT_TRUE(r.ended) << "homing did not end";
  EXPECT_TRUE(r.saw_drive_phase);
  const LoopStatus st = rig.loop.status();
  EXPECT_EQ(st.homing_failure, 0);
  EXPECT_EQ(st.homed_mask, 7u);
  EXPECT_EQ(st.state, MachineState::kReady)
      << to_string(st.cause) << " axis " << st.fault_axis << ": " << st.fault_value << " / " << st.fault_limit;
  EXPECT_EQ(rig.count(EventKind::kFault), 0u);
  // The loop commanded nothing on X while the drive moved, and its reference was the axis.
  EXPECT_EQ(r.max_abs_cmd_x, 0.0);
  EXPECT_LT(r.max_err_x, 1e-9);
  rig.step(1000);
  // The drive samples its switch each 1 ms period at 1 mm/s (1 um) + the BLU (0.5 um).
  EXPECT_NEAR(rig.loop.status().act_mm[0], rig.bus.true_position_mm(0), 0.0016);
  EXPECT_NEAR(rig.loop.status().ref_mm[0], -190.0, 1e-9);
  EXPECT_NEAR(rig.bus.true_position_mm(0), -190.0, 0.0016);
  for (int i = 1; i < 3; ++i) EXPECT_NEAR(rig.loop.status().act_mm[static_cast<std::size_t>(i)], rig.bus.true_position_mm(i), 0.0016);
}

TEST(DriveHomingLoop, IndexAndCurrentPositionMethods) {
  {
    // 33: the next index below; pulses every 5 mm at 0.25 + 5k true: the first below -150 is
    // -154.75, which home_offset_mm names.
    config::Config cfg = drive_config(33);
    cfg.machine.axes[0].sim_index_pitch_mm = 5.0;
    cfg.machine.axes[0].sim_index_phase_mm = 0.25;
    cfg.machine.axes[0].home.home_offset_mm = -154.75;
    test_rig::Rig rig{cfg};
    configure_sim_machine(rig.bus, cfg);
    ASSERT_TRUE(rig.enable());
    ASSERT_TRUE(home_all(rig, 0).ended);
    EXPECT_EQ(rig.loop.status().homing_failure, 0);
    rig.step(1000);
    // The drive latches the index exactly: the encoder's resolution only.
    EXPECT_NEAR(rig.loop.status().act_mm[0], rig.bus.true_position_mm(0), 0.0006);
  }
  {
    // 35: here is home: the power-up position becomes home_offset_mm.
    config::Config cfg = drive_config(35);
    cfg.machine.axes[0].home.home_offset_mm = -150.0;
    cfg.machine.axes[0].home.home_position_mm = -150.0;
    test_rig::Rig rig{cfg};
    configure_sim_machine(rig.bus, cfg);
    ASSERT_TRUE(rig.enable());
    ASSERT_TRUE(home_all(rig, 0).ended);
    EXPECT_EQ(rig.loop.status().homing_failure, 0);
    EXPECT_EQ(rig.loop.status().homed_mask & 1u, 1u);
    EXPECT_NEAR(rig.loop.status().act_mm[0], rig.bus.true_position_mm(0), 0.0006);
  }
}

TEST(DriveHomingLoop, AMethodThatRunsIntoTheLimitFailsWithTheDrivesErrorAndNoFault) {
  // 19 looks for a home switch on the positive side: the sim has none there, the drive runs into
  // its positive limit switch and reports a homing error (statusword bit 13).
  config::Config cfg = drive_config(19);
  cfg.machine.axes[0].sim_power_up_mm = 190.0;
  test_rig::Rig rig{cfg};
  configure_sim_machine(rig.bus, cfg);
  ASSERT_TRUE(rig.enable());
  const LoopRun r = home_all(rig, 0);
  ASSERT_TRUE(r.ended);
  const LoopStatus st = rig.loop.status();
  EXPECT_EQ(st.homing_failure, 10);
  EXPECT_EQ(st.homing_failure_axis, 0);
  EXPECT_NE(static_cast<std::uint32_t>(st.homing_failure_value) & 0x2000u, 0u);
  EXPECT_EQ(st.homed_mask & 1u, 0u);
  EXPECT_EQ(st.state, MachineState::kReady);
  EXPECT_EQ(rig.count(EventKind::kFault), 0u);
  EXPECT_GT(rig.bus.true_position_mm(0), 202.0);  // it did reach the limit switch
}

TEST(DriveHomingLoop, ADriveWithoutHomingFailsAtOnceNamingTheObject) {
  const config::Config cfg = drive_config(21);
  test_rig::Rig rig{cfg};
  configure_sim_machine(rig.bus, cfg);
  rig.bus.set_drive_homing_supported(0, false);
  ASSERT_TRUE(rig.enable());
  const double before = rig.bus.true_position_mm(0);
  const LoopRun r = home_all(rig, 0);
  ASSERT_TRUE(r.ended);
  const LoopStatus st = rig.loop.status();
  EXPECT_EQ(st.homing_failure, 11);
  EXPECT_EQ(st.homing_failure_value, static_cast<double>(0x609800));
  EXPECT_EQ(st.homed_mask & 1u, 0u);
  EXPECT_EQ(rig.count(EventKind::kFault), 0u);
  EXPECT_NEAR(rig.bus.true_position_mm(0), before, 1e-3);  // never moved
}

TEST(DriveHomingLoop, StopWhileTheDriveHomesStopsTheAxisWithoutAFault) {
  const config::Config cfg = drive_config(21);
  test_rig::Rig rig{cfg};
  configure_sim_machine(rig.bus, cfg);
  ASSERT_TRUE(rig.enable());
  rig.loop.post({CommandKind::kHome, 0});
  rig.step(500);  // searching at 20 mm/s
  ASSERT_TRUE(rig.loop.status().homing);
  rig.loop.post({CommandKind::kStop});
  for (int n = 0; n < 5000 && rig.loop.status().homing; ++n) rig.step(1);
  EXPECT_FALSE(rig.loop.status().homing);
  EXPECT_EQ(rig.loop.status().homing_failure, 5);
  EXPECT_EQ(rig.loop.status().state, MachineState::kReady);
  EXPECT_EQ(rig.count(EventKind::kFault), 0u);
  const double x = rig.bus.true_position_mm(0);
  rig.step(500);
  EXPECT_NEAR(rig.bus.true_position_mm(0), x, 0.01);  // standing, held by the loop
}

}  // namespace
}  // namespace contour::daemon
