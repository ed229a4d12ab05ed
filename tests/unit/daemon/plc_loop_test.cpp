// The soft PLC in the servo loop's `logic` stage (issue 20, phase 2): config/sim.yaml's
// example machine logic on the in-process simulated machine, stepped in lockstep. The PLC only
// requests; the state machine acts: door open -> HOLD, resume refused while it is open, allowed
// once it closes; run / jog refused while start is inhibited; an overtravel switch faults the
// axis and the reset is refused until it is released; no allocation in a cycle with the PLC.
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "daemon/event_log.hpp"
#include "daemon/plc_engine.hpp"
#include "loop_rig.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/temp_dir.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;

config::Config sim_plc() { return test_rig::sim_config(); }

bool refused(const Rig& r, CommandKind k, std::size_t from) {
  for (std::size_t i = from; i < r.events.size(); ++i) {
    if (r.events[i].kind == EventKind::kCommandRefused && r.events[i].command == k) return true;
  }
  return false;
}

struct PlcRig {
  PlcRig() : cfg(sim_plc()), rig(cfg), plc(cfg) {
    rig.loop.attach_plc(&plc);
    plc.start();
  }
  ~PlcRig() { plc.stop(); }
  config::Config cfg;
  Rig rig;
  PlcEngine plc;
};

// config/sim.yaml ships the example machine logic (issue 20's "Done when"): five programs, M6
// on the carousel, M100-M102; test support's variants drop it or make M6 a manual change.
TEST(PlcLoop, SimYamlShipsTheExampleMachineLogic) {
  const config::Config cfg = test_rig::sim_config();
  ASSERT_TRUE(cfg.plc.present);
  EXPECT_EQ(cfg.plc.programs.size(), 5u);
  EXPECT_TRUE(cfg.plc.tool_change);
  EXPECT_EQ(cfg.plc.mcodes.size(), 3u);
  const std::string dir = contour::test::process_temp_dir();
  const config::Config manual = config::load_config_file(
      contour::test::write_sim_yaml(dir + "/sim_manual.yaml", contour::test::SimPlc::kManualToolChange));
  EXPECT_TRUE(manual.plc.present);
  EXPECT_FALSE(manual.plc.tool_change);
  const config::Config none = config::load_config_file(
      contour::test::write_sim_yaml(dir + "/sim_noplc.yaml", contour::test::SimPlc::kNone));
  EXPECT_FALSE(none.plc.present);
  EXPECT_EQ(none.machine.axes.size(), cfg.machine.axes.size());
}

TEST(PlcLoop, DoorOpenHoldsTheProgramResumeOnlyOnceItIsClosed) {
  PlcRig p;
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(50);
  auto job = r.load("G1 X20 F600\nM2\n", 1);
  r.step(5);
  r.loop.post({CommandKind::kRun});
  r.step(300);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  const double x0 = r.loop.status().act_mm[0];

  p.plc.sim_plant()->set_door_open(true);
  r.step(5);
  auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kHold);
  EXPECT_TRUE(st.plc_requests.feed_hold);
  EXPECT_TRUE(st.plc_requests.inhibit_start);
  EXPECT_TRUE(st.plc_requests.spindle_inhibit);
  EXPECT_EQ(st.plc_cause.action, PlcAction::kHold);
  r.step(500);  // the hold ramps the feed down: the axis stops short of the end
  const double x_hold = r.loop.status().act_mm[0];
  EXPECT_GT(x_hold, x0);
  EXPECT_LT(x_hold, 19.0);

  std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kResume});
  r.step(5);
  EXPECT_TRUE(refused(r, CommandKind::kResume, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kHold);

  p.plc.sim_plant()->set_door_open(false);
  r.step(5);
  st = r.loop.status();
  EXPECT_FALSE(st.plc_requests.feed_hold);
  EXPECT_EQ(st.state, MachineState::kHold);  // closing the door does not resume by itself
  mark = r.events.size();
  r.loop.post({CommandKind::kResume});
  r.step(5);
  EXPECT_FALSE(refused(r, CommandKind::kResume, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kRunning);
  for (int i = 0; i < 60 && r.loop.status().state != MachineState::kReady; ++i) r.step(100);
  st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kReady);
  EXPECT_TRUE(st.finished_ok);
  EXPECT_NEAR(st.act_mm[0], 20.0, 0.01);
}

