// `plc:` section: the shipped example (the plc: section of config/sim.yaml)
// loads and compiles; every binding kind parses; bad keys, values and bindings are errors naming
// file:line:column and the key path; Structured Text errors of the programs come out of the same
// load (all at once, through ConfigError: exit 78), including an output written by two programs.
#include "config/plc_config.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "config/config.hpp"
#include "tests/support/config_errors.hpp"
#include "tests/support/sim_config.hpp"

namespace cc = contour::config;
namespace plc = contour::control::plc;
using contour::test::any_contains;
using contour::test::config_errors;

namespace {

std::string read(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// config/sim.yaml, which ends with the example plc: section, named as a file in config/
// (program paths resolve against it).
std::string sim_with_plc() { return read(std::string(CONTOUR_SOURCE_DIR) + "/config/sim.yaml"); }
const std::string kSimName = std::string(CONTOUR_SOURCE_DIR) + "/config/sim_plc_test.yaml";

// A scratch directory with .st files for error tests.
struct TempDir {
  TempDir() {
    path = std::filesystem::temp_directory_path() /
           ("plc_config_test_" + std::to_string(::getpid()) + "_" +
            std::to_string(counter++));
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  void write(const std::string& name, const std::string& text) const {
    std::ofstream(path / name) << text;
  }
  [[nodiscard]] std::string config(const std::string& name) const { return (path / name).string(); }
  std::filesystem::path path;
  static inline int counter = 0;
};

const char* kMinimal = R"(loop: {period_us: 1000}
bus: {type: sim}
machine:
  axes:
    - {name: X}
    - {name: Y}
    - {name: Z}
)";

}  // namespace

TEST(PlcConfig, ExampleMachineLoadsAndCompiles) {
  const cc::Config cfg = cc::load_config_string(sim_with_plc(), kSimName);
  const cc::PlcConfig& p = cfg.plc;
  ASSERT_TRUE(p.present);
  ASSERT_NE(p.compiled, nullptr);
  EXPECT_EQ(p.programs.size(), 5u);
  EXPECT_EQ(p.compiled->programs.size(), 5u);
  for (const auto& prog : p.compiled->programs) {
    ASSERT_NE(prog, nullptr);
    EXPECT_LE(prog->worst_case, p.instruction_budget);
  }
  EXPECT_EQ(p.compiled->programs[2]->name, "toolchanger");
  EXPECT_EQ(p.programs[4].period_cycles, 10);
  ASSERT_EQ(p.mcodes.size(), 3u);
  EXPECT_EQ(p.mcodes[2].m, 102);
  EXPECT_DOUBLE_EQ(p.mcodes[2].timeout_s, 120.0);
  EXPECT_DOUBLE_EQ(p.mcodes[0].timeout_s, 30.0);
  EXPECT_TRUE(p.tool_change);
  // Image: user signals, the fixed gpio roles, NC.* (per axis for X Y Z).
  const auto* door = p.compiled->symbols.find("door_closed");
  ASSERT_NE(door, nullptr);
  EXPECT_EQ(door->access, plc::Access::kRead);
  ASSERT_NE(p.compiled->symbols.find("NC.pos_x"), nullptr);
  ASSERT_NE(p.compiled->symbols.find("NC.axis_fault_z"), nullptr);
  EXPECT_EQ(p.compiled->symbols.find("drive_enable")->access, plc::Access::kRead);
  EXPECT_EQ(p.compiled->symbols.find("coolant_flood")->access, plc::Access::kReadWrite);
  EXPECT_EQ(p.compiled->entries.size(), p.compiled->symbols.all().size());
}

// The HIL variant: the same programs on contour-machine-sim's coupler.
TEST(PlcConfig, HilFragmentLoadsWithTheSamePrograms) {
  const std::string y = contour::test::sim_yaml(contour::test::SimPlc::kNone) + "\n" +
                        read(std::string(CONTOUR_SOURCE_DIR) + "/config/plc/hil_machine.yaml");
  const cc::Config cfg = cc::load_config_string(y, kSimName);
  ASSERT_NE(cfg.plc.compiled, nullptr);
  ASSERT_EQ(cfg.plc.modbus.size(), 1u);
  EXPECT_EQ(cfg.plc.modbus[0].transport.port, 1503);
  EXPECT_EQ(cfg.plc.compiled->programs.size(), 5u);
}

TEST(PlcConfig, EveryBindingKind) {
  const std::string y = std::string(kMinimal) + R"(plc:
  allow_forcing: true
  instruction_budget: 5000
  gpio_poll_ms: 5
  modbus:
    - {name: io1, transport: tcp, host: 10.0.0.5, port: 1502, unit_id: 3, poll_hz: 50, timeout_ms: 10, stale_ms: 100}
    - {name: io2, transport: rtu, device: /dev/ttyUSB1, baud: 19200, parity: even, unit_id: 2}
  signals:
    - {name: door, direction: input, gpio: {name: DOOR, active_low: true}}
    - {name: lamp, direction: output, gpio: {chip: gpiochip1, offset: 7}}
    - {name: air, modbus: {device: io1, discrete_input: 4}}
    - {name: valve, modbus: {device: io1, coil: 2}, default: true}
    - {name: level, type: REAL, modbus: {device: io2, input_register: 10, scale: 0.01, signed: false}}
    - {name: setpoint, type: DINT, direction: output, modbus: {device: io1, holding_register: 20}}
    - {name: ready_bit, direction: input, modbus: {device: io1, holding_register: 30, bit: 3, invert: true}}
    - {name: x_neg, cia402: {axis: X, input: negative_limit}}
    - {name: y_maker, cia402: {axis: y, input: 17}}
    - {name: z_out, cia402: {axis: Z, output: 16}}
    - {name: node5_in, cia401: {node: 5, digital_input: 1, bit: 3}}
    - {name: node5_ao, type: REAL, cia401: {node: 5, analog_output: 2, scale: 0.5}}
    - {name: pocket, type: INT, sim: carousel_pocket}
    - {name: count, type: DINT, default: 7}
    - {name: delay, type: TIME, default: 1500}
)";
  const cc::Config cfg = cc::load_config_string(y, "t.yaml");
  const cc::PlcConfig& p = cfg.plc;
  ASSERT_EQ(p.signals.size(), 15u);
  EXPECT_TRUE(p.allow_forcing);
  EXPECT_EQ(p.instruction_budget, 5000u);
  EXPECT_EQ(p.gpio_poll_ms, 5);
  ASSERT_EQ(p.modbus.size(), 2u);
  EXPECT_EQ(p.modbus[0].transport.port, 1502);
  EXPECT_EQ(p.modbus[0].stale_after.count(), 100000);
  EXPECT_EQ(p.modbus[1].transport.parity, 'E');
  const auto& s = p.signals;
  EXPECT_EQ(s[0].binding.kind, cc::PlcBindingKind::kGpio);
  EXPECT_EQ(s[0].binding.line.name, "DOOR");
  EXPECT_TRUE(s[0].binding.line.active_low);
  EXPECT_EQ(s[1].binding.line.offset, 7);
  EXPECT_EQ(s[1].direction, cc::PlcDirection::kOutput);
  EXPECT_EQ(s[2].direction, cc::PlcDirection::kInput);
  EXPECT_EQ(s[2].binding.table, cc::ModbusTable::kDiscreteInput);
  EXPECT_EQ(s[3].direction, cc::PlcDirection::kOutput);
  EXPECT_EQ(s[3].initial.i, 1);
  EXPECT_EQ(s[4].binding.device, 1);
  EXPECT_FALSE(s[4].binding.is_signed);
  EXPECT_DOUBLE_EQ(s[4].binding.scale, 0.01);
  EXPECT_EQ(s[5].binding.table, cc::ModbusTable::kHoldingRegister);
  EXPECT_EQ(s[6].binding.bit, 3);
  EXPECT_TRUE(s[6].binding.invert);
  EXPECT_EQ(s[7].binding.axis, 0);
  EXPECT_EQ(s[7].binding.bit, cc::kCia402NegativeLimit);
  EXPECT_EQ(s[8].binding.axis, 1);
  EXPECT_EQ(s[8].binding.bit, 17);
  EXPECT_EQ(s[9].direction, cc::PlcDirection::kOutput);
  EXPECT_EQ(s[10].binding.object, cc::Cia401Object::kDigitalInput);
  EXPECT_EQ(s[10].binding.node_id, 5);
  EXPECT_EQ(s[11].direction, cc::PlcDirection::kOutput);
  EXPECT_EQ(s[12].binding.point, plc::PlantPoint::kCarouselPocket);
  EXPECT_EQ(s[13].direction, cc::PlcDirection::kMemory);
  EXPECT_EQ(s[13].initial.i, 7);
  EXPECT_EQ(s[14].initial.i, 1500000000);
  ASSERT_NE(p.compiled, nullptr);  // no programs: the image alone
}

