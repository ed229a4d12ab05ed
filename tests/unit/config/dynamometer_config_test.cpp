// `dynamometer:`, `spindle:` and `gpio:` sections: full examples parse into the drivers' settings,
// defaults, and bad input reported with file:line:column and key path.
#include "config/dynamometer_config.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>

#include <cstdio>
#include <string>

#include "config/gpio_config.hpp"
#include "config/spindle_config.hpp"
#include "tests/support/config_errors.hpp"
#include "tests/support/sim_config.hpp"

namespace cc = contour::config;
namespace dm = contour::drivers::modbus;

namespace {
template <typename T, typename F>
T parse(const std::string& yaml, const std::string& key, F fn, std::vector<std::string>& errors) {
  cc::Diagnostics diag("test.yaml");
  T out;
  {
    cc::Section top(cc::load_yaml_string(yaml, "test.yaml"), "", diag);
    for (const auto& kv : top.node()) top.accept(kv.first.as<std::string>());  // other sections
    cc::Section sec = top.child(key);
    out = fn(sec);
  }
  errors = diag.errors();
  return out;
}
std::string joined(const std::vector<std::string>& e) {
  std::string s;
  for (const auto& x : e) s += x + "\n";
  return s;
}
bool has_error(const std::vector<std::string>& e, const std::string& needle) {
  return joined(e).find(needle) != std::string::npos;
}
}  // namespace

TEST(DynamometerConfig, FullTcpExample) {
  const std::string y = R"(dynamometer:
  transport: tcp
  host: 127.0.0.1
  port: 1502
  unit_id: 3
  function: holding
  channels:
    fx: {address: 0, type: float32, word_order: cdab}
    fz: {address: 4, type: int16, scale: 0.1, offset_n: -2.5}
  status: {address: 6, valid_bit: 3, valid_when: clear}
  poll_rate_hz: 500
  timeout_ms: 15
  stale_ms: 30
  filter: {moving_average: false, butterworth_order: 4, cutoff_hz: 20}
)";
  std::vector<std::string> err;
  const auto c = parse<cc::DynamometerConfig>(y, "dynamometer", cc::parse_dynamometer, err);
  ASSERT_TRUE(err.empty()) << joined(err);
  EXPECT_TRUE(c.enabled);
  EXPECT_EQ(c.reader.transport.transport, dm::Transport::kTcp);
  EXPECT_EQ(c.reader.transport.port, 1502);
  EXPECT_EQ(c.reader.transport.unit_id, 3);
  EXPECT_EQ(c.reader.transport.response_timeout.count(), 15000);
  EXPECT_EQ(c.reader.map.function, dm::RegisterFunction::kHolding);
  EXPECT_TRUE(c.reader.map.channels[0].enabled);
  EXPECT_EQ(c.reader.map.channels[0].order, dm::WordOrder::kCdab);
  EXPECT_FALSE(c.reader.map.channels[1].enabled);
  EXPECT_EQ(c.reader.map.channels[2].type, dm::RegisterType::kInt16);
  EXPECT_DOUBLE_EQ(c.reader.map.channels[2].scale, 0.1);
  EXPECT_DOUBLE_EQ(c.reader.map.channels[2].offset_N, -2.5);
  EXPECT_TRUE(c.reader.map.status.enabled);
  EXPECT_EQ(c.reader.map.status.valid_bit, 3u);
  EXPECT_FALSE(c.reader.map.status.valid_when_set);
  EXPECT_EQ(c.reader.stale_after.count(), 30000);
  EXPECT_TRUE(c.reader.filter_enabled);
  EXPECT_EQ(c.reader.filter.butterworth_order, 4);
  EXPECT_FALSE(c.reader.filter.moving_average);
  EXPECT_DOUBLE_EQ(c.reader.filter.sample_rate_hz, 500.0);
}

TEST(DynamometerConfig, RtuDefaultsAndAbsent) {
  std::vector<std::string> err;
  const auto c = parse<cc::DynamometerConfig>(
      "dynamometer:\n  transport: rtu\n  device: /dev/ttyS1\n  parity: even\n  channels:\n    fy: "
      "{address: 10}\n",
      "dynamometer", cc::parse_dynamometer, err);
  ASSERT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(c.reader.transport.transport, dm::Transport::kRtu);
  EXPECT_EQ(c.reader.transport.parity, 'E');
  EXPECT_EQ(c.reader.transport.baud, 115200);
  EXPECT_DOUBLE_EQ(c.reader.poll_rate_hz, 200.0);
  EXPECT_EQ(c.reader.transport.response_timeout.count(), 20000);
  EXPECT_EQ(c.reader.map.function, dm::RegisterFunction::kInput);
  const auto absent =
      parse<cc::DynamometerConfig>("other: 1\n", "dynamometer", cc::parse_dynamometer, err);
  EXPECT_FALSE(absent.enabled);
}

