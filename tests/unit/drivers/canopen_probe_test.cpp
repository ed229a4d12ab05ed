// drivers/canopen/probe.hpp against a scripted bus: nodes that answer SDOs, a stopped node that
// only sends heartbeats, a missing node, an object that aborts, a node found only by scan, and
// the read-only contract (the only write is 0x1017, put back).
#include <gtest/gtest.h>

#include <chrono>
#include <deque>
#include <map>
#include <thread>
#include <vector>

#include "drivers/canopen/probe.hpp"

namespace dc = contour::drivers::canopen;
using contour::drivers::BusState;
using contour::drivers::CanBus;
using contour::drivers::CanFrame;
using contour::drivers::CanStats;
using contour::drivers::SendResult;
using namespace std::chrono_literals;

namespace {

struct FakeNode {
  bool answers_sdo = true;
  std::map<std::uint32_t, std::uint32_t> od;  // (index << 8 | sub) -> value
  std::map<std::uint32_t, int> size;          // bytes per object (default 4)
  std::map<std::uint32_t, std::uint32_t> aborts;
  dc::NmtState state = dc::NmtState::kPreOperational;
};

std::uint32_t key(std::uint16_t index, std::uint8_t sub) {
  return static_cast<std::uint32_t>(index) << 8 | sub;
}

// Answers expedited SDO requests at once (queued for the next receive); a download of a non-zero
// heartbeat time queues one heartbeat after the response.
class ScriptedBus : public CanBus {
 public:
  std::map<int, FakeNode> nodes;
  std::vector<CanFrame> sent;
  std::deque<CanFrame> rx;

  SendResult send(const CanFrame& f) noexcept override {
    sent.push_back(f);
    const auto n = static_cast<int>(f.id) - 0x600;
    if (n < 1 || n > 127 || nodes.count(n) == 0 || !nodes[n].answers_sdo || f.dlc != 8)
      return SendResult::kOk;
    FakeNode& node = nodes[n];
    const std::uint16_t index = dc::get_u16(&f.data[1]);
    const std::uint8_t sub = f.data[3];
    CanFrame r;
    r.id = 0x580u + static_cast<std::uint32_t>(n);
    r.dlc = 8;
    r.data[1] = f.data[1];
    r.data[2] = f.data[2];
    r.data[3] = sub;
    const std::uint32_t k = key(index, sub);
    if (node.aborts.count(k) || (f.data[0] == 0x40 && node.od.count(k) == 0)) {
      r.data[0] = 0x80;
      dc::put_u32(&r.data[4], node.aborts.count(k) ? node.aborts[k] : 0x06020000u);
    } else if (f.data[0] == 0x40) {  // upload initiate
      const int size = node.size.count(k) ? node.size[k] : 4;
      r.data[0] = static_cast<std::uint8_t>(0x43 | ((4 - size) << 2));
      dc::put_u32(&r.data[4], node.od[k]);
    } else if ((f.data[0] & 0xE3) == 0x23) {  // expedited download
      const std::uint32_t v = dc::get_u32(&f.data[4]);
      node.od[k] = v;
      r.data[0] = 0x60;
      rx.push_back(r);
      if (k == key(0x1017, 0) && v != 0)
        rx.push_back(dc::heartbeat_frame(static_cast<std::uint8_t>(n), node.state));
      return SendResult::kOk;
    } else {
      return SendResult::kOk;  // aborts from the client
    }
    rx.push_back(r);
    return SendResult::kOk;
  }
  bool receive(CanFrame& f) noexcept override {
    if (rx.empty()) return false;
    f = rx.front();
    rx.pop_front();
    return true;
  }
  bool wait_readable(std::int64_t timeout_ns) noexcept override {
    if (!rx.empty()) return true;
    std::this_thread::sleep_for(
        std::chrono::nanoseconds(std::min<std::int64_t>(timeout_ns, 1000000)));
    return !rx.empty();
  }
  [[nodiscard]] CanStats stats() const noexcept override { return {}; }
  [[nodiscard]] BusState bus_state() const noexcept override { return BusState::kErrorActive; }
  void clear_bus_state() noexcept override {}
};

FakeNode drive(std::uint32_t serial) {
  FakeNode n;
  n.od = {{key(0x1000, 0), 0x00020192}, {key(0x1018, 1), 0x0C7D}, {key(0x1018, 2), 402},
          {key(0x1018, 3), 0x00010000}, {key(0x1018, 4), serial}, {key(0x6041, 0), 0x0240},
          {key(0x6061, 0), 9},          {key(0x1017, 0), 0}};
  n.size = {{key(0x6041, 0), 2}, {key(0x6061, 0), 1}, {key(0x1017, 0), 2}};
  return n;
}

dc::CanProbeSettings fast_settings() {
  dc::CanProbeSettings s;
  s.listen = 5ms;
  s.sdo_timeout = 30ms;
  s.scan_timeout = 2ms;
  return s;
}

const dc::CanProbeResult& by_id(const std::vector<dc::CanProbeResult>& v, int id) {
  for (const auto& r : v)
    if (r.node_id == id) return r;
  throw std::runtime_error("node " + std::to_string(id) + " not in the results");
}

}  // namespace

