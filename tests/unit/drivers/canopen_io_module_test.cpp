// CiA 401 I/O modules in the CANopen master (issue 20): the PDOs that follow from what the PLC
// uses, the exchange beside a drive over a scripted fake bus (inputs from the module's TPDO,
// outputs in its RPDO after the SYNC, allocation-free over 10k cycles), a silent module latching
// the missed-TPDO fault naming its node, the bus-load estimate counting its frames, and the
// composition root's mapping from plc.signals (config errors naming the signal).
#include <gtest/gtest.h>

#include <cstdio>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "daemon/canopen_master_config.hpp"
#include "drivers/canopen/master.hpp"
#include "tests/support/alloc_counter.hpp"

namespace co = contour::drivers::canopen;
using contour::drivers::BusState;
using contour::drivers::CanFrame;
using contour::drivers::CanStats;
using contour::drivers::SendResult;

namespace {

// Node 1: a drive answering every SYNC with {statusword, position}. Node 5: a CiA 401 module
// answering with TPDO1 {0x6000:01, 0x6000:02, 0x6401:01} = {di1, di2, ai1} (4 bytes). Frames the
// master sends to 0x205 (the module's RPDO1) are recorded in order with the SYNC count.
class FakeBus final : public contour::drivers::CanBus {
 public:
  std::array<CanFrame, 64> ring{};
  std::size_t head = 0, tail = 0;
  bool module_silent = false;
  std::uint8_t di1 = 0, di2 = 0;
  std::int16_t ai1 = 0;
  std::uint64_t syncs = 0;
  CanFrame last_rpdo{};
  std::uint64_t rpdos = 0, rpdo_before_first_sync = 0;
  void push(const CanFrame& f) {
    ring[head] = f;
    head = (head + 1) % ring.size();
  }
  SendResult send(const CanFrame& f) noexcept override {
    if (f.id == 0x205) {
      last_rpdo = f;
      ++rpdos;
      if (syncs == 0) ++rpdo_before_first_sync;
    }
    if (f.id == 0x080) {
      ++syncs;
      CanFrame t;
      t.id = 0x181;
      t.dlc = 6;
      co::put_u16(&t.data[0], 0x0237);
      co::put_u32(&t.data[2], 0);
      push(t);
      if (!module_silent) {
        CanFrame m;
        m.id = 0x185;
        m.dlc = 4;
        m.data[0] = di1;
        m.data[1] = di2;
        co::put_u16(&m.data[2], static_cast<std::uint16_t>(ai1));
        push(m);
      }
    }
    return SendResult::kOk;
  }
  bool receive(CanFrame& f) noexcept override {
    if (head == tail) return false;
    f = ring[tail];
    tail = (tail + 1) % ring.size();
    return true;
  }
  bool wait_readable(std::int64_t) noexcept override { return head != tail; }
  CanStats stats() const noexcept override { return {}; }
  BusState bus_state() const noexcept override { return BusState::kErrorActive; }
  void clear_bus_state() noexcept override {}
};

co::NodeSetup drive(std::uint8_t id) {
  co::NodeSetup s;
  s.node_id = id;
  s.name = "X";
  s.rpdo = co::default_rpdo(co::DriveMode::kCsv);
  s.tpdo = co::default_tpdo();
  return s;
}

co::NodeSetup module5() {
  co::NodeSetup s;
  s.kind = co::NodeKind::kIoModule;
  s.node_id = 5;
  s.name = "I/O module";
  s.io.digital_inputs = 0x03;   // 0x6000:01, :02
  s.io.analog_inputs = 0x01;    // 0x6401:01
  s.io.digital_outputs = 0x01;  // 0x6200:01
  s.io.analog_outputs = 0x02;   // 0x6411:02
  return s;
}

co::MasterConfig drive_and_module() {
  co::MasterConfig c;
  c.nodes = {drive(1), module5()};
  c.tpdo_deadline_us = 1000;
  c.missed_tpdo_fault = 3;
  return c;
}

std::string entries(const co::PdoMapping& m) {
  std::string s;
  char b[24];
  for (std::size_t k = 0; k < m.count; ++k) {
    std::snprintf(b, sizeof b, "%s%04X:%02X/%u", k ? " " : "", m.entries[k].index, m.entries[k].sub,
                  static_cast<unsigned>(m.entries[k].bits));
    s += b;
  }
  return s;
}

}  // namespace

