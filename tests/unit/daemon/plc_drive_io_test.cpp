// CiA 402 drive digital I/O (0x60FD / 0x60FE:01) bound to the soft PLC (plc.signals cia402), on
// the in-process simulated machine stepped in lockstep:
//   - SimBus: switches on the axis' true position, held (not fresh) through dropped TPDOs, bits
//     overridden for tests; outputs latched at the next SYNC, masked;
//   - ServoLoop + PlcEngine: a cam on 0x60FD bit 16 holds a running program and a positive-limit
//     switch faults the axis, as the ST program says; the reset is refused while the switch is
//     on; the PLC's lamp on 0x60FE:01 bit 16 reaches the drive; inputs older than the missed-TPDO
//     streak take their defaults; `io` names the source "axis x 0x60FD bit 1"; no allocation in
//     10k cycles with the bindings.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "daemon/event_log.hpp"
#include "daemon/plc_engine.hpp"
#include "daemon/plc_status.hpp"
#include "loop_rig.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/temp_dir.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;

std::vector<control::FeedDriveParams> one_axis() {
  control::FeedDriveParams p;
  p.period_s = 0.001;
  p.gain_per_s = 100.0;
  p.tau_s = 0.02;
  return {p};
}

TEST(SimBusDriveIo, SwitchesFollowTheAxisAndOutputsLatchAtTheNextSync) {
  SimBus bus(one_axis());
  bus.add_input_switch(0, 1, 2.0, true);    // positive limit above 2 mm
  bus.add_input_switch(0, 0, -2.0, false);  // negative limit below -2 mm
  BusFeedback fb;
  AxisCommands cmd;
  bus.begin_cycle();
  bus.read(fb);
  EXPECT_TRUE(fb.axis[0].digital_inputs_present);
  EXPECT_TRUE(fb.axis[0].digital_inputs_fresh);
  EXPECT_EQ(fb.axis[0].digital_inputs, 0u);
  ASSERT_TRUE(bus.set_position(0, -3.0));
  bus.begin_cycle();
  bus.read(fb);
  EXPECT_EQ(fb.axis[0].digital_inputs, 1u << 0);

  // Move up at 50 mm/s: bit 1 comes on exactly when the plant passes 2 mm.
  cmd.mode = DriveMode::kEnabled;
  cmd.velocity_mm_s[0] = 50.0;
  bool on = false;
  for (int k = 0; k < 400 && !on; ++k) {
    bus.write(cmd);
    bus.begin_cycle();
    bus.read(fb);
    on = (fb.axis[0].digital_inputs & 2u) != 0;
    EXPECT_EQ(on, fb.axis[0].position_mm > 2.0) << k;
    EXPECT_EQ((fb.axis[0].digital_inputs & 1u) != 0, fb.axis[0].position_mm < -2.0) << k;
  }
  ASSERT_TRUE(on);

  // A dropped TPDO: not fresh, the last value kept (the switch turning off is not seen yet).
  cmd.velocity_mm_s[0] = 0.0;
  bus.write(cmd);
  ASSERT_TRUE(bus.set_position(0, 0.0));
  bus.inject_tpdo_drop(0, 1);
  bus.begin_cycle();
  bus.read(fb);
  EXPECT_FALSE(fb.axis[0].fresh);
  EXPECT_FALSE(fb.axis[0].digital_inputs_fresh);
  EXPECT_EQ(fb.axis[0].digital_inputs, 2u);
  bus.begin_cycle();
  bus.read(fb);
  EXPECT_TRUE(fb.axis[0].digital_inputs_fresh);
  EXPECT_EQ(fb.axis[0].digital_inputs, 0u);

  // Override for tests: bit 3 (interlock) forced on.
  bus.inject_digital_inputs(0, 1u << 3, 1u << 3);
  bus.begin_cycle();
  bus.read(fb);
  EXPECT_EQ(fb.axis[0].digital_inputs, 1u << 3);

  // Outputs: masked, and only in effect from the next SYNC.
  cmd.digital_outputs[0] = (1u << 16) | (1u << 20);
  cmd.digital_output_mask[0] = 1u << 16;
  bus.write(cmd);
  EXPECT_EQ(bus.digital_outputs(0), 0u);
  bus.begin_cycle();
  EXPECT_EQ(bus.digital_outputs(0), 1u << 16);
}

TEST(SimBusDriveIo, DefaultSwitchesSitAtTheSoftLimits) {
  const config::Config cfg = test_rig::sim_config();
  auto bus = make_sim_bus(cfg);
  BusFeedback fb;
  const double max_x = cfg.machine.axes[0].max_mm, min_x = cfg.machine.axes[0].min_mm;
  const std::pair<double, std::uint32_t> cases[] = {
      {0.0, 0u},
      {max_x + kSimLimitMargin_mm + 0.01, 1u << 1},
      {max_x + kSimLimitMargin_mm - 0.01, 0u},
      {min_x + kSimHomeBand_mm - 0.01, 1u << 2},
      {min_x - kSimLimitMargin_mm - 0.01, (1u << 0) | (1u << 2)}};
  for (const auto& [x, bits] : cases) {
    ASSERT_TRUE(bus->set_position(0, x));
    bus->begin_cycle();
    bus->read(fb);
    EXPECT_EQ(fb.axis[0].digital_inputs, bits) << x;
  }
}