TEST(CanopenProbe, IdentityStatuswordAndNmtStateOfAnsweringDrive) {
  ScriptedBus bus;
  bus.nodes[1] = drive(0x1001);
  auto s = fast_settings();
  s.nodes = {{1, "X"}};
  const auto res = dc::probe_canopen(bus, s);
  ASSERT_EQ(res.size(), 1u);
  const auto& r = res[0];
  EXPECT_TRUE(r.configured);
  EXPECT_TRUE(r.found);
  EXPECT_EQ(r.name, "X");
  EXPECT_EQ(r.device_type, 0x00020192u);
  EXPECT_EQ(r.vendor_id, 0x0C7Du);
  EXPECT_EQ(r.product_code, 402u);
  EXPECT_EQ(r.revision, 0x00010000u);
  EXPECT_EQ(r.serial, 0x1001u);
  EXPECT_EQ(r.statusword, 0x0240);
  EXPECT_EQ(r.mode_display, 9);
  ASSERT_TRUE(r.nmt.has_value());
  EXPECT_EQ(*r.nmt, dc::NmtState::kPreOperational);
  EXPECT_NE(r.nmt_source.find("0x1017"), std::string::npos) << r.nmt_source;
  EXPECT_TRUE(r.errors.empty()) << r.errors.front();
  // Read-only apart from the heartbeat producer, which ends where it was.
  std::vector<std::uint32_t> hb;
  for (const auto& f : bus.sent) {
    EXPECT_GE(f.id, 0x600u) << "not an SDO request: 0x" << std::hex << f.id;
    if ((f.data[0] & 0xE0) == 0x20) {
      ASSERT_EQ(dc::get_u16(&f.data[1]), 0x1017) << "wrote another object";
      hb.push_back(dc::get_u32(&f.data[4]));
    }
  }
  EXPECT_EQ(hb, (std::vector<std::uint32_t>{s.temporary_heartbeat_ms, 0}));
  EXPECT_EQ(bus.nodes[1].od[key(0x1017, 0)], 0u);
}

TEST(CanopenProbe, HeardHeartbeatNeedsNoWriteAndStoppedNodeIsFoundByItsHeartbeat) {
  ScriptedBus bus;
  bus.nodes[1] = drive(0x1001);
  bus.nodes[2].answers_sdo = false;  // NMT stopped: no SDO server
  bus.rx.push_back(dc::heartbeat_frame(1, dc::NmtState::kOperational));
  bus.rx.push_back(dc::heartbeat_frame(2, dc::NmtState::kStopped));
  auto s = fast_settings();
  s.nodes = {{1, "X"}, {2, "Y"}};
  const auto res = dc::probe_canopen(bus, s);
  const auto& x = by_id(res, 1);
  EXPECT_EQ(x.nmt, dc::NmtState::kOperational);
  EXPECT_EQ(x.nmt_source, "heartbeat");
  for (const auto& f : bus.sent) EXPECT_NE(f.data[0] & 0xE0, 0x20) << "no write needed";
  const auto& y = by_id(res, 2);
  EXPECT_TRUE(y.found);
  EXPECT_EQ(y.nmt, dc::NmtState::kStopped);
  EXPECT_FALSE(y.device_type.has_value());
  ASSERT_FALSE(y.errors.empty());
  EXPECT_NE(y.errors[0].find("0x1000:00: no response"), std::string::npos) << y.errors[0];
}

TEST(CanopenProbe, MissingNodeAbortingObjectAndScanOnlyNode) {
  ScriptedBus bus;
  bus.nodes[1] = drive(0x1001);
  bus.nodes[1].aborts[key(0x1018, 4)] = 0x06020000;  // no serial number object
  bus.nodes[5] = drive(0x1005);
  auto s = fast_settings();
  s.nodes = {{1, "X"}, {3, "Z"}};
  s.scan = true;
  const auto res = dc::probe_canopen(bus, s);
  ASSERT_EQ(res.size(), 3u);
  const auto& x = by_id(res, 1);
  EXPECT_TRUE(x.found);
  EXPECT_FALSE(x.serial.has_value());
  ASSERT_EQ(x.errors.size(), 1u);
  EXPECT_NE(x.errors[0].find("0x1018:04: aborted by the drive: 0x06020000"), std::string::npos)
      << x.errors[0];
  EXPECT_EQ(x.vendor_id, 0x0C7Du) << "the rest of the node is still read";
  const auto& z = by_id(res, 3);
  EXPECT_TRUE(z.configured);
  EXPECT_FALSE(z.found);
  EXPECT_FALSE(z.nmt.has_value());
  EXPECT_FALSE(z.errors.empty());
  const auto& scanned = by_id(res, 5);
  EXPECT_FALSE(scanned.configured);
  EXPECT_TRUE(scanned.found);
  EXPECT_EQ(scanned.serial, 0x1005u);
}