TEST(PlcConfig, BadKeysValuesAndBindings) {
  const std::string y = std::string(kMinimal) + R"(plc:
  instruction_budget: 10
  colour: blue
  modbus:
    - {name: io1, port: 70000}
  signals:
    - {name: 3d, modbus: {device: io1, coil: 1}}
    - {name: air, modbus: {device: nowhere, discrete_input: 4}}
    - {name: lamp, gpio: {name: LAMP}}
    - {name: both, modbus: {device: io1, coil: 1, discrete_input: 2}}
    - {name: word, type: INT, modbus: {device: io1, coil: 5}}
    - {name: reg, modbus: {device: io1, input_register: 5}}
    - {name: hr, type: INT, modbus: {device: io1, holding_register: 5}}
    - {name: brake, cia402: {axis: X, output: 0}}
    - {name: w_in, cia402: {axis: W, input: home_switch}}
    - {name: nosuch, sim: teleporter}
    - {name: END_IF}
    - {name: estop, sim: door_closed}
    - {name: air, type: BOOL}
    - {name: in_out, direction: output, sim: door_closed}
    - {name: lamp2, direction: output, gpio: {name: LAMP}}
    - {name: coil_a, modbus: {device: io1, coil: 9}}
    - {name: coil_b, modbus: {device: io1, coil: 9}}
)";
  const auto e = config_errors(y, "t.yaml");
  auto expect = [&](const std::string& needle) {
    EXPECT_TRUE(any_contains(e, needle)) << "missing: " << needle;
  };
  expect("plc.instruction_budget");
  expect("plc.colour: unknown key");
  expect("plc.modbus[0].port");
  expect("plc.signals[0].name: '3d' is not an identifier");
  expect("plc.signals[1].modbus.device: no plc.modbus device named 'nowhere'");
  expect("plc.signals[2].gpio: a GPIO line is an input or an output: give direction");
  expect("plc.signals[3].modbus.coil: give exactly one of");
  expect("plc.signals[4].modbus.device: a coil or discrete input is BOOL, not INT");
  expect("plc.signals[5].modbus.bit: a BOOL in a register needs bit");
  expect("plc.signals[6].modbus.holding_register: a holding register is an input or an output");
  expect("plc.signals[7].cia402.output: 0x60FE bits 0..15 are the drive's (bit 0: brake)");
  expect("plc.signals[8].cia402.axis: no axis 'W'");
  expect("plc.signals[9].sim: no simulated point 'teleporter'");
  expect("plc.signals[10].name: 'END_IF' is a reserved word");
  expect("plc.signals[11].name: 'estop' is a fixed role");
  expect("plc.signals[12].name: 'air' is declared twice");
  expect("plc.signals[13].direction: sim point 'door_closed' is an input");
  expect("plc.signals[14].name: 'lamp2': GPIO line 'LAMP' is already used by signal 'lamp'");
  expect("plc.signals[16].name: 'coil_b': coil 9 of 'io1' is already driven by signal 'coil_a'");
  // file:line:column on each
  for (const auto& m : e) EXPECT_EQ(m.rfind("t.yaml:", 0), 0u) << m;
}