// config/sim.yaml plus a PLC program on X's drive I/O: a cam (0x60FD bit 16) holds the program,
// the positive limit (bit 1) faults the axis and lights a lamp on 0x60FE:01 bit 16.
config::Config drive_io_config() {
  const std::string dir = contour::test::process_temp_dir();
  std::ofstream(dir + "/drive_io.st") << "PROGRAM limits\n"
                                         "  NC.axis_fault_x := x_plus;\n"
                                         "  NC.feed_hold_req := x_cam;\n"
                                         "  x_lamp := x_plus;\n"
                                         "END_PROGRAM\n";
  const std::string yaml = contour::test::sim_yaml(contour::test::SimPlc::kNone) + "\nplc:\n  programs: [{file: " + dir +
                           "/drive_io.st}]\n  signals:\n"
                           "    - {name: x_plus, cia402: {axis: X, input: positive_limit}}\n"
                           "    - {name: x_cam, cia402: {axis: X, input: 16}}\n"
                           "    - {name: x_lamp, cia402: {axis: X, output: 16}}\n";
  return config::load_config_string(yaml, dir + "/drive_io.yaml");
}

struct IoRig {
  IoRig() : cfg(drive_io_config()), rig(cfg), plc(cfg) {
    rig.loop.attach_plc(&plc);
    plc.start();
  }
  ~IoRig() { plc.stop(); }
  config::Config cfg;
  Rig rig;
  PlcEngine plc;
};

bool refused(const Rig& r, CommandKind k, std::size_t from) {
  for (std::size_t i = from; i < r.events.size(); ++i)
    if (r.events[i].kind == EventKind::kCommandRefused && r.events[i].command == k) return true;
  return false;
}

// Enables the rig and starts `G1 X20 F600` (RUNNING when it worked: the caller asserts it). The
// job must outlive the run.
std::shared_ptr<ProgramJob> run_x20(Rig& r) {
  EXPECT_TRUE(r.enable());
  auto job = r.load("G1 X20 F600\nM2\n", 1);
  r.step(5);
  r.loop.post({CommandKind::kRun});
  r.step(2);
  return job;
}

TEST(PlcDriveIo, ACamOnTheDriveInputHoldsTheProgram) {
  IoRig p;
  Rig& r = p.rig;
  r.bus.add_input_switch(0, 16, 5.0, true);
  auto job = run_x20(r);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  for (int i = 0; i < 2000 && r.loop.status().state == MachineState::kRunning; ++i) {
    r.step(1);
    if (r.loop.status().act_mm[0] < 4.99) {
      EXPECT_FALSE(r.loop.status().plc_requests.feed_hold) << i;
    }
  }
  const auto st = r.loop.status();
  EXPECT_EQ(st.state, MachineState::kHold);
  EXPECT_TRUE(st.plc_requests.feed_hold);
  EXPECT_EQ(st.plc_cause.action, PlcAction::kHold);
  EXPECT_GT(st.act_mm[0], 5.0);
  r.step(500);
  EXPECT_LT(r.loop.status().act_mm[0], 19.0);  // held short of the end
}

