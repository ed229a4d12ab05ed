// The soft PLC engine without a loop, in lockstep (scan k = cycle k, 1 ms): the shipped example
// machine logic (config/sim.yaml's plc: section) on the simulated plant — door
// interlock requests, coolant, lube, overtravel switches, the M6 carousel sequence and user
// M-codes through the handshakes; scan order (inputs once, programs in order, outputs once) and
// scheduling; forcing rules; runtime errors; a lost Modbus I/O coupler (contour-machine-sim's, on
// loopback) latching a fault and the reset rule; JSON of `io` / `plc status`; no allocation in a
// scan.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <thread>

#include "config/config.hpp"
#include "daemon/plc_engine.hpp"
#include "daemon/plc_status.hpp"
#include "tests/support/alloc_counter.hpp"
// The simulated coupler lives in contour-machine-sim (not a library).
#include "tools/contour-machine-sim/dynamometer_server.cpp"
#include "tools/contour-machine-sim/plant_io.cpp"

namespace cfg = contour::config;
namespace cp = contour::control::plc;
using namespace contour::daemon;
using namespace std::chrono_literals;

namespace {

std::string read(const std::string& p) {
  std::ifstream in(p);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

cfg::Config example(const std::string& extra = "") {
  const std::string dir = std::string(CONTOUR_SOURCE_DIR) + "/config/";
  return cfg::load_config_string(read(dir + "sim.yaml") + extra,
                                 dir + "plc_engine_test.yaml");
}

// A scratch config with its own programs.
struct Scratch {
  Scratch() {
    dir = std::filesystem::temp_directory_path() / ("plc_engine_test_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
    std::filesystem::create_directories(dir);
  }
  ~Scratch() { std::filesystem::remove_all(dir); }
  void file(const std::string& name, const std::string& text) { std::ofstream(dir / name) << text; }
  cfg::Config load(const std::string& yaml) {
    std::ofstream(dir / "c.yaml") << yaml;
    return cfg::load_config_file((dir / "c.yaml").string());
  }
  std::filesystem::path dir;
  static inline int n = 0;
};

const char* kMachine = R"(loop: {period_us: 1000}
machine:
  axes:
    - {name: X, min_mm: -100, max_mm: 100}
    - {name: Y}
    - {name: Z}
)";

struct Rig {
  explicit Rig(const cfg::Config& c) : engine(c) {
    in.state = MachineState::kReady;
    in.axes = 3;
    in.homed = {true, true, true};
  }
  void scan(int n = 1) {
    for (int k = 0; k < n; ++k) {
      in.cycle = ++cycle;
      engine.scan(in, out);
      if (out.fault) faults.push_back(out.fault);
    }
  }
  // Scans until f() or `limit` cycles; true if f() became true.
  bool scan_until(const std::function<bool()>& f, int limit) {
    for (int k = 0; k < limit; ++k) {
      scan();
      if (f()) return true;
    }
    return false;
  }
  cp::Cell value(const std::string& name) {
    const int slot = engine.find(name);
    if (slot < 0) {
      ADD_FAILURE() << "no signal " << name;
      return {};
    }
    return engine.peek(slot);
  }
  PlcEngine engine;
  PlcNcInput in{};
  PlcCycleOutput out{};
  std::uint64_t cycle = 0;
  std::vector<PlcFault> faults;
};

}  // namespace

TEST(PlcEngine, DoorInterlockRequestsHoldSpindleStopAndInhibitStart) {
  Rig r(example());
  r.in.state = MachineState::kRunning;
  r.in.program_running = true;
  r.scan(5);
  EXPECT_FALSE(r.out.requests.feed_hold);
  EXPECT_FALSE(r.out.requests.inhibit_start);
  EXPECT_FALSE(r.out.requests.spindle_inhibit);
  r.engine.sim_plant()->set_door_open(true);
  r.scan();  // the plant steps at this scan's input stage: seen at once
  EXPECT_TRUE(r.out.requests.feed_hold);
  EXPECT_TRUE(r.out.requests.inhibit_start);
  EXPECT_TRUE(r.out.requests.spindle_inhibit);
  // What the PLC hands the NC holds requests only.
  EXPECT_FALSE(r.out.requests.estop);
  EXPECT_FALSE(r.out.requests.fault);
  r.engine.sim_plant()->set_door_open(false);
  r.scan();
  EXPECT_FALSE(r.out.requests.feed_hold);
  EXPECT_FALSE(r.out.requests.inhibit_start);
  EXPECT_FALSE(r.out.requests.spindle_inhibit);
}

TEST(PlcEngine, AirPressureIsDebouncedAndCoolantFollowsM8WithTheDoorClosed) {
  Rig r(example());
  r.scan(2);
  r.engine.sim_plant()->set_air_supply(false);
  r.scan(150);
  EXPECT_FALSE(r.out.requests.feed_hold);  // < 200 ms: not yet
  EXPECT_TRUE(r.scan_until([&] { return r.out.requests.feed_hold; }, 100));
  r.engine.sim_plant()->set_air_supply(true);
  r.scan();
  EXPECT_FALSE(r.out.requests.feed_hold);
  r.in.coolant_flood = true;
  r.scan();
  EXPECT_TRUE(r.out.coolant_flood);
  EXPECT_FALSE(r.out.coolant_mist);
  r.engine.sim_plant()->set_door_open(true);
  r.scan();
  EXPECT_FALSE(r.out.coolant_flood);
}

TEST(PlcEngine, LubePumpRunsOnEnableAndEveryMinute) {
  Rig r(example());
  r.in.state = MachineState::kDisabled;
  r.scan(100);
  EXPECT_EQ(r.value("lube_pump").i, 0);
  r.in.state = MachineState::kReady;  // drives enabled: a run at once
  ASSERT_TRUE(r.scan_until([&] { return r.value("lube_pump").i == 1; }, 40));
  // lube.st runs every 10 cycles; the pump runs 3 s and builds pressure on the way.
  r.scan(1600);
  EXPECT_EQ(r.value("lube_pressure_ok").i, 1);
  ASSERT_TRUE(r.scan_until([&] { return r.value("lube_pump").i == 0; }, 2000));
  EXPECT_EQ(r.value("lube_alarm").i, 0);
  // Next run ~60 s after the first trigger.
  ASSERT_TRUE(r.scan_until([&] { return r.value("lube_pump").i == 1; }, 60000));
  EXPECT_NEAR(static_cast<double>(r.cycle), 100 + 60000, 100);
}

// A fault and reset during a pump run: re-enabling gives the lube a fresh 2.5 s window to build
// pressure. (The pressure seen as missing 2.4 s into the run, the machine faulting and being reset
// then: the no-pressure timer once ran on through the re-enable and latched the alarm 0.1 s after
// it, inhibiting start until the next enable; seen in HIL after a lost coupler.)
TEST(PlcEngine, ReEnableRestartsTheLubePressureWindow) {
  Rig r(example());
  r.in.state = MachineState::kReady;
  ASSERT_TRUE(r.scan_until([&] { return r.value("lube_pump").i == 1; }, 40));
  ASSERT_EQ(r.engine.force("lube_pressure_ok", "FALSE"), "");  // the inputs' default: coupler lost
  r.scan(2000);
  r.in.state = MachineState::kFault;
  r.scan(400);
  EXPECT_EQ(r.value("lube_alarm").i, 0);  // 2.4 s: not yet
  r.in.state = MachineState::kReady;       // reset: the drives are enabled again
  r.scan(500);                             // the pump builds pressure again (1.5 s in the plant)
  EXPECT_EQ(r.value("lube_alarm").i, 0);
  ASSERT_EQ(r.engine.unforce("lube_pressure_ok"), "");
  r.scan(1500);
  EXPECT_EQ(r.value("lube_pressure_ok").i, 1);
  EXPECT_EQ(r.value("lube_alarm").i, 0);
  EXPECT_FALSE(r.out.requests.inhibit_start);
  // Pressure that never comes after the enable still raises the alarm, 2.5 s into the run.
  r.in.state = MachineState::kDisabled;
  r.scan(20);
  ASSERT_EQ(r.engine.force("lube_pressure_ok", "FALSE"), "");
  r.in.state = MachineState::kReady;
  r.scan(2400);
  EXPECT_EQ(r.value("lube_alarm").i, 0);
  EXPECT_TRUE(r.scan_until([&] { return r.value("lube_alarm").i == 1; }, 200));
  r.scan(20);  // interlocks.st reads the memory signal at its next scan
  EXPECT_TRUE(r.out.requests.inhibit_start);
}

TEST(PlcEngine, OvertravelSwitchFaultsItsAxis) {
  Rig r(example());
  r.scan();
  EXPECT_FALSE(r.out.requests.axis_fault[0]);
  r.in.pos_mm[0] = 203.0;  // soft limit 200 + 2 mm: the switch
  r.scan();
  EXPECT_TRUE(r.out.requests.axis_fault[0]);
  EXPECT_FALSE(r.out.requests.axis_fault[1]);
  EXPECT_FALSE(r.engine.causes_gone());  // reset refused while actuated
  r.in.pos_mm[0] = 150.0;
  r.scan();
  EXPECT_FALSE(r.out.requests.axis_fault[0]);
  EXPECT_TRUE(r.engine.causes_gone());
}

TEST(PlcEngine, CarouselToolChangeThroughTheM6Handshake) {
  Rig r(example());
  r.scan(5);
  ASSERT_TRUE(r.engine.handles_tool_change());
  // Empty spindle -> T5: turn to pocket 5, open, close.
  ASSERT_TRUE(r.engine.start_tool_change(5));
  EXPECT_FALSE(r.engine.start_tool_change(6));  // one at a time
  ASSERT_TRUE(r.scan_until([&] { return r.engine.tool_change_state() == Handshake::kDone; }, 10000));
  const auto& plant = r.engine.sim_plant()->plant();
  EXPECT_EQ(plant.get(cp::PlantPoint::kCarouselPocket), 5);
  EXPECT_EQ(plant.get(cp::PlantPoint::kDrawbarClamped), 1);
  r.engine.release_tool_change();
  r.in.tool = 5;  // the NC records the new tool
  r.scan(20);
  EXPECT_EQ(r.value("NC.tool_change_done").i, 0);  // dropped after the request fell
  // T5 -> T2: back to pocket 5 first (return the tool), then 2; the spindle is held off meanwhile.
  ASSERT_TRUE(r.engine.start_tool_change(2));
  bool inhibited = false;
  ASSERT_TRUE(r.scan_until([&] {
    inhibited = inhibited || r.out.requests.spindle_inhibit;
    return r.engine.tool_change_state() == Handshake::kDone;
  }, 10000));
  EXPECT_TRUE(inhibited);
  EXPECT_EQ(plant.get(cp::PlantPoint::kCarouselPocket), 2);
  EXPECT_TRUE(r.faults.empty());
}

TEST(PlcEngine, JammedCarouselRequestsAFaultAndNoAnswerTimesOut) {
  Rig r(example());
  r.scan(5);
  cp::PlantFaults f;
  f.carousel_jam = true;
  r.engine.sim_plant()->set_faults(f);
  ASSERT_TRUE(r.engine.start_tool_change(4));
  ASSERT_TRUE(r.scan_until([&] { return r.out.requests.fault; }, 8000));
  EXPECT_EQ(r.out.requests.fault_code, 1010);  // step 10 overran its 5 s
  // The sequence gave up: the handshake times out at plc.tool_change.timeout_s (30 s).
  ASSERT_TRUE(r.scan_until([&] { return r.engine.tool_change_state() == Handshake::kTimedOut; }, 30000));
  ASSERT_EQ(r.faults.size(), 1u);
  EXPECT_EQ(r.faults[0].kind, PlcFaultKind::kToolChangeTimeout);
  EXPECT_EQ(r.faults[0].code, 4);
  EXPECT_DOUBLE_EQ(r.faults[0].limit, 30.0);
  r.engine.release_tool_change();
  r.scan(2);
  EXPECT_FALSE(r.out.requests.fault);  // the request fell with the handshake: reset possible
  EXPECT_TRUE(r.engine.causes_gone());
}

TEST(PlcEngine, UserMcodes) {
  Rig r(example());
  r.scan(2);
  EXPECT_TRUE(r.engine.handles_mcode(100));
  EXPECT_FALSE(r.engine.handles_mcode(150));  // not in plc.mcodes
  EXPECT_FALSE(r.engine.start_mcode(150, NAN, NAN));
  ASSERT_TRUE(r.engine.start_mcode(100, NAN, NAN));
  ASSERT_TRUE(r.scan_until([&] { return r.engine.mcode_state() == Handshake::kDone; }, 10));
  EXPECT_EQ(r.engine.sim_plant()->plant().get(cp::PlantPoint::kWorkLight), 1);
  r.engine.release_mcode();
  r.scan(2);
  // M102 P0.5: a PLC dwell of 500 ms (mcodes.st scans every cycle).
  ASSERT_TRUE(r.engine.start_mcode(102, 0.5, NAN));
  const auto c0 = r.cycle;
  ASSERT_TRUE(r.scan_until([&] { return r.engine.mcode_state() == Handshake::kDone; }, 2000));
  EXPECT_NEAR(static_cast<double>(r.cycle - c0), 502, 3);
  r.engine.release_mcode();
  r.scan();
  EXPECT_EQ(r.value("NC.mcode_req").i, 0);
}

TEST(PlcEngine, McodeTimeoutIsAFault) {
  Scratch s;
  s.file("p.st", "PROGRAM p\n  ;\nEND_PROGRAM\n");  // never answers
  Rig r(s.load(std::string(kMachine) + "bus: {type: sim}\nplc:\n  mcodes: [{m: 120, timeout_s: 0.05}]\n  programs: [{file: p.st}]\n"));
  ASSERT_TRUE(r.engine.start_mcode(120, 3.0, NAN));
  r.scan(2);
  EXPECT_EQ(r.value("NC.mcode_req").i, 1);
  EXPECT_EQ(r.value("NC.mcode").i, 120);
  EXPECT_DOUBLE_EQ(r.value("NC.mcode_p").r, 3.0);
  ASSERT_TRUE(r.scan_until([&] { return r.engine.mcode_state() == Handshake::kTimedOut; }, 100));
  ASSERT_EQ(r.faults.size(), 1u);
  EXPECT_EQ(r.faults[0].kind, PlcFaultKind::kMcodeTimeout);
  EXPECT_EQ(r.faults[0].code, 120);
  r.scan();
  EXPECT_EQ(r.value("NC.mcode_req").i, 0);
}

TEST(PlcEngine, ScanOrderInputsOnceProgramsInOrderOutputsOnce) {
  Scratch s;
  // a runs first: copies the door into m and counts; b reads m in the same scan and a's counter;
  // a reads b's copy one scan late. The output is written twice in a program: the field sees
  // only the last value.
  s.file("a.st", "PROGRAM a\n  m := door;\n  n := n + 1;\n  a_saw_b := b_copy;\n  light := TRUE;\n  light := FALSE;\nEND_PROGRAM\n");
  s.file("b.st", "PROGRAM b\n  b_copy := n;\n  b_door := m;\nEND_PROGRAM\n");
  s.file("slow.st", "PROGRAM slow\n  runs := runs + 1;\nEND_PROGRAM\n");
  Rig r(s.load(std::string(kMachine) + R"(bus: {type: sim}
plc:
  programs:
    - {file: a.st}
    - {file: b.st}
    - {file: slow.st, period_cycles: 4, offset_cycles: 1}
  signals:
    - {name: door, sim: door_closed}
    - {name: light, sim: work_light}
    - {name: m}
    - {name: n, type: DINT}
    - {name: b_copy, type: DINT}
    - {name: a_saw_b, type: DINT}
    - {name: b_door}
    - {name: runs, type: DINT}
)"));
  bool light_seen = false;
  for (int k = 0; k < 20; ++k) {
    r.scan();
    light_seen = light_seen || r.engine.sim_plant()->plant().get(cp::PlantPoint::kWorkLight) != 0;
  }
  r.in.cycle = r.cycle + 20;  // publish
  r.cycle += 20;
  r.engine.scan(r.in, r.out);
  EXPECT_FALSE(light_seen);
  EXPECT_EQ(r.value("n").i, 21);
  EXPECT_EQ(r.value("b_copy").i, 21);   // same scan
  EXPECT_EQ(r.value("a_saw_b").i, 20);  // previous scan
  EXPECT_EQ(r.value("b_door").i, 1);
  // cycles 1..20 and 40: those with cycle % 4 == 1 -> 1, 5, 9, 13, 17
  EXPECT_EQ(r.value("runs").i, 5);
}

TEST(PlcEngine, ForcingRules) {
  {
    Rig r(example());  // the sim bus: allowed
    ASSERT_TRUE(r.engine.forcing_allowed());
    EXPECT_EQ(r.engine.force("door_closed", "FALSE"), "");
    r.scan();
    EXPECT_TRUE(r.out.requests.feed_hold);  // the programs see the forced input
    r.scan(20);
    const auto snap = r.engine.snapshot();
    bool shown = false;
    for (const auto& v : snap.signals)
      if (v.name == "door_closed") shown = v.forced && v.value.i == 0;
    EXPECT_TRUE(shown);
    EXPECT_EQ(plc_io_json(snap)["signals"][0]["forced"], true);
    // A forced output overrides what the program writes.
    EXPECT_EQ(r.engine.force("work_light", "0"), "");
    r.scan();
    EXPECT_EQ(r.engine.sim_plant()->plant().get(cp::PlantPoint::kWorkLight), 0);  // door "open"
    EXPECT_NE(r.engine.force("NC.feed_hold_req", "FALSE").find("only plc.signals entries"), std::string::npos);
    EXPECT_NE(r.engine.force("drive_enable", "TRUE").find("owned by the NC"), std::string::npos);
    EXPECT_NE(r.engine.force("carousel_pocket", "x").find("'x' is not"), std::string::npos);
    EXPECT_NE(r.engine.force("carousel_pocket", "70000").find("INT in -32768..32767"), std::string::npos);
    EXPECT_NE(r.engine.force("nosuch", "1").find("unknown signal"), std::string::npos);
    EXPECT_EQ(r.engine.unforce("all"), "");
    r.scan();
    EXPECT_FALSE(r.out.requests.feed_hold);
  }
  {
    // Not the sim bus and no plc.allow_forcing: refused.
    Scratch s;
    s.file("p.st", "PROGRAM p\n  out1 := in1;\nEND_PROGRAM\n");
    const std::string base = std::string("loop: {period_us: 1000}\nmachine:\n  axes:\n"
                                         "    - {name: X, node_id: 1}\n    - {name: Y, node_id: 2}\n") +
                             "bus: {type: socketcan, interface: vcan0}\nplc:\n%s  programs: [{file: p.st}]\n"
                             "  signals:\n    - {name: in1}\n    - {name: out1}\n";
    auto yaml = [&](const std::string& extra) {
      std::string y = base;
      y.replace(y.find("%s"), 2, extra);
      return y;
    };
    PlcEngine e(s.load(yaml("")));
    EXPECT_FALSE(e.forcing_allowed());
    EXPECT_NE(e.force("in1", "TRUE").find("forcing is allowed only on the sim bus or with plc.allow_forcing: true"),
              std::string::npos);
    PlcEngine e2(s.load(yaml("  allow_forcing: true\n")));
    EXPECT_EQ(e2.force("in1", "TRUE"), "");
  }
}

TEST(PlcEngine, RuntimeErrorStopsTheProgramFaultsAndResetRestartsIt) {
  Scratch s;
  s.file("p.st", "PROGRAM p\nVAR k : INT := 1; END_VAR\n  lamp := TRUE;\n  q := 10 / d;\n  k := k + 1;\nEND_PROGRAM\n");
  Rig r(s.load(std::string(kMachine) + R"(bus: {type: sim}
plc:
  programs: [{file: p.st}]
  signals:
    - {name: lamp, sim: work_light}
    - {name: d, type: INT, default: 2}
    - {name: q, type: INT}
)"));
  r.scan(3);
  EXPECT_TRUE(r.faults.empty());
  EXPECT_EQ(r.engine.force("d", "0"), "");
  r.scan();
  ASSERT_EQ(r.faults.size(), 1u);
  EXPECT_EQ(r.faults[0].kind, PlcFaultKind::kRuntimeError);
  EXPECT_EQ(r.faults[0].code, 4);  // the line of the division
  EXPECT_EQ(r.engine.sim_plant()->plant().get(cp::PlantPoint::kWorkLight), 0);  // back to default
  r.scan(20);
  const auto st = plc_status_json(r.engine.snapshot());
  EXPECT_EQ(st["programs"][0]["state"], "stopped");
  EXPECT_NE(st["programs"][0]["error"].get<std::string>().find(":4: division by zero"), std::string::npos);
  EXPECT_EQ(st["faults"][0]["kind"], "PLC runtime error");
  // A memory signal keeps its last (forced) value after unforce: give it a good one first.
  EXPECT_EQ(r.engine.force("d", "2"), "");
  r.scan();
  EXPECT_EQ(r.engine.unforce("d"), "");
  r.scan();
  EXPECT_EQ(r.faults.size(), 1u);  // still stopped: no new error
  r.engine.reset();
  r.scan();
  EXPECT_EQ(r.engine.sim_plant()->plant().get(cp::PlantPoint::kWorkLight), 1);
  EXPECT_EQ(r.faults.size(), 1u);
}

TEST(PlcEngine, LostIoCouplerLatchesAFaultUntilItIsBackAndReset) {
  contour::sim::CouplerServer server(1, 5000ms);
  server.start();
  server.set_discrete(0, true);
  Scratch s;
  s.file("p.st", "PROGRAM p\n  valve := door;\nEND_PROGRAM\n");
  Rig r(s.load(std::string(kMachine) + "bus: {type: sim}\nplc:\n  modbus:\n    - {name: io, port: " +
               std::to_string(server.port()) +
               ", poll_hz: 200, timeout_ms: 20, stale_ms: 100}\n  programs: [{file: p.st}]\n"
               "  signals:\n    - {name: door, modbus: {device: io, discrete_input: 0}}\n"
               "    - {name: valve, modbus: {device: io, coil: 3}}\n"));
  r.engine.start();
  auto scan_wall = [&](const std::function<bool()>& f) {
    for (int k = 0; k < 5000; ++k) {  // scans 1 ms apart in wall time: the coupler is real
      r.scan();
      if (f()) return true;
      std::this_thread::sleep_for(1ms);
    }
    return false;
  };
  ASSERT_TRUE(scan_wall([&] { return server.coil(3); }));  // input -> program -> output
  EXPECT_TRUE(r.faults.empty());
  server.stop();
  ASSERT_TRUE(scan_wall([&] { return !r.faults.empty(); }));
  EXPECT_EQ(r.faults[0].kind, PlcFaultKind::kIoStale);
  EXPECT_EQ(r.faults[0].index, 0);
  EXPECT_GT(r.faults[0].value, 0.1);
  EXPECT_EQ(r.value("door").i, 0);  // stale input -> its default
  EXPECT_FALSE(r.engine.causes_gone());
  r.scan(40);
  const auto st = plc_status_json(r.engine.snapshot());
  EXPECT_EQ(st["devices"][0]["state"], "stale");
  EXPECT_EQ(st["faults"][0]["device"], "io");
  server.start();  // back on the same port
  ASSERT_TRUE(scan_wall([&] { return r.engine.causes_gone(); }));
  r.engine.reset();
  r.scan(40);
  EXPECT_TRUE(r.engine.snapshot().faults.empty());
  EXPECT_EQ(r.faults.size(), 1u);  // latched once, not every cycle
  r.engine.stop();
  server.stop();
}

TEST(PlcEngine, GpioLinesThroughTheGpioThread) {
  Scratch s;
  s.file("p.st", "PROGRAM p\n  lamp := NOT door;\nEND_PROGRAM\n");
  Rig r(s.load(std::string(kMachine) + R"(bus: {type: sim}
gpio: {backend: sim, estop: {name: ESTOP}}
plc:
  gpio_poll_ms: 1
  programs: [{file: p.st}]
  signals:
    - {name: door, direction: input, gpio: {name: DOOR}}
    - {name: lamp, direction: output, gpio: {name: LAMP}, default: true}
)"));
  auto* sim = r.engine.sim_gpio();
  ASSERT_NE(sim, nullptr);
  EXPECT_TRUE(sim->output_active("LAMP"));  // requested at its default
  sim->set_input_level("DOOR", true);
  r.engine.start();
  bool ok = false;
  for (int k = 0; k < 5000 && !ok; ++k) {
    r.scan();
    ok = r.value("door").i == 1 && !sim->output_active("LAMP");
    std::this_thread::sleep_for(1ms);
  }
  EXPECT_TRUE(ok);
  r.engine.stop();
  EXPECT_TRUE(sim->output_active("LAMP"));  // back to its default at stop
  r.scan(20);
  const auto io = plc_io_json(r.engine.snapshot());
  EXPECT_EQ(io["signals"][0]["source"], "gpio door (line 'DOOR')");
  EXPECT_EQ(io["signals"][0]["direction"], "input");
}

TEST(PlcEngine, CiaBindingsDataPath) {
  Scratch s;
  s.file("p.st", "PROGRAM p\n  brake_lamp := x_home;\n  ao := ai * 2.0;\n  do3 := di5;\nEND_PROGRAM\n");
  Rig r(s.load(std::string(kMachine) + R"(bus: {type: sim}
plc:
  programs: [{file: p.st}]
  signals:
    - {name: x_home, cia402: {axis: X, input: home_switch}}
    - {name: brake_lamp, cia402: {axis: Y, output: 17}}
    - {name: di5, cia401: {node: 9, digital_input: 2, bit: 5}}
    - {name: do3, cia401: {node: 9, digital_output: 1, bit: 3}}
    - {name: ai, type: REAL, cia401: {node: 9, analog_input: 1, scale: 0.1}}
    - {name: ao, type: REAL, cia401: {node: 9, analog_output: 4, scale: 0.1}}
)"));
  std::array<Cia401Inputs, 1> node{};
  node[0].node_id = 9;
  node[0].valid = true;
  node[0].digital[1] = 1u << 5;
  node[0].analog[0] = 123;  // 12.3
  r.in.cia401 = node;
  r.in.drive_inputs[0] = 1u << 2;  // home switch
  r.in.drive_inputs_valid[0] = true;
  r.scan();
  EXPECT_EQ(r.out.drive_output_mask[1], 1u << 17);
  EXPECT_EQ(r.out.drive_outputs[1], 1u << 17);
  EXPECT_EQ(r.out.drive_output_mask[0], 0u);
  ASSERT_EQ(r.out.cia401_count, 1u);
  EXPECT_EQ(r.out.cia401[0].node_id, 9);
  EXPECT_EQ(r.out.cia401[0].digital[0], 1u << 3);
  EXPECT_EQ(r.out.cia401[0].analog[3], 246);
  // A node without a recent TPDO: its inputs take their defaults.
  node[0].valid = false;
  r.scan();
  EXPECT_EQ(r.out.cia401[0].digital[0], 0);
}

TEST(PlcEngine, BindingsThatDoNotFitTheMachineAreConfigErrors) {
  Scratch s;
  s.file("p.st", "PROGRAM p\n  ;\nEND_PROGRAM\n");
  const cfg::Config c = s.load(std::string(kMachine) +
                               "bus: {type: sim}\nplc:\n  programs: [{file: p.st}]\n  signals:\n"
                               "    - {name: big, cia401: {node: 3, digital_input: 12, bit: 0}}\n");
  try {
    PlcEngine e(c);
    FAIL() << "accepted sub-index 12";
  } catch (const cfg::ConfigError& e) {
    ASSERT_EQ(e.errors().size(), 1u);
    EXPECT_NE(e.errors()[0].find("plc.signals 'big': cia401 sub-index 12"), std::string::npos);
    EXPECT_NE(e.errors()[0].find("c.yaml:"), std::string::npos);
  }
}

TEST(PlcEngine, ScanDoesNotAllocate) {
  Rig r(example());
  r.in.state = MachineState::kRunning;
  r.scan(10);
  ASSERT_TRUE(r.engine.start_tool_change(3));
  std::size_t allocs = 0;
  {
    contour::test::AllocGuard g;
    for (int k = 0; k < 10000; ++k) {
      if (k == 5000) r.engine.sim_plant()->set_door_open(true);
      r.scan();
      if (r.engine.tool_change_state() == Handshake::kDone) r.engine.release_tool_change();
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  EXPECT_TRUE(r.out.requests.feed_hold);
}