TEST(CanopenIoModule, OnlyTheObjectsUsedAreMappedInPdosOfAtMost8Bytes) {
  const auto tx = co::io_module_pdos(module5().io, false);
  ASSERT_EQ(tx.size(), 1u);
  EXPECT_EQ(entries(tx[0]), "6000:01/8 6000:02/8 6401:01/16");
  const auto rx = co::io_module_pdos(module5().io, true);
  ASSERT_EQ(rx.size(), 1u);
  EXPECT_EQ(entries(rx[0]), "6200:01/8 6411:02/16");
  // Everything: 8 digital bytes fill TPDO1, the 8 analog words TPDO2 and TPDO3.
  co::IoModuleMap all{0xFF, 0xFF, 0xFF, 0xFF};
  const auto big = co::io_module_pdos(all, false);
  ASSERT_EQ(big.size(), 3u);
  EXPECT_EQ(big[0].bytes(), 8u);
  EXPECT_EQ(entries(big[1]), "6401:01/16 6401:02/16 6401:03/16 6401:04/16");
  EXPECT_EQ(entries(big[2]), "6401:05/16 6401:06/16 6401:07/16 6401:08/16");
  // Outputs only: no TPDO (the module is watched by its heartbeat alone).
  co::IoModuleMap out_only{};
  out_only.digital_outputs = 0x80;
  EXPECT_TRUE(co::io_module_pdos(out_only, false).empty());
  EXPECT_EQ(entries(co::io_module_pdos(out_only, true).at(0)), "6200:08/8");
}

TEST(CanopenIoModule, ReceiveFiltersTakeTheModulesTpdos) {
  const auto f = co::master_rx_filters(drive_and_module());
  auto has = [&](std::uint32_t id) {
    for (const auto& x : f)
      if (x.id == id) return true;
    return false;
  };
  EXPECT_TRUE(has(0x185));
  EXPECT_TRUE(has(0x085));   // EMCY
  EXPECT_TRUE(has(0x705));   // heartbeat
  EXPECT_FALSE(has(0x285));  // the module maps one TPDO
}

TEST(CanopenIoModule, InputsAndOutputsAreExchangedEachCycleWithoutAllocation) {
  FakeBus bus;
  co::Master m(bus, drive_and_module());
  m.set_request_all(co::DriveRequest::kEnabled);
  std::array<std::uint8_t, co::kIoChannels> dout{};
  std::array<std::int16_t, co::kIoChannels> aout{};
  for (int k = 0; k < 10; ++k) {  // warm-up
    m.begin_cycle(k * 1000000LL);
    m.collect();
    m.send_rpdos();
  }
  const std::uint64_t before = bus.rpdos;
  contour::test::AllocGuard g;
  bool all_fresh = true, values_ok = true, rpdo_ok = true;
  for (int k = 10; k < 10010; ++k) {
    bus.di1 = static_cast<std::uint8_t>(k & 0xFF);
    bus.di2 = static_cast<std::uint8_t>(~k & 0xFF);
    bus.ai1 = static_cast<std::int16_t>(-k);
    m.begin_cycle(k * 1000000LL);
    m.collect();
    const co::NodeRuntime& r = m.node(1);
    all_fresh = all_fresh && r.tpdo_fresh;
    values_ok = values_ok && r.io_digital_in[0] == bus.di1 && r.io_digital_in[1] == bus.di2 &&
                r.io_analog_in[0] == bus.ai1;
    dout[0] = static_cast<std::uint8_t>(k & 0x7F);
    aout[1] = static_cast<std::int16_t>(k - 5000);
    aout[0] = 99;  // not mapped: never sent
    m.set_io_outputs(1, dout, aout);
    m.send_rpdos();
    rpdo_ok = rpdo_ok && bus.last_rpdo.dlc == 3 && bus.last_rpdo.data[0] == (k & 0x7F) &&
              co::as_i16(co::get_u16(&bus.last_rpdo.data[1])) == k - 5000;
  }
  EXPECT_EQ(g.counts().total(), 0u);
  EXPECT_TRUE(all_fresh);
  EXPECT_TRUE(values_ok);
  EXPECT_TRUE(rpdo_ok);
  EXPECT_EQ(bus.rpdos - before, 10000u);  // one RPDO per cycle, after the SYNC
  EXPECT_EQ(bus.rpdo_before_first_sync, 0u);
  EXPECT_EQ(m.node(1).missed_total, 0u);
  EXPECT_EQ(m.node(0).state, co::Cia402State::kOperationEnabled);  // the drive as before
  EXPECT_TRUE(m.all_enabled());  // a module has no power state machine
}

TEST(CanopenIoModule, ASilentModuleFaultsNamingItsNode) {
  FakeBus bus;
  co::Master m(bus, drive_and_module());
  for (int k = 0; k < 5; ++k) {
    m.begin_cycle(k * 1000000LL);
    EXPECT_EQ(m.collect(), co::CycleStatus::kOk);
    m.send_rpdos();
  }
  bus.module_silent = true;
  co::CycleStatus st = co::CycleStatus::kOk;
  int k = 5;
  for (; k < 20 && st == co::CycleStatus::kOk; ++k) {
    m.begin_cycle(k * 1000000LL);
    st = m.collect();
    m.send_rpdos();
  }
  EXPECT_EQ(k, 8);
  EXPECT_EQ(m.node(1).missed_streak, 3u);
  EXPECT_EQ(m.node(0).missed_total, 0u);
  co::MasterEvent e;
  ASSERT_TRUE(m.pop_event(e));
  EXPECT_EQ(m.describe(e), "node 5 (I/O module): 3 TPDOs missed in a row (cycle 8)");
  // The inputs keep their last values (the consumer judges their age).
  bus.module_silent = false;
  m.reset_faults();
  m.begin_cycle(20 * 1000000LL);
  EXPECT_EQ(m.collect(), co::CycleStatus::kOk);
}