TEST(PlcDriveIo, PositiveLimitFaultsTheAxisLightsTheLampAndBlocksTheReset) {
  IoRig p;
  Rig& r = p.rig;
  r.bus.add_input_switch(0, 1, 8.0, true);
  auto job = run_x20(r);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  for (int i = 0; i < 3000 && r.loop.status().state == MachineState::kRunning; ++i) r.step(1);
  auto st = r.loop.status();
  ASSERT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kPlcFault);
  EXPECT_EQ(st.plc_cause.action, PlcAction::kAxisFault);
  EXPECT_EQ(st.plc_cause.axis, 0);
  EXPECT_GT(st.act_mm[0], 8.0);
  EXPECT_LT(st.act_mm[0], 9.0);  // faulted as the switch came on, not at the end of the move
  r.step(2);
  EXPECT_EQ(r.bus.digital_outputs(0), 1u << 16);  // x_lamp := x_plus, through 0x60FE:01

  r.step(600);
  std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kReset});
  r.step(300);
  EXPECT_TRUE(refused(r, CommandKind::kReset, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);

  r.bus.inject_digital_inputs(0, 1u << 1, 0);  // the switch released (the axis backed off)
  r.step(3);
  EXPECT_EQ(r.bus.digital_outputs(0), 0u);
  r.loop.post({CommandKind::kReset});
  r.step(40);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(PlcDriveIo, StaleInputsTakeTheirDefaultsAfterTheMissedTpdoStreak) {
  IoRig p;
  Rig& r = p.rig;
  r.bus.inject_digital_inputs(0, 1u << 16, 1u << 16);
  const int cam = p.plc.find("x_cam");
  ASSERT_GE(cam, 0);
  r.step(3);
  ASSERT_EQ(p.plc.peek(cam).i, 1);
  ASSERT_EQ(p.cfg.safety.missed_tpdo_streak, 3);
  r.bus.inject_tpdo_drop(0, 5);
  r.step(1);
  EXPECT_EQ(p.plc.peek(cam).i, 1);  // 1 cycle old: held, as the position is
  r.step(1);
  EXPECT_EQ(p.plc.peek(cam).i, 1);  // 2 cycles old
  r.step(1);
  EXPECT_EQ(p.plc.peek(cam).i, 0);  // 3: stale, the default (FALSE), not the old value
  r.step(2);
  EXPECT_EQ(p.plc.peek(cam).i, 0);
  r.step(1);  // fresh again
  EXPECT_EQ(p.plc.peek(cam).i, 1);
}

// A drive whose digital inputs (TPDO2) stop while its position (TPDO1) still comes: not a silent
// fall-back to the signals' defaults, but the missed-TPDO fault, named as the inputs', and a
// reset refused until they come again.
TEST(PlcDriveIo, LostDigitalInputsAloneFaultTheMachineAndBlockTheResetUntilBack) {
  IoRig p;
  Rig& r = p.rig;
  auto job = run_x20(r);
  ASSERT_EQ(r.loop.status().state, MachineState::kRunning);
  ASSERT_EQ(p.cfg.safety.missed_tpdo_streak, 3);
  r.bus.inject_inputs_tpdo_drop(1, -1);
  r.step(2);
  EXPECT_EQ(r.loop.status().state, MachineState::kRunning);  // 2 cycles: held, as the position is
  r.step(1);
  auto st = r.loop.status();
  ASSERT_EQ(st.state, MachineState::kFault);
  EXPECT_EQ(st.cause, FaultCause::kMissedTpdo);
  EXPECT_EQ(st.fault_axis, 1);
  EXPECT_EQ(st.fault_detail, static_cast<std::uint8_t>(MissedPdo::kDigitalInputs));
  EXPECT_EQ(st.fault_value, 3.0);
  std::string logged;
  for (const auto& e : r.events)
    if (e.kind == EventKind::kFault && e.cause == FaultCause::kMissedTpdo && e.axis == 1 &&
        e.detail == static_cast<std::uint8_t>(MissedPdo::kDigitalInputs))
      logged = describe(e);
  EXPECT_NE(logged.find("3 missed TPDOs in a row (0x60FD digital inputs"), std::string::npos)
      << logged;

  r.step(600);  // stopped; the inputs still do not come
  std::size_t mark = r.events.size();
  r.loop.post({CommandKind::kReset});
  r.step(300);  // the reset window passes: refused
  EXPECT_TRUE(refused(r, CommandKind::kReset, mark));
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);
  EXPECT_EQ(r.loop.status().reset_block.cause, FaultCause::kMissedTpdo);
  EXPECT_EQ(r.loop.status().reset_block.axis, 1);
  const std::string why = describe(r.loop.status().reset_block);
  EXPECT_NE(why.find("axis 1 still does not send its 0x60FD digital inputs"), std::string::npos)
      << why;

  r.bus.inject_inputs_tpdo_drop(1, 0);  // back
  r.step(2);
  r.loop.post({CommandKind::kReset});
  r.step(40);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  r.step(100);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

TEST(PlcDriveIo, IoNamesTheDriveAndBit) {
  IoRig p;
  p.rig.step(3);
  const auto snap = p.plc.snapshot();
  std::map<std::string, std::string> src;
  for (const auto& s : snap.signals) src[s.name] = s.source;
  EXPECT_EQ(src["x_plus"], "axis x 0x60FD bit 1");
  EXPECT_EQ(src["x_cam"], "axis x 0x60FD bit 16");
  EXPECT_EQ(src["x_lamp"], "axis x 0x60FE:01 bit 16");
}

TEST(PlcDriveIo, CyclesWithDriveIoBindingsDoNotAllocate) {
  IoRig p;
  Rig& r = p.rig;
  r.bus.add_input_switch(0, 16, 5.0, true);
  r.bus.add_input_switch(0, 1, 1e9, true);
  ASSERT_TRUE(r.enable());
  r.loop.post({CommandKind::kJog, 0, 10.0, 8.0});  // through the cam: the inputs change
  r.step(5);
  std::size_t allocs = 0;
  {
    contour::test::AllocGuard g;
    for (int k = 0; k < 10000; ++k) {
      if (k == 3000) r.bus.inject_tpdo_drop(0, 1);
      if (k == 6000) r.bus.inject_digital_inputs(0, 1u << 1, 1u << 1);
      r.loop.cycle();
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  EXPECT_EQ(r.loop.status().state, MachineState::kFault);  // the limit at k = 6000 faulted it
  EXPECT_EQ(r.bus.digital_outputs(0), 1u << 16);
}

}  // namespace
}  // namespace contour::daemon
