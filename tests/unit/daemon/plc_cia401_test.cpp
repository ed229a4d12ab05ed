// CiA 401 I/O modules bound to the soft PLC (plc.signals cia401), through ServoLoop: the bus'
// BusFeedback::io is the PLC's input snapshot each scan and its outputs leave in
// AxisCommands::io in the same cycle's write stage, matched by node-id (the bus may list the
// modules in any order); inputs older than the missed-TPDO streak take their defaults; no
// allocation in 10k cycles. The bus here is the in-process SimBus with two modules added by a
// thin wrapper (the CANopen side is CanopenIoModule / Cia401Loopback / Cia401Hil).
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "daemon/plc_engine.hpp"
#include "loop_rig.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/temp_dir.hpp"

namespace contour::daemon {
namespace {

// SimBus plus two CiA 401 modules (nodes 9 and 5, in that order) whose inputs the test sets.
class ModuleBus final : public AxisBus {
 public:
  explicit ModuleBus(const config::Config& cfg) : sim(test_rig::drives(cfg)) {
    modules[0].node_id = 9;
    modules[1].node_id = 5;
  }
  void start() override { sim.start(); }
  void stop() noexcept override { sim.stop(); }
  void begin_cycle() noexcept override { sim.begin_cycle(); }
  void read(BusFeedback& fb) noexcept override {
    sim.read(fb);
    fb.io_modules = 2;
    for (std::size_t k = 0; k < 2; ++k) {
      fb.io[k] = modules[k];
      if (silent_left[k] > 0) {
        --silent_left[k];
        fb.io[k].fresh = false;
      } else {
        fb.io[k].fresh = true;
      }
    }
  }
  void write(const AxisCommands& cmd) noexcept override {
    last = cmd;
    sim.write(cmd);
  }
  bool set_position(int axis, double mm) override { return sim.set_position(axis, mm); }
  [[nodiscard]] std::string describe() const override { return "sim + 2 CiA 401 modules"; }
  // The outputs the loop wrote for `node` (nullptr: none).
  [[nodiscard]] const IoModuleCommands* out(int node) const {
    for (const auto& o : last.io)
      if (o.node_id == node) return &o;
    return nullptr;
  }

  SimBus sim;
  std::array<IoModuleFeedback, 2> modules{};
  std::array<int, 2> silent_left{};
  AxisCommands last{};
};

config::Config cia401_config() {
  const std::string dir = contour::test::process_temp_dir();
  std::ofstream(dir + "/cia401.st") << "PROGRAM io\n"
                                       "  clamp := part;\n"
                                       "  valve := flow + 1;\n"
                                       "  lamp := TRUE;\n"
                                       "END_PROGRAM\n";
  const std::string yaml = contour::test::sim_yaml(contour::test::SimPlc::kNone) +
                           "\nplc:\n  programs: [{file: " + dir +
                           "/cia401.st}]\n  signals:\n"
                           "    - {name: part, cia401: {node: 5, digital_input: 2, bit: 4}}\n"
                           "    - {name: clamp, cia401: {node: 5, digital_output: 1, bit: 2}}\n"
                           "    - {name: flow, type: INT, cia401: {node: 5, analog_input: 1}}\n"
                           "    - {name: valve, type: INT, cia401: {node: 5, analog_output: 1}}\n"
                           "    - {name: lamp, cia401: {node: 9, digital_output: 3, bit: 7}}\n";
  config::Config c = config::load_config_string(yaml, dir + "/cia401.yaml");
  // The in-process sim bus refuses cia401 bindings
  // (PlcHandshake.Cia401BindingsAreRefusedOnTheSimBus); here the bus is the wrapper above, standing
  // in for the CANopen bus.
  c.bus.type = "socketcan";
  return c;
}

struct Cia401Rig {
  Cia401Rig() : cfg(cia401_config()), bus(cfg), loop(cfg, bus, 4096), plc(cfg) {
    loop.attach_plc(&plc);
    plc.start();
  }
  ~Cia401Rig() { plc.stop(); }
  void step(int n) {
    RtEvent e;
    for (int i = 0; i < n; ++i) {
      loop.cycle();
      while (loop.events().pop(e)) {
      }
    }
  }
  config::Config cfg;
  ModuleBus bus;
  ServoLoop loop;
  PlcEngine plc;
};

TEST(PlcCia401, ModuleInputsReachTheScanAndItsOutputsTheSameCyclesWrite) {
  Cia401Rig r;
  r.bus.modules[1].digital[1] = 0x10;  // node 5, 0x6000:02 bit 4
  r.bus.modules[1].analog[0] = 100;    // node 5, 0x6401:01
  r.step(1);
  const IoModuleCommands* o5 = r.bus.out(5);
  const IoModuleCommands* o9 = r.bus.out(9);
  ASSERT_NE(o5, nullptr);
  ASSERT_NE(o9, nullptr);
  EXPECT_EQ(o5->digital[0], 0x04);  // clamp := part, in the write stage of the same cycle
  EXPECT_EQ(o5->analog[0], 101);    // valve := flow + 1
  EXPECT_EQ(o9->digital[2], 0x80);  // lamp on node 9 (listed first by the bus)
  EXPECT_EQ(o9->digital[0], 0);
  r.bus.modules[1].digital[1] = 0x00;
  r.step(1);
  EXPECT_EQ(r.bus.out(5)->digital[0], 0);
}

TEST(PlcCia401, StaleModuleInputsTakeTheirDefaultsAfterTheMissedTpdoStreak) {
  Cia401Rig r;
  ASSERT_EQ(r.cfg.safety.missed_tpdo_streak, 3);
  r.bus.modules[1].digital[1] = 0x10;
  const int part = r.plc.find("part");
  ASSERT_GE(part, 0);
  r.step(2);
  ASSERT_EQ(r.plc.peek(part).i, 1);
  r.bus.silent_left[1] = 4;
  r.step(1);
  EXPECT_EQ(r.plc.peek(part).i, 1);  // 1 cycle old: held
  r.step(1);
  EXPECT_EQ(r.plc.peek(part).i, 1);  // 2
  r.step(1);
  EXPECT_EQ(r.plc.peek(part).i, 0);  // 3: stale, the default
  EXPECT_EQ(r.bus.out(5)->digital[0], 0);
  r.step(1);
  EXPECT_EQ(r.plc.peek(part).i, 0);
  r.step(1);  // fresh again
  EXPECT_EQ(r.plc.peek(part).i, 1);
}

TEST(PlcCia401, CyclesWithModuleBindingsDoNotAllocate) {
  Cia401Rig r;
  r.step(5);
  std::size_t allocs = 0;
  {
    contour::test::AllocGuard g;
    for (int k = 0; k < 10000; ++k) {
      r.bus.modules[1].digital[1] = static_cast<std::uint8_t>((k / 100) % 2 != 0 ? 0x10 : 0);
      r.bus.modules[1].analog[0] = static_cast<std::int16_t>(k % 1000);
      if (k == 5000) r.bus.silent_left[1] = 5;
      r.loop.cycle();
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  EXPECT_EQ(r.bus.out(5)->analog[0], 9999 % 1000 + 1);
}

}  // namespace
}  // namespace contour::daemon
