// Master start-up against drives that are not the simulator (issue 17), over an in-process
// scripted SDO server: missing optional objects are skipped with a log line, missing mandatory
// ones stop the boot; drive quirks (skipped objects, one PDO, mapping limits, expedited-only
// SDO) change what the master sends, checked frame by frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <deque>
#include <map>
#include <set>
#include <string>

#include "drivers/canopen/master.hpp"

namespace co = contour::drivers::canopen;
using contour::drivers::BusState;
using contour::drivers::CanFrame;
using contour::drivers::CanStats;
using contour::drivers::SendResult;

namespace {

constexpr std::uint32_t key(std::uint16_t i, std::uint8_t s) { return (std::uint32_t{i} << 8) | s; }

// CiA 402 drives answering NMT and SDO (expedited, and segmented uploads for > 4 bytes) from an
// object dictionary per node; objects can be removed. Records every SDO request.
class FakeDrives final : public contour::drivers::CanBus {
 public:
  struct Request {
    std::uint8_t node;
    std::uint8_t cs;
    std::uint16_t index;
    std::uint8_t sub;
  };
  explicit FakeDrives(std::vector<std::uint8_t> nodes) : nodes_(std::move(nodes)) {
    for (auto n : nodes_) {
      auto& od = od_[n];
      auto put = [&](std::uint16_t i, std::uint8_t s, std::vector<std::uint8_t> v) {
        od[key(i, s)] = std::move(v);
      };
      put(0x1000, 0, {0x92, 0x01, 0x02, 0x00});
      const std::string name = "fake drive";
      put(0x1008, 0, std::vector<std::uint8_t>(name.begin(), name.end()));
      for (auto i : {0x1006, 0x1007}) put(static_cast<std::uint16_t>(i), 0, {0, 0, 0, 0});
      put(0x1016, 1, {0, 0, 0, 0});
      put(0x1017, 0, {0, 0});
      for (std::uint16_t k = 0; k < 4; ++k)
        for (int base : {0x1400, 0x1800, 0x1600, 0x1A00})
          for (std::uint8_t s = 0; s <= 8; ++s) put(static_cast<std::uint16_t>(base + k), s, {0, 0, 0, 0});
      put(0x605A, 0, {2, 0});
      put(0x6085, 0, {0, 0, 0, 0});
      put(0x60C2, 1, {0});
      put(0x60C2, 2, {0});
      put(0x6060, 0, {0});
      put(0x6061, 0, {0});
    }
  }
  void remove(std::uint8_t node, std::uint16_t index, int sub = -1) {
    auto& od = od_[node];
    for (auto it = od.begin(); it != od.end();)
      it = ((it->first >> 8) == index && (sub < 0 || static_cast<int>(it->first & 0xFF) == sub))
               ? od.erase(it)
               : std::next(it);
  }
  void set_expedited_only(std::uint8_t node) { expedited_only_.insert(node); }
  const std::vector<Request>& requests() const { return requests_; }
  bool any_request(std::uint16_t index, std::uint8_t sub) const {
    return std::any_of(requests_.begin(), requests_.end(),
                       [&](const Request& r) { return r.index == index && r.sub == sub; });
  }

  // On NMT start: each node's heartbeat sent in pre-operational just before it handled the
  // command (it arrives after it), then, when confirm_start, its first one in operational.
  bool stale_heartbeat_on_start = false;
  bool confirm_start = true;
  void inject(const CanFrame& f) { push(f); }

  SendResult send(const CanFrame& f) noexcept override {
    if (f.id == 0 && f.dlc == 2 && f.data[0] == 0x82)
      for (auto n : nodes_) push(co::heartbeat_frame(n, co::NmtState::kBootUp));
    if (f.id == 0 && f.dlc == 2 && f.data[0] == 0x01) {
      if (stale_heartbeat_on_start)
        for (auto n : nodes_) push(co::heartbeat_frame(n, co::NmtState::kPreOperational));
      if (confirm_start)
        for (auto n : nodes_) push(co::heartbeat_frame(n, co::NmtState::kOperational));
    }
    if (const auto n = co::node_of(f.id, co::kCobSdoRx); n != 0 && od_.count(n) != 0) on_sdo(n, f);
    return SendResult::kOk;
  }
  bool receive(CanFrame& f) noexcept override {
    if (q_.empty()) return false;
    f = q_.front();
    q_.pop_front();
    return true;
  }
  bool wait_readable(std::int64_t) noexcept override { return !q_.empty(); }
  CanStats stats() const noexcept override { return {}; }
  BusState bus_state() const noexcept override { return BusState::kErrorActive; }
  void clear_bus_state() noexcept override {}

