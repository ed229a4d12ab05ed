// ServoLoop on the simulated bus: no allocation over 10k cycles, program execution, hold/resume on
// the path, stop, E-stop/reset, drive fault, gains swap at a cycle boundary.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "config/config.hpp"
#include "daemon/offline_run.hpp"
#include "daemon/planner.hpp"
#include "daemon/servo_loop.hpp"
#include "daemon/sim_bus.hpp"
#include "daemon/telemetry.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;
using test_rig::sim_config;

const char* kSquare =
    "G21 G90 G17 G64 P0.02\nG01 X20 Y0 F3000\nG01 X20 Y20\nG01 X0 Y20\nG01 X0 Y0\nM2\n";

TEST(ServoLoop, NoAllocationOver10kCyclesRunningAProgram) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  auto job = r.load(kSquare, 1);
  r.loop.post({CommandKind::kRun});
  r.step(3);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  RtEvent e;
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int i = 0; i < 10000; ++i) {
      r.loop.cycle();
      while (r.loop.events().pop(e)) {}  // POD pop: no allocation
      TelemetrySample s;
      while (r.loop.telemetry().pop(s)) {}
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  // The square (80 mm at 3 m/min = 1.6 s + FIR + settling) has finished inside the 10k cycles.
  EXPECT_EQ(r.loop.status().finished_job, 1u);
  EXPECT_TRUE(r.loop.status().finished_ok);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(ServoLoop, RunsTable2AndEndsInPositionWithBoundedContourError) {
  const auto cfg = sim_config();
  const char* csv = std::getenv("CONTOUR_TEST_CSV");  // optional trace for inspection
  const auto res = run_offline(cfg, {"table2.ngc", std::string(CONTOUR_SOURCE_DIR) + "/config/programs/table2.ngc", ""},
                               2'000'000, csv != nullptr ? csv : "");
  EXPECT_TRUE(res.finished_ok);
  EXPECT_EQ(res.state, "READY");
  EXPECT_GT(res.stats.samples, 1000u);
  EXPECT_GT(res.stats.max_contour_error_um, 0.0);
  EXPECT_LT(res.stats.max_contour_error_um, 100.0);  // G64 P50 blend + servo error
  EXPECT_LE(res.stats.rms_contour_error_um(), res.stats.max_contour_error_um);
  EXPECT_EQ(res.underruns, 0u);
  // Deterministic: a second run gives bit-identical figures.
  const auto res2 = run_offline(cfg, {"table2.ngc", std::string(CONTOUR_SOURCE_DIR) + "/config/programs/table2.ngc", ""});
  EXPECT_EQ(res.stats.max_contour_error_um, res2.stats.max_contour_error_um);
  EXPECT_EQ(res.stats.sum_sq_um2, res2.stats.sum_sq_um2);
}

TEST(ServoLoop, HoldDeceleratesOnThePathAndResumeContinues) {
  const auto cfg = sim_config();
  // Reference run without hold.
  Rig a(cfg);
  ASSERT_TRUE(a.enable());
  a.load(kSquare, 1);
  a.loop.post({CommandKind::kRun});
  for (int i = 0; i < 20000 && a.loop.status().finished_job != 1; ++i) a.step();
  a.writer.drain();
  const double free_max = a.writer.stats(1).max_contour_error_um;

  Rig r(cfg);
  ASSERT_TRUE(r.enable());
  r.load(kSquare, 1);
  r.loop.post({CommandKind::kRun});
  r.step(500);  // on the first edge at full feed
  r.loop.post({CommandKind::kHold});
  r.step(1);
  EXPECT_EQ(r.loop.status().state, MachineState::kHold);
  r.step(600);  // FIR ramp (100 ms) + settling
  const auto h1 = r.loop.status();
  r.step(200);
  const auto h2 = r.loop.status();
  EXPECT_EQ(h1.ref_mm, h2.ref_mm) << "reference must stand still in HOLD";
  EXPECT_LT(std::abs(h2.act_mm[0] - h2.ref_mm[0]), 0.01);
  EXPECT_GT(h2.progress_mm, 1.0);
  EXPECT_LT(h2.progress_mm, 79.0);
  r.loop.post({CommandKind::kResume});
  for (int i = 0; i < 20000 && r.loop.status().finished_job != 1; ++i) r.step();
  r.writer.drain();
  EXPECT_TRUE(r.loop.status().finished_ok);
  const double hold_max = r.writer.stats(1).max_contour_error_um;
  // Hold/resume stays on the path: the true contour error is no worse than the blend tolerance
  // (20 um) plus the free run's servo error.
  EXPECT_LT(hold_max, free_max + 20.0) << "free " << free_max << " um, with hold " << hold_max;
}

TEST(ServoLoop, StopDeceleratesAndFlushes) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  auto job = r.load(kSquare, 7);
  r.loop.post({CommandKind::kRun});
  r.step(400);
  r.loop.post({CommandKind::kStop});
  for (int i = 0; i < 2000 && r.loop.status().state != MachineState::kReady; ++i) r.step();
  const auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kReady);
  EXPECT_EQ(st.finished_job, 7u);
  EXPECT_FALSE(st.finished_ok);
  EXPECT_EQ(st.attached_job, 0u);
  EXPECT_TRUE(job->abort.load());
  // A new run without a program is refused.
  r.loop.post({CommandKind::kRun});
  r.step(2);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(ServoLoop, EstopIsImmediateAndResetReEnables) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  r.load(kSquare, 1);
  r.loop.post({CommandKind::kRun});
  r.step(400);
  r.loop.post({CommandKind::kEstop});
  r.step(1);
  auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kEstop);
  EXPECT_EQ(st.cause, FaultCause::kEstopCommand);
  EXPECT_EQ(st.cmd_mm_s[0], 0.0);
  EXPECT_EQ(st.cmd_mm_s[1], 0.0);
  r.step(5);
  EXPECT_FALSE(r.loop.status().drives_enabled);
  r.loop.post({CommandKind::kRun});
  r.step(2);
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop);
  r.loop.post({CommandKind::kReset});
  r.step(10);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(ServoLoop, DriveFaultFaultsWithCauseAndResetNeedsTheCauseGone) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  r.bus.inject_drive_fault(1, true);
  r.step(2);
  auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kDriveFault);
  EXPECT_EQ(st.fault_axis, 1);
  r.loop.post({CommandKind::kReset});
  r.step(3);
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
  r.bus.inject_drive_fault(1, false);
  r.loop.post({CommandKind::kReset});
  r.step(10);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(ServoLoop, TheCycleThatReachesReadyAlreadyCommandsTheDrivesEnabled) {
  // Regression: READY was judged before the ENABLING -> READY step, so that cycle wrote
  // "disabled" and the drives dropped out of operation enabled right after READY.
  Rig r(sim_config());
  r.loop.post({CommandKind::kEnable});
  int ready_at = -1;
  for (int k = 0; k < 20; ++k) {
    r.step();
    const bool ready = r.loop.status().state == MachineState::kReady;
    if (ready && ready_at < 0) ready_at = k;
    if (ready) {
      EXPECT_EQ(r.bus.written_mode(), DriveMode::kEnabled) << "cycle " << k << ", READY at " << ready_at;
    }
  }
  ASSERT_GE(ready_at, 0);
  EXPECT_TRUE(r.loop.status().drives_enabled);
}

