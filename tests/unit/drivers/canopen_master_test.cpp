// Master unit tests over a scripted fake bus: the RT cycle is allocation-free over 10k cycles,
// missed TPDOs are counted and fault after the configured streak, the bus-load ceiling refuses.
#include <gtest/gtest.h>

#include <deque>

#include "drivers/canopen/master.hpp"
#include "tests/support/alloc_counter.hpp"

namespace co = contour::drivers::canopen;
using contour::drivers::BusState;
using contour::drivers::CanFrame;
using contour::drivers::CanStats;
using contour::drivers::SendResult;

namespace {

// Answers every SYNC with a TPDO {statusword, position} per node from a fixed ring.
class FakeBus final : public contour::drivers::CanBus {
 public:
  std::array<CanFrame, 64> ring{};
  std::size_t head = 0, tail = 0;
  int nodes = 3;
  int drop_node = 0;  // node whose TPDO is not sent
  std::int32_t pos = 0;
  std::uint64_t sent = 0;
  void push(const CanFrame& f) {
    ring[head] = f;
    head = (head + 1) % ring.size();
  }
  SendResult send(const CanFrame& f) noexcept override {
    ++sent;
    if (f.id == 0x080) {
      pos += 7;
      for (int n = 1; n <= nodes; ++n) {
        if (n == drop_node) continue;
        CanFrame t;
        t.id = 0x180u + static_cast<std::uint32_t>(n);
        t.dlc = 6;
        co::put_u16(&t.data[0], 0x0237);
        co::put_u32(&t.data[2], static_cast<std::uint32_t>(pos));
        push(t);
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

co::MasterConfig three_axes() {
  co::MasterConfig c;
  for (std::uint8_t n = 1; n <= 3; ++n) {
    co::NodeSetup s;
    s.node_id = n;
    s.name = std::string(1, static_cast<char>('W' + n));
    s.rpdo = co::default_rpdo(co::DriveMode::kCsv);
    s.tpdo = co::default_tpdo();
    c.nodes.push_back(s);
  }
  c.tpdo_deadline_us = 1000;
  return c;
}

}  // namespace

TEST(CanopenMaster, CycleIsAllocationFreeOver10kCycles) {
  FakeBus bus;
  co::Master m(bus, three_axes());
  m.set_request_all(co::DriveRequest::kEnabled);
  for (int k = 0; k < 10; ++k) {  // warm-up
    m.begin_cycle(k * 1000000LL);
    m.collect();
    m.send_rpdos();
  }
  contour::test::AllocGuard g;
  for (int k = 10; k < 10010; ++k) {
    m.begin_cycle(k * 1000000LL);
    m.collect();
    for (std::size_t i = 0; i < 3; ++i) m.set_target(i, k);
    m.send_rpdos();
  }
  EXPECT_EQ(g.counts().total(), 0u);
  EXPECT_EQ(m.node(0).tpdo_received, 10010u) << "missed " << m.node(0).missed_total << " late " << m.counters().late_or_stray_frames;
  EXPECT_EQ(m.node(2).position_counts, 7 * 10010);
  EXPECT_EQ(m.node(1).state, co::Cia402State::kOperationEnabled);
}

TEST(CanopenMaster, MissedTpdosAreCountedAndFaultAfterTheStreak) {
  FakeBus bus;
  auto cfg = three_axes();
  cfg.missed_tpdo_fault = 3;
  cfg.tpdo_deadline_us = 100;
  co::Master m(bus, cfg);
  bus.drop_node = 2;
  co::CycleStatus st = co::CycleStatus::kOk;
  int k = 0;
  for (; k < 10 && st == co::CycleStatus::kOk; ++k) {
    m.begin_cycle(k * 1000000LL);
    st = m.collect();
    m.send_rpdos();
  }
  EXPECT_EQ(k, 3);
  EXPECT_EQ(m.node(1).missed_total, 3u);
  EXPECT_EQ(m.node(0).missed_total, 0u);
  co::MasterEvent e;
  ASSERT_TRUE(m.pop_event(e));
  EXPECT_EQ(m.describe(e), "node 2 (Y): 3 TPDOs missed in a row (cycle 3)");
}

TEST(CanopenMaster, BusLoadAboveTheCeilingIsRefused) {
  FakeBus bus;
  auto cfg = three_axes();
  co::NodeSetup s = cfg.nodes[0];
  s.node_id = 4;
  cfg.nodes.push_back(s);  // SYNC + 4 x (6 + 6) bytes every cycle: 97.5 % worst case
  try {
    co::Master m(bus, cfg);
    FAIL();
  } catch (const co::StartupError& e) {
    EXPECT_STREQ(e.what(), "bus load 97.5 % worst case exceeds the ceiling of 80.0 %");
  }
  cfg.nodes[3].sync_every = 10;  // the spindle at a tenth of the rate: 76.8 %
  EXPECT_NO_THROW(co::Master(bus, cfg));
}