TEST(DynamometerConfig, BadInputNamesFileLineAndKey) {
  const std::string y = R"(dynamometer:
  transport: tcp
  channels:
    fx: {address: 0, type: float64, word_order: abdc}
    fz: {address: 100, type: int16}
  poll_rate_hz: 5000
  filter: {butterworth_order: 3}
  bogus: 1
)";
  std::vector<std::string> err;
  (void)parse<cc::DynamometerConfig>(y, "dynamometer", cc::parse_dynamometer, err);
  const std::string all = joined(err);
  std::printf("[messages]\n%s", all.c_str());
  EXPECT_TRUE(has_error(err, "test.yaml:4:")) << all;
  EXPECT_TRUE(has_error(err, "dynamometer.channels.fx.type")) << all;
  EXPECT_TRUE(has_error(err, "dynamometer.channels.fx.word_order")) << all;
  EXPECT_TRUE(has_error(err, "dynamometer.channels")) << all;  // span > 32 registers
  EXPECT_TRUE(has_error(err, "dynamometer.poll_rate_hz")) << all;
  EXPECT_TRUE(has_error(err, "dynamometer.filter.butterworth_order")) << all;
  EXPECT_TRUE(has_error(err, "dynamometer.bogus")) << all;
}

TEST(SpindleConfig, VfdExampleAndErrors) {
  const std::string y = R"(spindle:
  type: modbus_vfd
  min_rpm: 500
  max_rpm: 12000
  rate_rpm_s: 3000
  vfd:
    device: /dev/ttyUSB1
    baud: 19200
    setpoint_register: 8192
    setpoint_counts_per_rpm: 0.5
    run: {kind: coil, address: 3}
    actual_register: 8193
)";
  std::vector<std::string> err;
  const auto c = parse<cc::SpindleConfig>(y, "spindle", cc::parse_spindle, err);
  ASSERT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(c.type, "modbus_vfd");
  EXPECT_EQ(c.vfd.transport.transport, dm::Transport::kRtu);
  EXPECT_EQ(c.vfd.setpoint_register, 8192);
  EXPECT_TRUE(c.vfd.run_is_coil);
  EXPECT_DOUBLE_EQ(c.vfd.limits.rate_rpm_s, 3000.0);
  EXPECT_DOUBLE_EQ(c.limits.min_rpm, 500.0);

  (void)parse<cc::SpindleConfig>("spindle:\n  type: canopen\n  min_rpm: 900\n  max_rpm: 100\n",
                                 "spindle", cc::parse_spindle, err);
  EXPECT_TRUE(has_error(err, "spindle.node_id")) << joined(err);
  EXPECT_TRUE(has_error(err, "spindle.min_rpm")) << joined(err);
  const auto can = parse<cc::SpindleConfig>("spindle:\n  type: canopen\n  node_id: 5\n", "spindle",
                                            cc::parse_spindle, err);
  EXPECT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(can.node_id, 5);
}