TEST(ServoLoop, ADriveLeavingOperationEnabledWithoutAFaultStopsTheMachine) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  r.step(20);
  ASSERT_EQ(r.loop.status().state, MachineState::kReady);
  r.bus.inject_drive_disabled(2, true);
  r.step(2);
  auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kDriveDisabled);
  EXPECT_EQ(st.fault_axis, 2);
  // Reset while the drive stays disabled: the loop waits in ENABLING, never READY.
  r.loop.post({CommandKind::kReset});
  r.step(50);
  EXPECT_NE(r.loop.status().state, MachineState::kReady);
  r.bus.inject_drive_disabled(2, false);
  r.step(10);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(ServoLoop, FollowingErrorFaultsWhenTheGainIsTooLow) {
  auto cfg = sim_config();
  Rig r(cfg);
  ASSERT_TRUE(r.enable());
  // Gains staged while READY, swapped at the next cycle boundary.
  auto p = r.loop.active_params();
  for (auto& a : p.axis) a.kp = 0.01;
  p.coupling.enable = false;
  const auto before = r.loop.status().cycle;
  const auto gen = r.loop.stage_gains(p);
  r.step(1);
  auto st = r.loop.status();
  EXPECT_EQ(st.gains_generation, gen);
  EXPECT_EQ(st.gains_cycle, before + 1);  // the first cycle after staging
  EXPECT_DOUBLE_EQ(r.loop.active_params().axis[0].kp, 0.01);
  r.load(kSquare, 1);
  r.loop.post({CommandKind::kRun});
  r.step(1);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  for (int i = 0; i < 5000 && r.loop.status().state == MachineState::kRunning; ++i) r.step();
  st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kFollowingError);
  EXPECT_GT(st.fault_value, st.fault_limit);
  // The controlled stop ramps the command to zero and disables the drives.
  r.step(2000);
  EXPECT_EQ(r.loop.status().cmd_mm_s[0], 0.0);
  EXPECT_FALSE(r.loop.status().drives_enabled);
}