TEST(PlcLoop, InhibitStartRefusesRunAndJog) {
  PlcRig p;
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(50);
  p.plc.sim_plant()->set_door_open(true);
  r.step(5);
  ASSERT_TRUE(r.loop.status().plc_requests.inhibit_start);
  auto job = r.load("G1 X5 F600\nM2\n", 1);
  r.step(5);
  std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kRun});
  r.loop.post({CommandKind::kJog, 0, 10.0, 1.0});
  r.step(5);
  EXPECT_TRUE(refused(r, CommandKind::kRun, mark));
  EXPECT_TRUE(refused(r, CommandKind::kJog, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  p.plc.sim_plant()->set_door_open(false);
  r.step(5);
  mark = r.events.size();
  r.loop.post({CommandKind::kRun});
  r.step(5);
  EXPECT_FALSE(refused(r, CommandKind::kRun, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kRunning);
}

// An overtravel switch (the simulated plant's, kLimitMargin_mm beyond the soft limit) faults its
// axis; reset is refused while it is actuated and accepted once it is released (forced off here:
// the sim bus allows forcing).
TEST(PlcLoop, OvertravelFaultsTheAxisResetOnlyOnceReleased) {
  PlcRig p;
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(20);
  ASSERT_EQ(p.plc.force("limit_y_pos", "TRUE"), "");
  r.step(3);
  auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kPlcFault);  // the machine logic's, not "internal error"
  EXPECT_EQ(st.plc_cause.action, PlcAction::kAxisFault);
  EXPECT_EQ(st.plc_cause.axis, 1);
  EXPECT_TRUE(st.plc_requests.axis_fault[1]);
  r.step(600);  // the controlled stop finishes
  std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kReset});
  r.step(300);  // the reset window runs out
  EXPECT_TRUE(refused(r, CommandKind::kReset, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
  EXPECT_EQ(r.loop.status().reset_block.cause, FaultCause::kPlcFault);

  ASSERT_EQ(p.plc.unforce("limit_y_pos"), "");
  r.step(3);
  r.loop.post({CommandKind::kReset});
  r.step(20);
  EXPECT_NE(r.loop.status().state, MachineState::kFault);
  r.step(20);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

// A reset whose cause is still there stays pending for the loop's window (250 cycles) and is
// decided in the cycle the cause goes, or refused when the window closes. The loop publishes
// each verdict (reset_verdicts): the `reset` command's reply waits for it, so a reply never says
// "refused" for a reset that completes later (the 1 s wall-clock wait did, on a slow loop).
TEST(PlcLoop, AResetIsDecidedByTheLoopAndTheVerdictIsPublished) {
  PlcRig p;
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(20);
  auto v = r.loop.status().reset_verdicts;
  r.loop.post({CommandKind::kReset});  // READY: refused at once, a verdict
  r.step(2);
  EXPECT_EQ(r.loop.status().reset_verdicts, v + 1);
  EXPECT_FALSE(r.loop.status().reset_pending);

  ASSERT_EQ(p.plc.force("limit_y_pos", "TRUE"), "");
  r.step(600);
  ASSERT_EQ(r.loop.status().state, MachineState::kFault);
  v = r.loop.status().reset_verdicts;
  r.loop.post({CommandKind::kReset});
  r.step(200);
  EXPECT_TRUE(r.loop.status().reset_pending);
  EXPECT_EQ(r.loop.status().reset_verdicts, v);  // not decided yet
  ASSERT_EQ(p.plc.unforce("limit_y_pos"), "");
  int k = 0;
  while (r.loop.status().reset_verdicts == v && k < 49) {
    r.step(1);
    ++k;
  }
  EXPECT_EQ(r.loop.status().reset_verdicts, v + 1) << "decided inside the window";
  EXPECT_FALSE(r.loop.status().reset_pending);
  EXPECT_NE(r.loop.status().state, MachineState::kFault);

  r.step(50);
  ASSERT_EQ(p.plc.force("limit_y_pos", "TRUE"), "");
  r.step(600);
  ASSERT_EQ(r.loop.status().state, MachineState::kFault);
  v = r.loop.status().reset_verdicts;
  const std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kReset});
  r.step(240);
  EXPECT_EQ(r.loop.status().reset_verdicts, v);
  EXPECT_FALSE(refused(r, CommandKind::kReset, mark));
  r.step(20);
  EXPECT_EQ(r.loop.status().reset_verdicts, v + 1) << "refused when the window closed";
  EXPECT_TRUE(refused(r, CommandKind::kReset, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
}

// A PLC E-stop request: ESTOP at once, reset refused while it is requested.
TEST(PlcLoop, EstopRequestAndItsReset) {
  config::Config cfg = test_rig::sim_config();
  const std::string dir = contour::test::process_temp_dir();
  {
    std::ofstream(dir + "/estop.st") << "PROGRAM e\n  NC.estop_req := stop_button;\nEND_PROGRAM\n";
  }
  const std::string yaml = contour::test::sim_yaml(contour::test::SimPlc::kNone) + "\nplc:\n  programs: [{file: " + dir +
                           "/estop.st}]\n  signals:\n    - {name: stop_button}\n";
  cfg = config::load_config_string(yaml, dir + "/x.yaml");
  Rig r(cfg);
  PlcEngine plc(cfg);
  r.loop.attach_plc(&plc);
  plc.start();
  ASSERT_TRUE(r.enable());
  ASSERT_EQ(plc.force("stop_button", "TRUE"), "");
  r.step(2);
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop);
  EXPECT_EQ(r.loop.status().plc_cause.action, PlcAction::kEstop);
  EXPECT_EQ(r.loop.status().cause, FaultCause::kPlcEstop);
  std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kReset});
  r.step(300);
  EXPECT_TRUE(refused(r, CommandKind::kReset, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop);
  ASSERT_EQ(plc.unforce("stop_button"), "");
  // A memory signal keeps its forced value after unforce until written: clear it.
  ASSERT_EQ(plc.force("stop_button", "FALSE"), "");
  r.step(2);
  r.loop.post({CommandKind::kReset});
  r.step(30);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  plc.stop();
}