TEST(CanopenIoModule, TheBusLoadEstimateCountsTheModulesFrames) {
  FakeBus bus;
  co::MasterConfig drives_only;
  drives_only.nodes = {drive(1)};
  const co::Master a(bus, drives_only);
  const co::Master b(bus, drive_and_module());
  // A 4-byte TPDO (95 bits worst case) and a 3-byte RPDO (85 bits) more per 1 ms cycle at 1 Mbit/s.
  EXPECT_NEAR(b.bus_load().worst_case - a.bus_load().worst_case,
              (co::frame_bits_worst(4) + co::frame_bits_worst(3)) / 1000.0, 1e-9);
  auto c = drive_and_module();
  c.load_ceiling = a.bus_load().worst_case + 0.01;
  EXPECT_THROW(co::Master(bus, c), co::StartupError);
}

TEST(CanopenIoModule, AModuleMappingNothingOrNeedingMorePdosThanItHasIsRefused) {
  FakeBus bus;
  auto c = drive_and_module();
  c.nodes[1].io = {};
  try {
    co::Master m(bus, c);
    FAIL();
  } catch (const co::StartupError& e) {
    EXPECT_STREQ(e.what(), "node 5 (I/O module): CiA 401 module maps no object");
  }
  c.nodes[1].io.analog_inputs = 0xFF;  // two TPDOs
  c.nodes[1].quirks.tpdos = 1;
  c.nodes[1].quirks.profile = "cia401";
  try {
    co::Master m(bus, c);
    FAIL();
  } catch (const co::StartupError& e) {
    EXPECT_STREQ(e.what(),
                 "node 5 (I/O module): the CiA 401 inputs used need 2 TPDOs, the module has 1 "
                 "(profile 'cia401')");
  }
}

namespace {
contour::config::Config load(const std::string& plc) {
  const std::string yaml = R"(loop: {period_us: 1000}
machine:
  axes:
    - {name: X, node_id: 1, counts_per_mm: 2000, min_mm: -100, max_mm: 100, max_velocity_mm_min: 6000}
bus:
  type: socketcan
  interface: vcan0
  drives: {heartbeat_ms: 40, heartbeat_timeout_ms: 150}
plc:
  signals:
)" + plc;
  return contour::config::load_config_string(yaml, "io.yaml");
}
}  // namespace

TEST(CanopenIoModule, PlcSignalsBecomeOneModuleNodePerNodeIdMappingWhatTheyUse) {
  const auto cfg = load(
      "    - {name: clamp, cia401: {node: 5, digital_output: 1, bit: 2}}\n"
      "    - {name: clamped, cia401: {node: 5, digital_input: 3, bit: 0}}\n"
      "    - {name: flow, type: REAL, cia401: {node: 9, analog_input: 2, scale: 0.1}}\n"
      "    - {name: valve, type: INT, cia401: {node: 5, analog_output: 4}}\n");
  const auto mc = contour::daemon::master_config_from(cfg);
  ASSERT_EQ(mc.nodes.size(), 3u);
  EXPECT_EQ(mc.nodes[0].kind, co::NodeKind::kDrive);
  const auto& m5 = mc.nodes[1];
  EXPECT_EQ(m5.kind, co::NodeKind::kIoModule);
  EXPECT_EQ(m5.node_id, 5);
  EXPECT_EQ(m5.io.digital_outputs, 0x01);
  EXPECT_EQ(m5.io.digital_inputs, 0x04);
  EXPECT_EQ(m5.io.analog_outputs, 0x08);
  EXPECT_EQ(m5.io.analog_inputs, 0x00);
  EXPECT_EQ(m5.heartbeat_ms, 40);
  EXPECT_EQ(m5.heartbeat_timeout_ms, 150);
  EXPECT_EQ(mc.nodes[2].node_id, 9);
  EXPECT_EQ(mc.nodes[2].io.analog_inputs, 0x02);
}

TEST(CanopenIoModule, AModuleOnADrivesNodeIdIsAConfigErrorNamingTheSignal) {
  const auto cfg = load("    - {name: clamp, cia401: {node: 1, digital_output: 1, bit: 2}}\n");
  try {
    (void)contour::daemon::master_config_from(cfg);
    FAIL();
  } catch (const contour::config::ConfigError& e) {
    ASSERT_EQ(e.errors().size(), 1u);
    EXPECT_NE(e.errors()[0].find("io.yaml:"), std::string::npos) << e.errors()[0];
    EXPECT_NE(e.errors()[0].find("plc.signals 'clamp': cia401.node 1 is the node of drive 'X'"),
              std::string::npos)
        << e.errors()[0];
  }
}
