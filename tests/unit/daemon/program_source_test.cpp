// ProgramSource (daemon/reference_sources.hpp) without a loop, a bus or a daemon: the planner's
// job, stepped by the test, with the inputs the state machine would give it.
#include <gtest/gtest.h>

#include <cmath>

#include "daemon/planner.hpp"
#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::sim_config;

struct Prog {
  explicit Prog(const std::string& text) : cfg(sim_config()), planner(cfg) {
    src = ProgramSource(cfg.spindle.limits, cfg.machine.period_s);
    job = planner.start({"<test>", "", text}, Eigen::Vector3d::Zero(), 1,
                        [](std::uint64_t, const control::PlannedSegment&) {});
    ProgramPlanner::wait_prefill(*job, 30.0);
    src.attach(job.get());
    src.start();
  }
  // One cycle as RUNNING at 100 % override with no spindle wait.
  RefPoint step(ProgramStep& s, bool running = true, bool wait = false, bool at_speed = false,
                double target = 0.0) {
    src.drain();
    ProgramSource::Inputs in;
    in.running = running;
    in.override_ratio = 1.0;
    in.wait_for_spindle = wait;
    in.spindle_at_speed = at_speed;
    in.spindle_target_rpm = target;
    return src.step(in, s);
  }
  config::Config cfg;
  ProgramPlanner planner;
  ProgramSource src;
  std::shared_ptr<ProgramJob> job;
};

TEST(ProgramSource, RunsALineToItsEndAndSettlesInPosition) {
  Prog p("G21 G90 G1 X10 F600\nM2\n");
  ProgramStep s;
  RefPoint r;
  int n = 0;
  for (; n < 5000 && !p.src.settling(); ++n) r = p.step(s);
  ASSERT_TRUE(p.src.settling()) << "the interpolator did not finish";
  EXPECT_EQ(r.source, SourceKind::kProgram);
  EXPECT_TRUE(r.track);
  EXPECT_NEAR(r.position_mm.x(), 10.0, 1e-9);
  // 10 mm at 10 mm/s: about 1 s plus the FIR.
  EXPECT_GT(n, 900);
  EXPECT_FALSE(p.src.settled(r.position_mm, Eigen::Vector3d(9.99, 0, 0), 3)) << "10 um away";
  EXPECT_TRUE(p.src.settled(r.position_mm, Eigen::Vector3d(9.999, 0, 0), 3)) << "1 um away";
}

TEST(ProgramSource, M0AsksForAHoldOnlyWhileRunningAndWaitsForResume) {
  Prog p("G21 G90 G1 X1 F600\nM0\nG1 X2\nM2\n");
  ProgramStep s;
  bool asked = false;
  for (int n = 0; n < 3000 && !asked; ++n) {
    p.step(s);
    asked = s.program_hold;
  }
  ASSERT_TRUE(asked);
  EXPECT_EQ(s.status, control::InterpStatus::kHolding);
  // In HOLD (not running) the same status asks nothing, and the reference stands.
  const RefPoint a = p.step(s, false);
  EXPECT_FALSE(s.program_hold);
  const RefPoint b = p.step(s, false);
  EXPECT_EQ(a.position_mm, b.position_mm);
  p.src.resume();
  RefPoint r;
  for (int n = 0; n < 3000 && !p.src.settling(); ++n) r = p.step(s);
  EXPECT_NEAR(r.position_mm.x(), 2.0, 1e-9);
}

TEST(ProgramSource, StopDeceleratesOnThePathThenReportsStoppedAndAbortsThePlanner) {
  Prog p("G21 G90 G1 X100 F3000\nM2\n");
  ProgramStep s;
  for (int n = 0; n < 500; ++n) p.step(s);
  p.src.request_stop();
  EXPECT_TRUE(p.job->abort.load());
  double prev = p.src.output().position_mm.x();
  double prev_v = 1e9;
  int n = 0;
  for (; n < 5000 && !s.stopped; ++n) {
    const RefPoint r = p.step(s);
    const double v = (r.position_mm.x() - prev) / p.cfg.machine.period_s;
    EXPECT_LE(v, prev_v + 1e-9) << "the stop must not speed up (cycle " << n << ")";
    EXPECT_GE(v, -1e-9);
    prev = r.position_mm.x();
    prev_v = v;
  }
  EXPECT_TRUE(s.stopped);
  EXPECT_LT(prev, 100.0);
  EXPECT_EQ(p.src.detach(false), p.job.get());
  EXPECT_FALSE(p.src.attached());
}

TEST(ProgramSource, AFeedMoveAfterM3WaitsUntilTheSpindleIsAtTheMarkersSpeed) {
  Prog p("G21 G90 M3 S3000\nG1 X5 F600\nM2\n");
  ProgramStep s;
  int waited = 0;
  for (int n = 0; n < 200; ++n) {
    const RefPoint r = p.step(s, true, true, false, 0.0);
    if (s.spindle_waiting) ++waited;
    EXPECT_NEAR(r.position_mm.x(), 0.0, 1e-12) << "no motion while the spindle is not at speed";
  }
  EXPECT_EQ(waited, 200);
  EXPECT_EQ(p.src.waited_cycles(), 200);
  EXPECT_NEAR(p.src.programmed_spindle_rpm(), 3000.0, 1e-9);
  // At speed, but of another target: still waiting.
  p.step(s, true, true, true, 1000.0);
  EXPECT_TRUE(s.spindle_waiting);
  p.step(s, true, true, true, 3000.0);
  EXPECT_TRUE(s.spindle_at_speed);
  EXPECT_EQ(p.src.spindle_waits(), 1u);
  EXPECT_NEAR(p.src.last_wait_s(), 201 * p.cfg.machine.period_s, 1e-12);
  RefPoint r;
  for (int n = 0; n < 3000 && !p.src.settling(); ++n) r = p.step(s, true, true, true, 3000.0);
  EXPECT_NEAR(r.position_mm.x(), 5.0, 1e-9);
}

TEST(ProgramSource, WithoutTheWaitPolicyTheMarkerIsPassedAtOnce) {
  Prog p("G21 G90 M3 S3000\nG1 X5 F600\nM2\n");
  ProgramStep s;
  RefPoint r;
  for (int n = 0; n < 3000 && !p.src.settling(); ++n) {
    r = p.step(s, true, false);
    EXPECT_FALSE(s.spindle_waiting);
  }
  EXPECT_NEAR(r.position_mm.x(), 5.0, 1e-9);
  EXPECT_EQ(p.src.spindle_waits(), 0u);
}

TEST(ProgramSource, APlannerFailureAsksForAStopOnce) {
  Prog p("G21 G90 G1 X50 F3000\nM2\n");
  ProgramStep s;
  for (int n = 0; n < 100; ++n) p.step(s);
  p.job->planner_failed.store(true);
  p.step(s);
  EXPECT_TRUE(s.planner_failed);
  EXPECT_TRUE(p.src.stopping());
  p.step(s);
  EXPECT_FALSE(s.planner_failed) << "asked once";
}

TEST(ProgramSource, NoAllocationInDrainAndStep) {
  Prog p("G21 G90 G1 X20 F3000\nG1 Y20\nG1 X0\nG1 Y0\nM2\n");
  ProgramStep s;
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 3000; ++n) p.step(s);
    (void)p.src.settled(p.src.output().position_mm, p.src.output().position_mm, 3);
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