// A fault the PLC engine latches (here a runtime error in the second program) is not an axis
// fault: the status names no axis (the engine fault's index, the program's, is in plc_cause) and
// the fault event carries the engine fault's kind for the log. It used to report "axis 1".
TEST(PlcLoop, EngineFaultIsNotAnAxisFault) {
  const std::string dir = contour::test::process_temp_dir();
  std::ofstream(dir + "/a.st") << "PROGRAM a\n  lamp := TRUE;\nEND_PROGRAM\n";
  std::ofstream(dir + "/b.st") << "PROGRAM b\nVAR x : INT; END_VAR\n  x := 10 / d;\nEND_PROGRAM\n";
  const std::string yaml = contour::test::sim_yaml(contour::test::SimPlc::kNone) + "\nplc:\n  programs: [{file: " + dir +
                           "/a.st}, {file: " + dir + "/b.st}]\n  signals:\n    - {name: lamp}\n" +
                           "    - {name: d, type: INT, default: 1}\n";
  const config::Config cfg = config::load_config_string(yaml, dir + "/x.yaml");
  Rig r(cfg);
  PlcEngine plc(cfg);
  r.loop.attach_plc(&plc);
  plc.start();
  ASSERT_TRUE(r.enable());
  r.step(20);
  ASSERT_EQ(r.loop.status().state, MachineState::kReady);
  const std::size_t mark = r.events.size();
  ASSERT_EQ(plc.force("d", "0"), "");
  r.step(3);
  const LoopStatus st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kPlcFault);
  EXPECT_EQ(st.fault_axis, -1);
  EXPECT_EQ(st.plc_cause.action, PlcAction::kEngineFault);
  EXPECT_EQ(st.plc_cause.engine, PlcFaultKind::kRuntimeError);
  EXPECT_EQ(st.plc_cause.axis, 1);  // the program's index
  bool seen = false;
  for (std::size_t i = mark; i < r.events.size(); ++i) {
    const RtEvent& e = r.events[i];
    if (e.kind != EventKind::kFault) continue;
    seen = true;
    EXPECT_EQ(e.axis, -1);
    EXPECT_EQ(e.detail, static_cast<std::uint8_t>(PlcFaultKind::kRuntimeError));
    EXPECT_EQ(describe(e).find("axis"), std::string::npos) << describe(e);
  }
  EXPECT_TRUE(seen);
  plc.stop();
}

TEST(PlcLoop, NoAllocationInACycleWithThePlc) {
  PlcRig p;
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(100);
  p.plc.sim_plant()->set_door_open(true);
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int i = 0; i < 200; ++i) r.loop.cycle();
    p.plc.sim_plant()->set_door_open(false);
    for (int i = 0; i < 200; ++i) r.loop.cycle();
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0U);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

}  // namespace
}  // namespace contour::daemon