TEST(ServoLoop, JogMovesTheAxisByTheDistance) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  r.loop.post({CommandKind::kJog, 2, 10.0, -1.5});
  r.step(3000);
  const auto st = r.loop.status();
  EXPECT_FALSE(st.jogging);
  EXPECT_DOUBLE_EQ(st.ref_mm[2], -1.5);
  EXPECT_NEAR(st.act_mm[2], -1.5, 0.002);
}

TEST(ServoLoop, SetPositionAndAJogStopsAtTheSoftLimit) {
  Rig r(sim_config());
  ASSERT_TRUE(r.enable());
  r.loop.post({CommandKind::kSetPosition, 0, 199.0, 0.0});
  r.step(3);
  EXPECT_DOUBLE_EQ(r.loop.status().act_mm[0], 199.0);
  EXPECT_DOUBLE_EQ(r.loop.status().ref_mm[0], 199.0);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  // A jog past the +200 mm limit (the socket handler refuses it; the loop checks anyway). Until
  // issue 16/18 the loop let the reference run past the limit and faulted; a jog now stays inside
  // the soft limits and stops at the limit (deliberate contract change).
  r.loop.post({CommandKind::kJog, 0, 20.0, 5.0});
  for (int i = 0; i < 3000 && (i < 5 || r.loop.status().jogging); ++i) r.step();
  const auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kReady);
  EXPECT_FALSE(st.jogging);
  EXPECT_DOUBLE_EQ(st.ref_mm[0], 200.0);
  // A jog from outside a limit moves back in, never further out, and is never turned around.
  r.loop.post({CommandKind::kJog, 0, 20.0, -3.0});
  for (int i = 0; i < 3000 && (i < 5 || r.loop.status().jogging); ++i) r.step();
  EXPECT_NEAR(r.loop.status().ref_mm[0], 197.0, 1e-9);
}

TEST(Planner, LoadErrorsNameFileLineColumnAndSoftLimits) {
  const auto cfg = sim_config();
  ProgramPlanner p(cfg);
  try {
    p.validate({"bad.ngc", "", "G21 G90\nG01 X1 Q5 F100\n"}, Eigen::Vector3d::Zero());
    FAIL() << "no error";
  } catch (const ProgramError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.ngc:2:"), std::string::npos) << e.what();
  }
  try {
    p.validate({"far.ngc", "", "G21 G90\nG01 X10 F100\nG01 X500\nM2\n"}, Eigen::Vector3d::Zero());
    FAIL() << "no error";
  } catch (const ProgramError& e) {
    EXPECT_NE(std::string(e.what()).find("far.ngc:3:1: soft limit"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace contour::daemon

namespace contour::daemon {
namespace {

// Issue 16: `disable` (and SIGTERM, which disables) never sends "disable voltage" while an axis
// moves: a jog at 40 mm/s is ramped down first, the drives stay enabled with a zero command until
// the axes stand still, then they are disabled.
TEST(ServoLoop, DisableWhileJoggingRampsDownAndSwitchesOffOnlyAtStandstill) {
  Rig r(test_rig::sim_config());
  ASSERT_TRUE(r.enable());
  r.loop.post({CommandKind::kJog, 0, 40.0, 100.0});
  r.step(400);  // at speed
  ASSERT_TRUE(r.loop.status().jogging);
  r.loop.post({CommandKind::kDisable});
  BusFeedback fb;
  double prev = 1e9;
  bool off = false;
  for (int k = 0; k < 3000 && !off; ++k) {
    r.step();
    r.bus.read(fb);
    const auto st = r.loop.status();
    if (st.state != MachineState::kDisabled) continue;
    EXPECT_LE(std::abs(st.cmd_mm_s[0]), prev + 1e-9) << k;
    prev = std::abs(st.cmd_mm_s[0]);
    if (r.bus.written_mode() == DriveMode::kDisabled) {
      off = true;
      EXPECT_LT(std::abs(fb.axis[0].velocity_mm_s), r.cfg.safety.standstill_velocity_mm_s);
      EXPECT_EQ(st.stop_phase, StopSource::Phase::kOff);
    } else {
      EXPECT_EQ(st.source, SourceKind::kStop);
    }
  }
  EXPECT_TRUE(off);
}

}  // namespace
}  // namespace contour::daemon