TEST(SpindleConfig, AtSpeedWaitSimTypeAndCrossChecksWithTheBus) {
  std::vector<std::string> err;
  const auto c = parse<cc::SpindleConfig>(
      "spindle:\n  type: sim\n  sim_tau_s: 0.5\n  at_speed_wait: force\n", "spindle",
      cc::parse_spindle, err);
  EXPECT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(c.at_speed_wait, cc::SpindleConfig::Wait::kForce);
  EXPECT_DOUBLE_EQ(c.sim_tau_s, 0.5);
  (void)parse<cc::SpindleConfig>("spindle:\n  at_speed_wait: sometimes\n  sim_tau_s: 0\n",
                                 "spindle", cc::parse_spindle, err);
  EXPECT_TRUE(has_error(err, "spindle.at_speed_wait")) << joined(err);
  EXPECT_TRUE(has_error(err, "spindle.sim_tau_s")) << joined(err);
  // Whole-file checks: a canopen spindle is the bus' spindle node; sim only on the sim bus.
  using contour::test::any_contains;
  using contour::test::config_errors;
  const std::string root = std::string(CONTOUR_SOURCE_DIR) + "/config/";
  auto with = [](const std::string& file, const std::string& from, const std::string& to) {
    // sim.yaml's copy with its machine logic's program paths made absolute (tests/support).
    std::ifstream in(file);
    std::string t = file.ends_with("/sim.yaml") ? contour::test::sim_yaml()
                                                : std::string((std::istreambuf_iterator<char>(in)),
                                                              std::istreambuf_iterator<char>());
    const auto at = t.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) t.replace(at, from.size(), to);
    return t;
  };
  auto e = config_errors(with(root + "hil.yaml", "  type: canopen\n  node_id: 4", "  type: canopen\n  node_id: 5"));
  EXPECT_TRUE(any_contains(e, "spindle.node_id")) << (e.empty() ? "" : e[0]);
  EXPECT_TRUE(any_contains(e, "bus.spindle.node_id (4)")) << (e.empty() ? "" : e[0]);
  e = config_errors(with(root + "hil.yaml", "  type: canopen\n  node_id: 4", "  type: sim"));
  EXPECT_TRUE(any_contains(e, "spindle.type")) << (e.empty() ? "" : e[0]);
  e = config_errors(with(root + "sim.yaml", "  type: sim\n", "  type: canopen\n  node_id: 4\n"));
  EXPECT_TRUE(any_contains(e, "bus.spindle")) << (e.empty() ? "" : e[0]);
  EXPECT_TRUE(config_errors(with(root + "sim.yaml", "x", "x")).empty());
}

TEST(GpioConfig, LinesByOffsetAndNameAndErrors) {
  const std::string y = R"(gpio:
  backend: libgpiod
  chip: gpiochip0
  estop: {offset: 17, debounce_ms: 2}
  drive_enable: {offset: 18}
  spindle_enable: {name: SPINDLE_EN}
  coolant_flood: {offset: 21, chip: gpiochip1, active_low: true}
)";
  std::vector<std::string> err;
  const auto c = parse<cc::GpioConfig>(y, "gpio", cc::parse_gpio, err);
  ASSERT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(c.backend, "libgpiod");
  EXPECT_EQ(c.lines.estop.offset, 17);
  EXPECT_TRUE(c.lines.estop.active_low);  // E-stop active-low by default
  EXPECT_EQ(c.lines.estop_debounce.count(), 2000);
  EXPECT_EQ(c.lines.spindle_enable.name, "SPINDLE_EN");
  EXPECT_EQ(c.lines.coolant_flood.chip, "gpiochip1");
  EXPECT_TRUE(c.lines.coolant_flood.active_low);
  EXPECT_FALSE(c.lines.coolant_mist.configured());

  (void)parse<cc::GpioConfig>("gpio:\n  backend: sim\n  drive_enable: {offset: 1, name: X}\n",
                              "gpio", cc::parse_gpio, err);
  EXPECT_TRUE(has_error(err, "gpio.estop")) << joined(err);
  EXPECT_TRUE(has_error(err, "gpio.drive_enable.name")) << joined(err);
  EXPECT_TRUE(has_error(err, "gpio.drive_enable.chip")) << joined(err);
}

// The snippet proposed for config/hil.yaml (contour-machine-sim serves it on 127.0.0.1:1502).
TEST(DynamometerConfig, ProposedHilSnippetParses) {
  const std::string y = R"(dynamometer:
  transport: tcp
  host: 127.0.0.1
  port: 1502
  unit_id: 1
  function: input
  channels:
    fx: {address: 0, type: float32, word_order: abcd}
    fy: {address: 2, type: float32, word_order: abcd}
    fz: {address: 4, type: float32, word_order: abcd}
  status: {address: 6, valid_bit: 0}
  poll_rate_hz: 200
  timeout_ms: 20
  stale_ms: 50
  filter: {teeth: 4, min_spindle_rpm: 100, butterworth_order: 2, cutoff_hz: 10}
gpio:
  backend: sim
  estop: {name: ESTOP, debounce_ms: 5}
  drive_enable: {name: DRIVE_EN}
  spindle_enable: {name: SPINDLE_EN}
  coolant_mist: {name: MIST}
  coolant_flood: {name: FLOOD}
  alive: {name: ALIVE}
)";
  std::vector<std::string> err;
  const auto d = parse<cc::DynamometerConfig>(y, "dynamometer", cc::parse_dynamometer, err);
  EXPECT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(dm::register_block(d.reader.map).count, 7);
  const auto g = parse<cc::GpioConfig>(y, "gpio", cc::parse_gpio, err);
  EXPECT_TRUE(err.empty()) << joined(err);
  EXPECT_EQ(g.backend, "sim");
  EXPECT_TRUE(g.lines.alive.configured());
}