 private:
  void push(const CanFrame& f) { q_.push_back(f); }
  void reply(std::uint8_t n, std::uint8_t cs, std::uint16_t i, std::uint8_t s,
             const std::vector<std::uint8_t>& d = {}) {
    CanFrame r;
    r.id = co::kCobSdoTx + n;
    r.dlc = 8;
    r.data[0] = cs;
    co::put_u16(&r.data[1], i);
    r.data[3] = s;
    for (std::size_t k = 0; k < d.size() && k < 4; ++k) r.data[4 + k] = d[k];
    push(r);
  }
  void on_sdo(std::uint8_t n, const CanFrame& f) {
    const std::uint8_t cs = f.data[0];
    const std::uint16_t i = co::get_u16(&f.data[1]);
    const std::uint8_t s = f.data[3];
    requests_.push_back({n, cs, i, s});
    auto& od = od_[n];
    if ((cs & 0xE0) == 0x60 && !seg_.empty()) {  // upload segment request
      const std::size_t k = std::min<std::size_t>(7, seg_.size());
      CanFrame r;
      r.id = co::kCobSdoTx + n;
      r.dlc = 8;
      r.data[0] = static_cast<std::uint8_t>((cs & 0x10) | ((7 - k) << 1) | (k == seg_.size() ? 1 : 0));
      std::copy(seg_.begin(), seg_.begin() + static_cast<std::ptrdiff_t>(k), r.data.begin() + 1);
      seg_.erase(seg_.begin(), seg_.begin() + static_cast<std::ptrdiff_t>(k));
      push(r);
      return;
    }
    if (cs == 0x80) return;  // abort from the client
    auto abort = [&](std::uint32_t code) {
      push(co::sdo_abort_frame(n, true, i, s, code));
    };
    auto it = od.find(key(i, s));
    if (it == od.end()) {
      const bool index_exists = std::any_of(od.begin(), od.end(),
                                            [&](const auto& kv) { return (kv.first >> 8) == i; });
      return abort(index_exists ? 0x06090011 : 0x06020000);
    }
    if ((cs & 0xE0) == 0x40) {  // initiate upload
      const auto& v = it->second;
      if (v.size() <= 4) return reply(n, static_cast<std::uint8_t>(0x43 | ((4 - v.size()) << 2)), i, s, v);
      if (expedited_only_.count(n) != 0) return abort(0x05040001);
      seg_ = v;
      std::vector<std::uint8_t> size(4);
      co::put_u32(size.data(), static_cast<std::uint32_t>(v.size()));
      return reply(n, 0x41, i, s, size);
    }
    if ((cs & 0xE0) == 0x20) {  // initiate download
      if ((cs & 0x02) == 0 && expedited_only_.count(n) != 0) return abort(0x05040001);
      const std::size_t len = 4 - ((cs >> 2) & 3);
      it->second.assign(f.data.begin() + 4, f.data.begin() + 4 + static_cast<std::ptrdiff_t>(len));
      if (i == 0x6060) od[key(0x6061, 0)] = it->second;
      return reply(n, 0x60, i, s);
    }
    abort(0x05040001);
  }

  std::vector<std::uint8_t> nodes_;
  std::map<std::uint8_t, std::map<std::uint32_t, std::vector<std::uint8_t>>> od_;
  std::set<std::uint8_t> expedited_only_;
  std::deque<CanFrame> q_;
  std::vector<std::uint8_t> seg_;
  std::vector<Request> requests_;
};

co::MasterConfig two_axes() {
  co::MasterConfig c;
  for (std::uint8_t n = 1; n <= 2; ++n) {
    co::NodeSetup s;
    s.node_id = n;
    s.name = n == 1 ? "X" : "Y";
    s.rpdo = co::default_rpdo(co::DriveMode::kCsv);
    s.tpdo = co::default_tpdo();
    c.nodes.push_back(s);
  }
  c.sdo_timeout_ms = 50;
  c.sdo_retries = 0;
  return c;
}

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& l : v) s += l + "\n";
  return s;
}

