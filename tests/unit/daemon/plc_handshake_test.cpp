// M6 and the user M-codes handed to the machine logic (issue 20): config/sim.yaml's example
// logic (toolchanger.st on the simulated 8-pocket carousel, mcodes.st) on the in-process
// simulated machine, stepped in lockstep. The program stays RUNNING while the PLC's sequence
// runs and goes on when the PLC says done; the path waits at its exact stop meanwhile; a done that
// never comes is a PLC fault after the configured timeout (cause "machine logic fault"), never a
// hang; a user M-code no PLC program handles passes at once; without the PLC, M6 is the
// operator's pause (tests/sim/tool_change_pause_test.cpp).
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "daemon/plc_engine.hpp"
#include "daemon/plc_sim.hpp"
#include "loop_rig.hpp"

namespace contour::daemon {
namespace {

using control::plc::PlantPoint;
using test_rig::Rig;

config::Config sim_plc() {
  return config::load_config_file(std::string(CONTOUR_SOURCE_DIR) + "/config/sim.yaml");
}

struct PlcRig {
  explicit PlcRig(const config::Config& c) : cfg(c), rig(cfg), plc(cfg) {
    rig.loop.attach_plc(&plc);
    plc.start();
  }
  ~PlcRig() { plc.stop(); }
  config::Config cfg;
  Rig rig;
  PlcEngine plc;
};

// Steps until the loop is READY again (or the cycle budget runs out); returns whether HOLD was
// ever seen and the longest stretch of RUNNING cycles with the reference standing still.
struct RunTrace {
  bool saw_hold = false;
  int longest_still = 0;
  MachineState end = MachineState::kRunning;
};
RunTrace run_to_end(Rig& r, int max_cycles) {
  RunTrace t;
  int still = 0;
  auto prev = r.loop.status().ref_mm;
  for (int i = 0; i < max_cycles; ++i) {
    r.step(1);
    const LoopStatus st = r.loop.status();
    t.saw_hold = t.saw_hold || st.state == MachineState::kHold;
    if (st.state == MachineState::kRunning && st.ref_mm == prev) {
      t.longest_still = std::max(t.longest_still, ++still);
    } else {
      still = 0;
    }
    prev = st.ref_mm;
    if (st.state != MachineState::kRunning && st.state != MachineState::kHold) {
      t.end = st.state;
      return t;
    }
  }
  t.end = r.loop.status().state;
  return t;
}

TEST(PlcHandshake, M6RunsTheCarouselSequenceAndTheProgramGoesOnByItself) {
  PlcRig p(sim_plc());
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(50);
  auto job = r.load("G1 X5 F600\nT3 M6\nG1 X10\nM2\n", 1);
  r.step(5);
  r.loop.post({CommandKind::kRun});
  const RunTrace t = run_to_end(r, 30000);
  const LoopStatus st = r.loop.status();
  EXPECT_EQ(t.end, MachineState::kReady);
  EXPECT_FALSE(t.saw_hold) << "M6 went to the operator although the PLC runs the tool changer";
  EXPECT_TRUE(st.finished_ok);
  EXPECT_NEAR(st.act_mm[0], 10.0, 0.01);
  // The carousel turned and stands at pocket 3 (tool T lives in pocket T); the path waited at
  // X5 for the whole sequence (several index steps of 0.25 s and two drawbar strokes).
  EXPECT_EQ(p.plc.sim_plant()->get(PlantPoint::kCarouselPocket), 3);
  EXPECT_GT(t.longest_still, 500);
  EXPECT_EQ(p.plc.tool_change_state(), Handshake::kIdle);
  EXPECT_EQ(r.count(EventKind::kProgramPause), 0U);
}

TEST(PlcHandshake, UserMcodesWaitForThePlcsDone) {
  PlcRig p(sim_plc());
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(50);
  // M100 work light on, M102 P0.4: a 0.4 s PLC dwell, M101 light off.
  auto job = r.load("G1 X2 F600\nM100\nM102 P0.4\nG1 X4\nM101\nM2\n", 1);
  r.step(5);
  r.loop.post({CommandKind::kRun});
  r.step(2);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  bool light_seen = false;
  int still = 0, longest = 0;
  auto prev = r.loop.status().ref_mm;
  for (int i = 0; i < 20000 && r.loop.status().state != MachineState::kReady; ++i) {
    r.step(1);
    const LoopStatus st = r.loop.status();
    ASSERT_NE(st.state, MachineState::kHold);
    ASSERT_NE(st.state, MachineState::kFault);
    light_seen = light_seen || p.plc.sim_plant()->plant().get(PlantPoint::kWorkLight) != 0;
    if (st.state == MachineState::kRunning && st.ref_mm == prev) longest = std::max(longest, ++still);
    else still = 0;
    prev = st.ref_mm;
  }
  const LoopStatus st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kReady);
  EXPECT_TRUE(st.finished_ok);
  EXPECT_NEAR(st.act_mm[0], 4.0, 0.01);
  EXPECT_TRUE(light_seen);
  // The light went off again with M101 (the door is closed: the PLC's own term is off).
  EXPECT_EQ(p.plc.sim_plant()->plant().get(PlantPoint::kWorkLight), 0);
  EXPECT_GE(longest, 400);   // the PLC's 0.4 s dwell held the path
  EXPECT_LT(longest, 1000);  // and then it went on
}

TEST(PlcHandshake, ADoneThatNeverComesIsAPlcFaultAfterTheTimeoutNotAHang) {
  config::Config cfg = sim_plc();
  for (auto& m : cfg.plc.mcodes) {
    if (m.m == 102) m.timeout_s = 0.2;  // M102 P5 asks for 5 s: the NC gives up after 0.2 s
  }
  PlcRig p(cfg);
  Rig& r = p.rig;
  ASSERT_TRUE(r.enable());
  r.step(50);
  auto job = r.load("G1 X2 F600\nM102 P5\nG1 X4\nM2\n", 1);
  r.step(5);
  r.loop.post({CommandKind::kRun});
  const RunTrace t = run_to_end(r, 10000);
  const LoopStatus st = r.loop.status();
  EXPECT_EQ(t.end, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kPlcFault);
  EXPECT_EQ(st.plc_engine_fault.kind, PlcFaultKind::kMcodeTimeout);
  EXPECT_EQ(st.plc_engine_fault.code, 102);
  EXPECT_LT(st.act_mm[0], 2.0 + 1e-3);  // it never went on to X4
  r.step(2000);
  EXPECT_EQ(p.plc.mcode_state(), Handshake::kIdle);  // the program's abort released it
}

TEST(PlcHandshake, AUserMcodeNoPlcProgramHandlesPassesAtOnce) {
  // The same path with a zero dwell (an exact stop, nothing else) is the yardstick.
  auto trace = [](const std::string& program) {
    PlcRig p(sim_plc());
    Rig& r = p.rig;
    EXPECT_TRUE(r.enable());
    r.step(50);
    auto job = r.load(program, 1);
    r.step(5);
    r.loop.post({CommandKind::kRun});
    const RunTrace t = run_to_end(r, 20000);
    EXPECT_NEAR(r.loop.status().act_mm[0], 4.0, 0.01) << program;
    return t;
  };
  const RunTrace m = trace("G1 X2 F600\nM150 P1\nG1 X4\nM2\n");
  const RunTrace g4 = trace("G1 X2 F600\nG4 P0\nG1 X4\nM2\n");
  EXPECT_EQ(m.end, MachineState::kReady);
  EXPECT_FALSE(m.saw_hold);
  EXPECT_LE(m.longest_still, g4.longest_still + 2);  // an exact stop, no wait
}

// A signal bound to a CiA 401 module needs the CANopen bus (the master maps the module's PDOs):
// the in-process sim bus has no such module and the signal would sit at its default. Start-up
// refuses it on the sim bus, naming the signal and what to do.
TEST(PlcHandshake, Cia401BindingsAreRefusedOnTheSimBus) {
  config::Config cfg = sim_plc();
  ASSERT_FALSE(cfg.plc.signals.empty());
  ASSERT_EQ(cfg.bus.type, "sim");
  cfg.plc.signals[0].binding.kind = config::PlcBindingKind::kCia401;
  SimBus bus(test_rig::drives(cfg));
  try {
    ServoLoop loop(cfg, bus);
    FAIL() << "accepted a cia401 binding on the sim bus";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'" + cfg.plc.signals[0].name + "'"), std::string::npos) << what;
    EXPECT_NE(what.find("cia401 (CAN I/O module) bindings need the CANopen bus"), std::string::npos)
        << what;
  }
}

}  // namespace
}  // namespace contour::daemon