// CiA 401 bindings (CAN I/O modules, daemon/PLC.md "CAN I/O modules"): every wrong field is an
// error naming the file, line and field.
TEST(PlcConfig, Cia401FieldErrorsNameTheField) {
  const std::string y = std::string(kMinimal) + R"(plc:
  signals:
    - {name: a, cia401: {node: 0, digital_input: 1, bit: 0}}
    - {name: b, cia401: {node: 5, digital_input: 1, digital_output: 2, bit: 0}}
    - {name: c, cia401: {node: 5, digital_output: 1, bit: 8}}
    - {name: d, cia401: {node: 5, digital_output: 1}}
    - {name: e, type: INT, cia401: {node: 5, digital_input: 1, bit: 1}}
    - {name: f, cia401: {node: 5, analog_input: 1}}
    - {name: g, type: INT, cia401: {node: 5, analog_output: 1, scale: 2.0}}
    - {name: h, direction: output, cia401: {node: 5, digital_input: 1, bit: 3}}
    - {name: i, cia401: {node: 5, digital_input: 0, bit: 3}}
    - {name: j, cia401: {node: 5, digital_output: 1, bit: 1, colour: red}}
)";
  const auto e = config_errors(y, "t.yaml");
  auto expect = [&](const std::string& needle) {
    EXPECT_TRUE(any_contains(e, needle)) << "missing: " << needle;
  };
  expect("plc.signals[0].cia401.node");
  expect("plc.signals[1].cia401.node: give exactly one of digital_input, digital_output");
  expect("plc.signals[2].cia401.bit");
  expect("plc.signals[3].cia401.bit");
  expect("plc.signals[4].cia401.node: a digital CiA 401 point is BOOL");
  expect("plc.signals[5].cia401.node: an analog CiA 401 point is INT, REAL or LREAL");
  expect("plc.signals[6].cia401.scale: only for REAL and LREAL signals");
  expect("plc.signals[7].cia401.node: 0x6000/0x6401 are inputs (direction)");
  expect("plc.signals[8].cia401.digital_input");
  expect("plc.signals[9].cia401.colour: unknown key");
  for (const auto& m : e) EXPECT_EQ(m.rfind("t.yaml:", 0), 0u) << m;
}

