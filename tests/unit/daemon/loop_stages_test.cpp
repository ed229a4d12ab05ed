// The servo cycle as a pipeline (daemon/servo_loop.hpp): the loop chooses one reference source
// per cycle (hold, jog, program, stop), and no stage or source allocates, whichever is active.
#include <gtest/gtest.h>

#include <array>

#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;
using test_rig::sim_config;

TEST(LoopStages, EachStateRunsItsReferenceSourceAndNoneAllocates) {
  Rig r(sim_config());
  std::array<bool, 4> seen{};  // by SourceKind (no allocation inside the guard)
  std::size_t allocs = 0;
  auto run = [&](int n) {
    RtEvent e;
    TelemetrySample s;
    test::AllocGuard g;
    for (int i = 0; i < n; ++i) {
      r.loop.cycle();
      seen[static_cast<std::size_t>(r.loop.status().source)] = true;
      while (r.loop.events().pop(e)) {}
      while (r.loop.telemetry().pop(s)) {}
    }
    allocs += g.counts().total();
  };
  run(3);  // DISABLED: hold, following the measured position
  EXPECT_EQ(r.loop.status().source, SourceKind::kHold);
  r.loop.post({CommandKind::kEnable});
  run(5);
  ASSERT_EQ(r.loop.status().state, MachineState::kReady);
  r.loop.post({CommandKind::kJog, 0, 20.0, 2.0});  // X +2 mm at 20 mm/s
  run(2);
  EXPECT_EQ(r.loop.status().source, SourceKind::kJog);
  run(400);
  EXPECT_FALSE(r.loop.status().jogging);
  EXPECT_EQ(r.loop.status().source, SourceKind::kHold);
  EXPECT_NEAR(r.loop.status().ref_mm[0], 2.0, 1e-9) << "the hold keeps the jog's end";
  auto job = r.load("G21 G90 G1 X10 Y5 F3000\nG1 X0 Y0\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  run(300);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  EXPECT_EQ(r.loop.status().source, SourceKind::kProgram);
  // A drive fault mid-program: the stop source ramps the command down, then disables.
  r.bus.inject_drive_fault(1, true);
  run(1);
  ASSERT_EQ(r.loop.status().state, MachineState::kFault);
  run(300);
  EXPECT_EQ(r.loop.status().source, SourceKind::kStop);
  r.bus.inject_drive_fault(1, false);
  r.loop.post({CommandKind::kReset});
  run(20);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  r.loop.post({CommandKind::kEstop});
  run(5);
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop);
  EXPECT_EQ(r.loop.status().source, SourceKind::kHold);
  for (std::size_t k = 0; k < seen.size(); ++k) {
    EXPECT_TRUE(seen[k]) << "source " << to_string(static_cast<SourceKind>(k)) << " never ran";
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