struct Booted {
  std::vector<std::string> log;
  std::string error;  // empty when start_up() succeeded
};

Booted boot(FakeDrives& bus, const co::MasterConfig& cfg) {
  Booted b;
  co::Master m(bus, cfg, [&](const std::string& s) { b.log.push_back(s); });
  try {
    m.start_up();
  } catch (const co::StartupError& e) {
    b.error = e.what();
  }
  return b;
}

}  // namespace

TEST(CanopenQuirks, CompleteDrivesBootAsBefore) {
  FakeDrives bus({1, 2});
  const auto b = boot(bus, two_axes());
  EXPECT_EQ(b.error, "");
  EXPECT_NE(joined(b.log).find("node 1 (X): device \"fake drive\""), std::string::npos) << joined(b.log);
  EXPECT_TRUE(bus.any_request(0x1403, 1));  // PDOs 2..4 switched off
  EXPECT_TRUE(bus.any_request(0x1803, 1));
}

// Issue 17: "SDO upload 0x1008:00 aborted: 0x06020000" stopped the boot of such a drive.
TEST(CanopenQuirks, MissingOptionalObjectsAreSkippedWithALogLine) {
  FakeDrives bus({1, 2});
  bus.remove(1, 0x1008);
  bus.remove(1, 0x1006);
  bus.remove(2, 0x60C2, 2);  // sub-index missing: 0x06090011
  bus.remove(2, 0x605A);
  bus.remove(2, 0x6085);
  const auto b = boot(bus, two_axes());
  ASSERT_EQ(b.error, "") << joined(b.log);
  const std::string log = joined(b.log);
  EXPECT_NE(log.find("node 1 (X): SDO upload 0x1008:00: aborted by the drive: 0x06020000 object "
                     "does not exist in the object dictionary: optional object, skipped"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("node 1 (X): SDO download 0x1006:00: aborted by the drive: 0x06020000"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("node 2 (Y): SDO download 0x60C2:02: aborted by the drive: 0x06090011"),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("node 2 (Y): SDO download 0x605A:00"), std::string::npos) << log;
  EXPECT_NE(log.find("node 2 (Y): SDO download 0x6085:00"), std::string::npos) << log;
  EXPECT_NE(log.find("node 1 (X): device \"?\""), std::string::npos) << log;
}

TEST(CanopenQuirks, MissingMandatoryObjectsStopTheBoot) {
  {
    FakeDrives bus({1, 2});
    bus.remove(2, 0x6060);
    EXPECT_EQ(boot(bus, two_axes()).error,
              "node 2 (Y): SDO download 0x6060:00: aborted by the drive: 0x06020000 object does "
              "not exist in the object dictionary");
  }
  {
    FakeDrives bus({1, 2});
    bus.remove(1, 0x1017);
    EXPECT_NE(boot(bus, two_axes()).error.find("node 1 (X): SDO download 0x1017:00"),
              std::string::npos);
  }
  {
    // The heartbeat consumer is what stops a drive when the master dies: only a profile that
    // says the drive has none skips it.
    FakeDrives bus({1, 2});
    bus.remove(1, 0x1016);
    EXPECT_NE(boot(bus, two_axes()).error.find("node 1 (X): SDO download 0x1016:01"),
              std::string::npos);
    auto cfg = two_axes();
    cfg.nodes[0].quirks.profile = "acme";
    cfg.nodes[0].quirks.skip.push_back({0x1016, co::ObjectRef::kAllSubs});
    FakeDrives bus2({1, 2});
    bus2.remove(1, 0x1016);
    const auto b = boot(bus2, cfg);
    EXPECT_EQ(b.error, "");
    EXPECT_NE(joined(b.log).find("node 1 (X): WARNING: no heartbeat consumer"), std::string::npos);
  }
}

TEST(CanopenQuirks, SkippedObjectsAreNeverAccessed) {
  FakeDrives bus({1, 2});
  auto cfg = two_axes();
  cfg.nodes[1].quirks.profile = "no-quick-stop-objects";
  cfg.nodes[1].quirks.skip = {{0x605A, co::ObjectRef::kAllSubs}, {0x6085, 0}, {0x1008, 0}};
  const auto b = boot(bus, cfg);
  ASSERT_EQ(b.error, "") << joined(b.log);
  for (const auto& r : bus.requests()) {
    if (r.node != 2) continue;
    EXPECT_NE(r.index, 0x605A);
    EXPECT_NE(r.index, 0x6085);
    EXPECT_NE(r.index, 0x1008);
  }
  EXPECT_TRUE(bus.any_request(0x605A, 0));  // node 1 still gets them
  EXPECT_NE(joined(b.log).find("node 2 (Y): 0x605A:00 not written (drive profile "
                               "'no-quick-stop-objects' has no such object)"),
            std::string::npos);
}

TEST(CanopenQuirks, OnlyMandatoryObjectsMayBeSkipped) {
  FakeDrives bus({1, 2});
  auto cfg = two_axes();
  cfg.nodes[0].quirks.skip = {{0x6060, 0}};
  try {
    co::Master m(bus, cfg);
    FAIL();
  } catch (const co::StartupError& e) {
    EXPECT_STREQ(e.what(), "node 1 (X): object 0x6060 is mandatory for this master and cannot be "
                           "skipped (drive profile 'generic')");
  }
}

TEST(CanopenQuirks, OnePdoDriveGetsNoWritesToPdosItLacks) {
  FakeDrives bus({1, 2});
  for (std::uint16_t k = 1; k < 4; ++k)
    for (int base : {0x1400, 0x1800, 0x1600, 0x1A00})
      bus.remove(1, static_cast<std::uint16_t>(base + k));
  EXPECT_NE(boot(bus, two_axes()).error.find("node 1 (X): SDO download 0x1401:01: aborted by the "
                                             "drive: 0x06020000"),
            std::string::npos);
  auto cfg = two_axes();
  cfg.nodes[0].quirks.rpdos = 1;
  cfg.nodes[0].quirks.tpdos = 1;
  FakeDrives bus2({1, 2});
  for (std::uint16_t k = 1; k < 4; ++k)
    for (int base : {0x1400, 0x1800, 0x1600, 0x1A00})
      bus2.remove(1, static_cast<std::uint16_t>(base + k));
  EXPECT_EQ(boot(bus2, cfg).error, "");
  for (const auto& r : bus2.requests()) {
    if (r.node != 1) continue;
    const bool other_pdo = (r.index >= 0x1401 && r.index <= 0x1403) ||
                           (r.index >= 0x1801 && r.index <= 0x1803);
    EXPECT_FALSE(other_pdo) << std::hex << r.index;
  }
}

TEST(CanopenQuirks, MappingBeyondTheDrivesPdoIsRefusedNamingNodeAndObjects) {
  FakeDrives bus({1, 2});
  auto cfg = two_axes();
  auto& n = cfg.nodes[1];
  n.quirks.profile = "acme-x1";
  n.quirks.tpdo_max_entries = 2;
  n.tpdo.entries[2] = {0x606C, 0, 16};
  n.tpdo.count = 3;
  try {
    co::Master m(bus, cfg);
    FAIL();
  } catch (const co::StartupError& e) {
    EXPECT_STREQ(e.what(), "node 2 (Y): TPDO1 needs 3 entries (0x6041, 0x6064, 0x606C), the drive "
                           "maps at most 2 (drive profile 'acme-x1')");
  }
  n.tpdo.count = 2;
  EXPECT_NO_THROW(co::Master(bus, cfg));
}

TEST(CanopenQuirks, ExpeditedOnlyDrivesSeeNoSegmentedTransfer) {
  // Today's master reads the device name with a segmented upload: such a drive aborts it.
  FakeDrives bus({1, 2});
  bus.set_expedited_only(1);
  EXPECT_NE(boot(bus, two_axes()).error.find("node 1 (X): SDO upload 0x1008:00: aborted by the "
                                             "drive: 0x05040001"),
            std::string::npos);
  auto cfg = two_axes();
  cfg.nodes[0].quirks.expedited_only = true;
  FakeDrives bus2({1, 2});
  bus2.set_expedited_only(1);
  const auto b = boot(bus2, cfg);
  ASSERT_EQ(b.error, "") << joined(b.log);
  for (const auto& r : bus2.requests()) {
    if (r.node != 1) continue;
    EXPECT_NE(r.index, 0x1008);
    const bool expedited_download = (r.cs & 0xE2) == 0x22;
    const bool upload = r.cs == 0x40;
    EXPECT_TRUE(expedited_download || upload) << std::hex << int{r.cs} << " " << r.index;
  }
  EXPECT_NE(joined(b.log).find("node 1 (X): 0x1008:00 device name not read"), std::string::npos);
  // A download of more than 4 bytes would be segmented: refused before anything is sent.
  co::Master m(bus2, cfg);
  const std::uint8_t six[6] = {1, 2, 3, 4, 5, 6};
  const auto before = bus2.requests().size();
  try {
    m.sdo_download(1, 0x2000, 0, six);
    FAIL();
  } catch (const co::StartupError& e) {
    EXPECT_STREQ(e.what(), "node 1 (X): SDO download 0x2000:00: 6 bytes need a segmented transfer, "
                           "the drive takes expedited SDO only");
  }
  EXPECT_EQ(bus2.requests().size(), before);
}

TEST(CanopenQuirks, ExpeditedOnlyClientAbortsASegmentedUploadAnswer) {
  // A drive that answers with a segmented upload anyway: the master aborts at once.
  FakeDrives bus({1, 2});
  auto cfg = two_axes();
  cfg.nodes[0].quirks.expedited_only = true;
  co::Master m(bus, cfg);
  try {
    m.sdo_upload(1, 0x1008, 0);
    FAIL();
  } catch (const co::SdoAbortError& e) {
    EXPECT_EQ(e.code(), 0x06010000u);
    EXPECT_FALSE(e.from_server());
    EXPECT_NE(std::string(e.what()).find("its profile says expedited only"), std::string::npos);
  }
  ASSERT_FALSE(bus.requests().empty());
  EXPECT_EQ(bus.requests().back().cs, 0x80);  // the client's abort, no segment request
}

// A heartbeat a drive sent in pre-operational just before it handled the NMT start reaches the
// master after the start: start_up() takes it in while it waits for each drive's first heartbeat
// in operational, so the first cycles do not read it as the drive leaving operational (a HIL
// flake: "node 2 is no longer NMT operational" at cycle 0..22 under load).
TEST(CanopenQuirks, AStaleHeartbeatFromBeforeTheNmtStartIsNotAStateChange) {
  FakeDrives bus({1, 2});
  bus.stale_heartbeat_on_start = true;
  co::Master m(bus, two_axes(), [](const std::string&) {});
  m.start_up();
  for (int k = 0; k < 3; ++k) {
    m.begin_cycle(k * 1000000LL);
    m.collect();
  }
  co::MasterEvent e;
  while (m.pop_event(e)) EXPECT_NE(e.kind, co::MasterEvent::Kind::kNmtStateChange) << m.describe(e);
  EXPECT_FALSE(m.node(0).nmt_lost);
  EXPECT_FALSE(m.node(1).nmt_lost);
}

// A drive whose operational heartbeat never comes within two heartbeat periods is taken as
// operational (logged): its next heartbeat in another state faults it in the cycle.
TEST(CanopenQuirks, ADriveThatDoesNotConfirmTheStartIsJudgedByItsNextHeartbeat) {
  FakeDrives bus({1, 2});
  bus.stale_heartbeat_on_start = true;
  bus.confirm_start = false;
  std::vector<std::string> log;
  co::Master m(bus, two_axes(), [&](const std::string& s) { log.push_back(s); });
  m.start_up();
  EXPECT_NE(joined(log).find("node 1 (X): no operational heartbeat within 120 ms of NMT start "
                             "(last: pre-operational)"),
            std::string::npos)
      << joined(log);
  m.begin_cycle(0);
  m.collect();
  EXPECT_FALSE(m.node(1).nmt_lost);
  bus.inject(co::heartbeat_frame(2, co::NmtState::kPreOperational));
  m.begin_cycle(1000000LL);
  m.collect();
  EXPECT_TRUE(m.node(1).nmt_lost);
  EXPECT_FALSE(m.node(0).nmt_lost);
}