TEST(PlcConfig, StructuredTextErrorsComeOutOfTheSameLoad) {
  TempDir d;
  d.write("a.st",
          "PROGRAM a\n"
          "  lamp := door_close;\n"    // unknown signal
          "  count := lamp;\n"         // type mismatch
          "  door := TRUE;\n"          // assignment to an input
          "END_PROGRAM\n");
  d.write("b.st",
          "PROGRAM b\n"
          "  lamp := TRUE\n"           // syntax: missing ';'
          "END_PROGRAM\n");
  d.write("c.st", "PROGRAM c\n  lamp2 := TRUE;\n  NC.feed_hold_req := TRUE;\nEND_PROGRAM\n");
  d.write("e.st", "PROGRAM e\n  NC.feed_hold_req := FALSE;\n  lamp2 := FALSE;\nEND_PROGRAM\n");
  const std::string y = std::string(kMinimal) + R"(plc:
  programs:
    - {file: a.st}
    - {file: b.st}
    - {file: c.st}
    - {file: e.st}
    - {file: missing.st}
  signals:
    - {name: door, sim: door_closed}
    - {name: lamp, sim: work_light}
    - {name: lamp2, type: BOOL}
    - {name: count, type: INT}
)";
  std::ofstream(d.config("cfg.yaml")) << y;
  const auto e = contour::test::config_errors_of([&] { cc::load_config_file(d.config("cfg.yaml")); });
  auto expect = [&](const std::string& needle) {
    EXPECT_TRUE(any_contains(e, needle)) << "missing: " << needle << "\n in:\n"
                                         << [&] { std::string s; for (auto& x : e) s += x + "\n"; return s; }();
  };
  const std::string a = d.config("a.st"), b = d.config("b.st"), e_st = d.config("e.st");
  expect("plc.programs[4].file: cannot read '" + d.config("missing.st") + "'");
  // Missing file: nothing compiled, but the YAML errors are all there. Fix it and load again.
  d.write("missing.st", "PROGRAM m\nEND_PROGRAM\n");
  const auto e2 = contour::test::config_errors_of([&] { cc::load_config_file(d.config("cfg.yaml")); });
  auto expect2 = [&](const std::string& needle) {
    EXPECT_TRUE(any_contains(e2, needle)) << "missing: " << needle;
  };
  expect2("plc.programs[0].file: " + a + ":2:11: unknown variable or signal 'door_close'");
  expect2("plc.programs[0].file: " + a + ":3:12: type mismatch: BOOL where INT is expected");
  expect2("plc.programs[0].file: " + a + ":4:3: assignment to an input: 'door' is an input");
  expect2("plc.programs[1].file: " + b + ":3:1: ';' expected, found 'END_PROGRAM'");
  // lamp2 is memory (several writers allowed); NC.feed_hold_req is a request: one writer.
  expect2("plc.programs[3].file: " + e_st +
          ":2:3: 'NC.feed_hold_req' is also written by program 'c'");
  EXPECT_FALSE(any_contains(e2, "'lamp2' is also written"));
  EXPECT_EQ(e2.size(), 5u);
}

TEST(PlcConfig, AxisNamesFollowTheMachine) {
  cc::Diagnostics diag("t.yaml");
  cc::PlcConfig p;
  {
    cc::Section top(cc::load_yaml_string("plc:\n  signals:\n    - {name: u_home, cia402: {axis: U, input: home_switch}}\n", "t.yaml"), "", diag);
    cc::Section sec = top.child("plc");
    p = cc::parse_plc(sec, {"X", "U"});
  }
  EXPECT_TRUE(diag.errors().empty());
  ASSERT_NE(p.compiled, nullptr);
  EXPECT_NE(p.compiled->symbols.find("NC.pos_u"), nullptr);
  EXPECT_EQ(p.compiled->symbols.find("NC.pos_y"), nullptr);
  EXPECT_EQ(p.signals[0].binding.axis, 1);
}
