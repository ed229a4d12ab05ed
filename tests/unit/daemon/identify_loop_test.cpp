// Drive identification through the servo loop (issue 16, `contourctl identify`): the loop plays
// the excitation on one axis of the in-process simulated machine, the others hold, and the fit of
// the record (control::identify_axis) recovers the SIMULATED drive's gain, time constant and
// delay - also when the simulated drive differs from what config/sim.yaml says (its delay one
// cycle longer, its time constant shorter), which is the point: the delay is measured, not
// taken from the file. Lockstep, no wall clock; no allocation in a cycle of the experiment.
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "control/system_identification.hpp"
#include "loop_rig.hpp"
#include "tests/support/alloc_counter.hpp"

namespace contour::daemon {
namespace {

struct IdRig {
  IdRig(const config::Config& c, std::vector<control::FeedDriveParams> plant)
      : cfg(c), bus(std::move(plant)), loop(cfg, bus) {}
  void step(int n) {
    RtEvent e;
    for (int i = 0; i < n; ++i) {
      loop.cycle();
      while (loop.events().pop(e)) {}
    }
  }
  config::Config cfg;
  SimBus bus;
  ServoLoop loop;
};

control::IdentificationResult identify(IdRig& r, int axis) {
  r.loop.post({CommandKind::kEnable});
  r.step(60);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  const std::uint64_t seq0 = r.loop.status().identify_seq;
  r.loop.post({CommandKind::kIdentify, axis});
  const int n = static_cast<int>(r.loop.identify_excitation().size());
  r.step(n + 5);
  const LoopStatus st = r.loop.status();
  EXPECT_EQ(st.identify_state, IdentifyState::kDone);
  EXPECT_EQ(st.identify_seq, seq0 + 1);
  EXPECT_EQ(st.state, MachineState::kReady);
  control::IdentificationInput in;
  in.period_s = r.cfg.machine.period_s;
  in.command_gain_per_s = r.cfg.machine.axes[static_cast<std::size_t>(axis)].drive.gain_per_s;
  int got_axis = -1;
  EXPECT_TRUE(r.loop.identify_record(got_axis, in.v_cmd_mm_s, in.position_mm));
  EXPECT_EQ(got_axis, axis);
  return control::identify_axis(in);
}

TEST(IdentifyLoop, RecoversTheSimulatedDrivesOfSimYaml) {
  const config::Config cfg = test_rig::sim_config();
  for (int axis = 0; axis < 3; ++axis) {
    const auto plant = test_rig::drives(cfg);
    IdRig r(cfg, plant);
    const control::IdentificationResult id = identify(r, axis);
    const auto& p = plant[static_cast<std::size_t>(axis)];
    SCOPED_TRACE("axis " + std::to_string(axis) + ": " + id.message);
    ASSERT_TRUE(id.ok);
    std::printf("axis %d: K %.3f 1/s (sim %.1f), tau %.3f ms (sim %.1f), delay %d (sim %d), confidence %.2f\n",
                axis, id.gain_per_s, p.gain_per_s, id.tau_s * 1e3, p.tau_s * 1e3, id.delay_cycles,
                p.delay_cycles, id.delay_confidence);
    EXPECT_NEAR(id.gain_per_s, p.gain_per_s, 0.02 * p.gain_per_s);
    EXPECT_NEAR(id.tau_s, p.tau_s, 0.02 * p.tau_s);
    EXPECT_EQ(id.delay_cycles, p.delay_cycles);
    // The other axes held; the axis under test is back at rest near where it started.
    const LoopStatus st = r.loop.status();
    EXPECT_LT(std::abs(st.cmd_mm_s[static_cast<std::size_t>(axis)]), 1.0);
  }
}

TEST(IdentifyLoop, MeasuresADriveThatDiffersFromTheConfig) {
  const config::Config cfg = test_rig::sim_config();  // says delay 1, K 120, tau 30 ms on X
  auto plant = test_rig::drives(cfg);
  plant[0].delay_cycles += 1;  // one cycle more than the file says
  plant[0].tau_s *= 0.8;       // a stiffer velocity loop
  IdRig r(cfg, plant);
  const control::IdentificationResult id = identify(r, 0);
  SCOPED_TRACE(id.message);
  ASSERT_TRUE(id.ok);
  EXPECT_EQ(id.delay_cycles, plant[0].delay_cycles);
  EXPECT_NEAR(id.gain_per_s, plant[0].gain_per_s, 0.02 * plant[0].gain_per_s);
  EXPECT_NEAR(id.velocity_gain, 1.0, 0.02);  // the simulated drive follows its target exactly
  EXPECT_NEAR(id.tau_s, plant[0].tau_s, 0.02 * plant[0].tau_s);
}

TEST(IdentifyLoop, RefusedUnlessReadyAndAbortedByAnEstop) {
  const config::Config cfg = test_rig::sim_config();
  IdRig r(cfg, test_rig::drives(cfg));
  r.loop.post({CommandKind::kIdentify, 0});  // DISABLED: refused
  r.step(5);
  EXPECT_EQ(r.loop.status().identify_state, IdentifyState::kIdle);
  r.loop.post({CommandKind::kEnable});
  r.step(60);
  r.loop.post({CommandKind::kIdentify, 7});  // no such axis
  r.step(5);
  EXPECT_EQ(r.loop.status().identify_state, IdentifyState::kIdle);
  r.loop.post({CommandKind::kIdentify, 1});
  r.step(100);
  EXPECT_EQ(r.loop.status().identify_state, IdentifyState::kRunning);
  r.loop.post({CommandKind::kEstop});
  r.step(5);
  EXPECT_EQ(r.loop.status().identify_state, IdentifyState::kAborted);
  int axis = -1;
  std::vector<double> v, x;
  EXPECT_FALSE(r.loop.identify_record(axis, v, x));
}

TEST(IdentifyLoop, NoAllocationDuringTheExperiment) {
  const config::Config cfg = test_rig::sim_config();
  IdRig r(cfg, test_rig::drives(cfg));
  r.loop.post({CommandKind::kEnable});
  r.step(60);
  r.loop.post({CommandKind::kIdentify, 2});
  r.step(2);
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int i = 0; i < 500; ++i) r.loop.cycle();
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0U);
  EXPECT_EQ(r.loop.status().identify_state, IdentifyState::kRunning);
}

}  // namespace
}  // namespace contour::daemon
