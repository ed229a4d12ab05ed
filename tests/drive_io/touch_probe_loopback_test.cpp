// CiA 402 touch probe 1 as the encoder index latch of home.use_index, in one process: the daemon's
// CanopenBus (master config from the YAML) against contour-machine-sim's SimDrive over a loopback
// CanBus that delivers every frame at once (lockstep, no wall clock), as drive_io_loopback_test.
//   - only an axis homed on a switch with use_index maps it: 0x60B8 appended to RPDO1 (8 bytes
//     with the default {0x6040, 0x60FF}), {0x60B9, 0x60BA} in TPDO3 (TPDO2 is the home switch's
//     0x60FD); the other axis is configured bit for bit as without it; the bus load counts the
//     extra TPDO; a drive whose RPDO1 has no room gets 0x60B8 in an RPDO of its own;
//   - the simulated drive: arming is an edge of 0x60B8, the first pulse is latched exactly (to the
//     count) and only once, a new arm needs the disarm first;
//   - the bus: AxisCommands::index_arm -> index_latched / index_position_mm in position_mm's
//     coordinates (also across the wrap of the drive's 32-bit position register);
//   - a drive without the objects, and a one-PDO drive, stop the start-up naming node and object.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "config/config.hpp"
#include "daemon/canopen_bus.hpp"
#include "drivers/canopen/codec.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/drive_io/loopback_bus.hpp"
#include "tools/contour-machine-sim/sim_drive.hpp"

namespace contour {
namespace {

namespace co = drivers::canopen;
using drivers::BusState;
using drivers::CanFrame;
using drivers::CanStats;
using drivers::SendResult;

using Loopback = test::SimLoopback;  // tests/drive_io/loopback_bus.hpp

// X homed on its switch (0x60FD in TPDO2), with or without use_index (%INDEX%); Y not homed.
constexpr const char* kMachine = R"(loop: {period_us: 1000, tpdo_deadline_us: 800}
safety: {missed_tpdo_streak: 3, ferror_mm: 5.0, min_ferror_mm: 1.0}
machine:
  allow_unhomed: true
  axes:
    - {name: X, node_id: 1, counts_per_mm: %CPM%, sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1},
       min_mm: -200, max_mm: 200, max_velocity_mm_min: 10000,
       home: {method: switch, search_vel_mm_min: -1200, latch_vel_mm_min: 60%INDEX%}}
    - {name: Y, node_id: 2, counts_per_mm: 2000, sim: {gain_per_s: 120, tau_ms: 30, blu_um: 0.5, delay_cycles: 1},
       min_mm: -200, max_mm: 200, max_velocity_mm_min: 10000}
bus:
  type: socketcan
  interface: vcan0
  lockstep: true
  master_heartbeat_ms: 0
  load_ceiling_percent: 95
  profiles: {one-pdo: {rpdos: 1, tpdos: 1}, two-entries: {rpdo_max_entries: 2}}
  drives: {mode: csv, heartbeat_ms: 50, heartbeat_timeout_ms: 200, rpdo: ["0x6040", "0x60FF"], tpdo: ["0x6041", "0x6064"]}
)";

std::string machine(bool use_index, double cpm = 2000.0, const std::string& extra = "") {
  std::string y = kMachine;
  auto sub = [&y](const std::string& from, const std::string& to) {
    y.replace(y.find(from), from.size(), to);
  };
  sub("%INDEX%", use_index ? ", use_index: true" : "");
  char c[32];
  std::snprintf(c, sizeof c, "%.0f", cpm);
  sub("%CPM%", c);
  return y + extra;
}

struct Scratch : test::ScratchDir {
  Scratch() : ScratchDir("touch_probe") {}
};

constexpr double kPitchMm = 5.0;
constexpr double kPhaseMm = 0.3;

sim::SimDriveSetup drive(std::uint8_t node, const std::string& name, double cpm = 2000.0) {
  sim::SimDriveSetup s = test::sim_drive_setup(node, name, cpm);
  s.switches = {{0, -202.0, false}, {1, 202.0, true}, {2, -199.5, false}};
  s.index_pitch_mm = kPitchMm;
  s.index_phase_mm = kPhaseMm;
  return s;
}

struct Bench : test::LoopbackBench {
  explicit Bench(const config::Config& c) : Bench(c, drive(1, "X")) {}
  Bench(const config::Config& c, sim::SimDriveSetup x) : LoopbackBench(c) {
    can.add(std::move(x));
    can.add(drive(2, "Y"));
  }
  // Enabled, X at rest.
  daemon::BusFeedback enable(daemon::AxisCommands& cmd) {
    cmd.mode = daemon::DriveMode::kEnabled;
    daemon::BusFeedback fb = cycle(cmd);
    for (int k = 0; k < 40 && !(fb.axis[0].enabled && fb.axis[1].enabled); ++k) fb = cycle(cmd);
    EXPECT_TRUE(fb.axis[0].enabled);
    return fb;
  }
};

using W = Loopback::Write;
bool has(const std::vector<W>& v, W w) { return std::find(v.begin(), v.end(), w) != v.end(); }
bool touches(const std::vector<W>& v, std::uint16_t index) {
  return std::any_of(v.begin(), v.end(), [&](const W& w) { return w.index == index; });
}

TEST(TouchProbeLoopback, OnlyTheUseIndexAxisMapsTheTouchProbe) {
  Scratch s;
  Bench plain(s.load(machine(false)));
  plain.start();
  Bench indexed(s.load(machine(true)));
  indexed.start();
  // Y: the same SDO writes with or without X's use_index, nothing of the touch probe.
  const auto y_plain = plain.can.sdo_writes(2), y_idx = indexed.can.sdo_writes(2);
  ASSERT_FALSE(y_plain.empty());
  EXPECT_EQ(y_plain, y_idx);
  const auto x_plain = plain.can.sdo_writes(1);
  for (const auto* v : {&x_plain, &y_plain}) {
    EXPECT_FALSE(touches(*v, 0x60B8));
    EXPECT_FALSE(touches(*v, 0x1A02));  // TPDO3 never mapped
    EXPECT_FALSE(has(*v, W{0x1600, 3, 0x60B80010u}));
  }
  EXPECT_TRUE(has(x_plain, W{0x1802, 1, 0x80000000u | 0x381}));  // TPDO3 off
  EXPECT_EQ(plain.bus->master()->touch_probe_pdos(0).tpdo, -1);

  // X with use_index: RPDO1 {0x6040, 0x60FF, 0x60B8} (8 bytes), TPDO2 {0x60FD} as before,
  // TPDO3 {0x60B9, 0x60BA} on 0x381; RPDO2 stays off.
  const auto x_idx = indexed.can.sdo_writes(1);
  EXPECT_TRUE(has(x_idx, W{0x1600, 3, 0x60B80010u}));
  EXPECT_TRUE(has(x_idx, W{0x1600, 0, 3}));
  EXPECT_TRUE(has(x_idx, W{0x1A01, 1, 0x60FD0020u}));
  EXPECT_TRUE(has(x_idx, W{0x1A02, 1, 0x60B90010u}));
  EXPECT_TRUE(has(x_idx, W{0x1A02, 2, 0x60BA0020u}));
  EXPECT_TRUE(has(x_idx, W{0x1A02, 0, 2}));
  EXPECT_TRUE(has(x_idx, W{0x1802, 1, 0x381}));
  EXPECT_TRUE(has(x_idx, W{0x1401, 1, 0x80000000u | 0x301}));  // RPDO2 off
  EXPECT_TRUE(has(x_idx, W{0x1803, 1, 0x80000000u | 0x481}));  // TPDO4 off
  const auto* m = indexed.bus->master();
  EXPECT_EQ(m->touch_probe_pdos(0).rpdo, 0);
  EXPECT_EQ(m->touch_probe_pdos(0).tpdo, 2);
  EXPECT_EQ(m->touch_probe_pdos(1).tpdo, -1);
  EXPECT_EQ(m->setup(0).rpdo.bytes(), 8u);
  // The bus load counts one more frame a cycle (the TPDO) and the RPDO's 2 bytes.
  const auto& l0 = plain.bus->master()->bus_load();
  const auto& l1 = m->bus_load();
  EXPECT_EQ(l1.frames_per_cycle_avg_x1000, l0.frames_per_cycle_avg_x1000 + 1000);
  EXPECT_GT(l1.worst_case, l0.worst_case);

  // The feedback: index_present for X only; the TPDO3 arrives every cycle (the master waits for it).
  daemon::AxisCommands cmd;
  daemon::BusFeedback fb = indexed.cycle(cmd);
  fb = indexed.cycle(cmd);
  EXPECT_TRUE(fb.axis[0].index_present);
  EXPECT_FALSE(fb.axis[0].index_latched);
  EXPECT_FALSE(fb.axis[1].index_present);
  EXPECT_TRUE(m->node(0).touch_probe_fresh);
  EXPECT_EQ(m->node(0).touch_probe_missed, 0u);
  fb = plain.cycle(cmd);
  EXPECT_FALSE(fb.axis[0].index_present);
}

TEST(TouchProbeLoopback, AFullRpdo1Puts60B8IntoAnRpdoOfItsOwn) {
  Scratch s;
  Bench b(s.load(machine(true, 2000.0, "  nodes: [{node_id: 1, profile: two-entries}]\n")));
  b.start();
  const auto* m = b.bus->master();
  EXPECT_EQ(m->touch_probe_pdos(0).rpdo, 1);
  EXPECT_EQ(m->setup(0).rpdo.count, 2u);
  const auto x = b.can.sdo_writes(1);
  EXPECT_TRUE(has(x, W{0x1601, 1, 0x60B80010u}));
  EXPECT_TRUE(has(x, W{0x1401, 1, 0x301}));
  // The arm still reaches the drive: 0x60B8 in RPDO2 (0x301, 2 bytes).
  daemon::AxisCommands cmd;
  b.enable(cmd);
  cmd.index_arm[0] = true;
  for (int k = 0; k < 3; ++k) b.cycle(cmd);
  EXPECT_EQ(b.can.drives[0]->touch_probe_function(), co::kTouchProbe1ArmIndex);
  EXPECT_EQ(b.can.drives[0]->touch_probe_status() & co::kTouchProbe1Enabled, co::kTouchProbe1Enabled);
}

// The simulated drive alone, driven by hand: RPDO1 mapped {0x6040, 0x60FF, 0x60B8} over SDO,
// 0x60B8 applied at the SYNC after its RPDO. The arm edge, the first event only, the exact
// position, the status bits.
TEST(TouchProbeSimDrive, ArmEdgeFirstEventAndExactPosition) {
  std::vector<CanFrame> out;
  sim::SimDrive d(drive(1, "X"), [&](const CanFrame& f) { out.push_back(f); });
  d.power_on();
  auto sdo = [&](std::uint16_t index, std::uint8_t sub, std::uint32_t v, int bytes) {
    CanFrame f;
    f.id = co::kCobSdoRx + 1;
    f.dlc = 8;
    f.data[0] = static_cast<std::uint8_t>(0x23 | ((4 - bytes) << 2));  // expedited download
    co::put_u16(&f.data[1], index);
    f.data[3] = sub;
    co::put_u32(&f.data[4], v);
    out.clear();
    d.on_frame(f);
    ASSERT_EQ(out.size(), 1u);
    ASSERT_EQ(out[0].data[0], 0x60) << std::hex << index << ":" << int{sub};  // confirmed
  };
  sdo(0x1400, 1, 0x80000201u, 4);
  sdo(0x1600, 0, 0, 1);
  sdo(0x1600, 1, 0x60400010u, 4);
  sdo(0x1600, 2, 0x60FF0020u, 4);
  sdo(0x1600, 3, 0x60B80010u, 4);
  sdo(0x1600, 0, 3, 1);
  sdo(0x1400, 1, 0x201, 4);
  sdo(0x6060, 0, 9, 1);  // CSV
  CanFrame nmt;
  nmt.id = co::kCobNmt;
  nmt.dlc = 2;
  nmt.data[0] = 0x01;  // start
  d.on_frame(nmt);
  std::uint16_t cw = 0;
  std::int32_t target = 0;
  std::uint16_t tp = 0;
  // One cycle: the RPDO, then the SYNC that applies it (and steps the plant).
  auto cycle = [&] {
    CanFrame r;
    r.id = co::kCobRpdo[0] + 1;
    r.dlc = 8;
    co::put_u16(&r.data[0], cw);
    co::put_u32(&r.data[2], static_cast<std::uint32_t>(target));
    co::put_u16(&r.data[6], tp);
    d.on_frame(r);
    CanFrame y;
    y.id = co::kCobSync;
    d.on_frame(y);
  };
  for (std::uint16_t c : {std::uint16_t{0x06}, std::uint16_t{0x07}, std::uint16_t{0x0F}}) {
    cw = c;
    cycle();
  }
  ASSERT_EQ(d.state(), co::Cia402State::kOperationEnabled);
  target = 20000;  // 10 mm/s
  // Enabled, positive edge, but trigger source 00 (touch probe input): the index is not latched.
  tp = co::kTouchProbe1Enable | co::kTouchProbe1PositiveEdge;
  cycle();
  EXPECT_EQ(d.touch_probe_function(), tp);
  EXPECT_EQ(d.touch_probe_status(), co::kTouchProbe1Enabled);
  while (d.position_mm() < kPhaseMm + 0.01) cycle();
  EXPECT_EQ(d.touch_probe_status(), co::kTouchProbe1Enabled);
  EXPECT_EQ(d.index_latches(), 0);
  // The trigger switched to the index while bit 4 stays 1 is no edge: still not armed.
  tp = co::kTouchProbe1ArmIndex;
  cycle();
  while (d.position_mm() < kPhaseMm + kPitchMm + 0.01) cycle();
  EXPECT_EQ(d.index_latches(), 0);
  // Bit 4 0 -> 1: armed; the next pulse (10.3 mm) is latched exactly, once.
  tp = co::kTouchProbe1Enable | co::kTouchProbe1TriggerIndex;
  cycle();
  tp = co::kTouchProbe1ArmIndex;
  cycle();
  EXPECT_EQ(d.touch_probe_status(), co::kTouchProbe1Enabled);
  const double pulse_mm = kPhaseMm + 2 * kPitchMm;
  while (d.position_mm() < pulse_mm) cycle();
  EXPECT_EQ(d.index_latches(), 1);
  EXPECT_EQ(d.touch_probe_status(), co::kTouchProbe1Enabled | co::kTouchProbe1PositiveStored);
  EXPECT_EQ(d.touch_probe_position_counts(), 20600);  // 10.3 mm x 2000, not the sample after it
  EXPECT_DOUBLE_EQ(d.last_index_mm(), pulse_mm);
  // First event: the next pulse changes nothing.
  while (d.position_mm() < pulse_mm + kPitchMm + 0.01) cycle();
  EXPECT_EQ(d.index_latches(), 1);
  EXPECT_EQ(d.touch_probe_position_counts(), 20600);
  // Touch probe off clears the status; on again with bit 4 set is an edge: the next pulse.
  tp = 0;
  cycle();
  EXPECT_EQ(d.touch_probe_status(), 0);
  tp = co::kTouchProbe1ArmIndex;
  cycle();
  while (d.position_mm() < pulse_mm + 2 * kPitchMm + 0.01) cycle();
  EXPECT_EQ(d.index_latches(), 2);
  EXPECT_EQ(d.touch_probe_position_counts(), 40600);
  // Continuous (bit 1): every pulse, the last one's position.
  tp = 0;
  cycle();
  tp = co::kTouchProbe1ArmIndex | co::kTouchProbe1Continuous;
  cycle();
  while (d.position_mm() < pulse_mm + 4 * kPitchMm + 0.01) cycle();
  EXPECT_EQ(d.index_latches(), 4);
  EXPECT_EQ(d.touch_probe_position_counts(), 60600);
  // The TPDO carries them when mapped (0x60B9/0x60BA are PDO-mappable).
  sdo(0x1A01, 0, 0, 1);
  sdo(0x1A01, 1, 0x60B90010u, 4);
  sdo(0x1A01, 2, 0x60BA0020u, 4);
  sdo(0x1A01, 0, 2, 1);
}

// The bus: arm after the switch edge, latch, hold, disarm and re-arm; the position is the
// pulse's, quantised to the count, in position_mm's coordinates.
TEST(TouchProbeLoopback, ArmLatchesThePulseExactlyInThePositionCoordinates) {
  Scratch s;
  Bench b(s.load(machine(true)));
  b.start();
  daemon::AxisCommands cmd;
  daemon::BusFeedback fb = b.enable(cmd);
  cmd.index_arm[0] = true;
  cmd.velocity_mm_s[0] = 7.0;
  int k = 0;
  for (; k < 3000 && !fb.axis[0].index_latched; ++k) {
    fb = b.cycle(cmd);
    ASSERT_TRUE(fb.axis[0].index_present);
  }
  ASSERT_TRUE(fb.axis[0].index_latched) << b.can.drives[0]->position_mm();
  // The first pulse after the arm: 0.3 mm (the axis starts at 0).
  EXPECT_DOUBLE_EQ(b.can.drives[0]->last_index_mm(), kPhaseMm);
  EXPECT_DOUBLE_EQ(fb.axis[0].index_position_mm, 600.0 / 2000.0);
  // Held while armed, whatever pulses follow.
  for (int j = 0; j < 1000; ++j) fb = b.cycle(cmd);
  EXPECT_GT(fb.axis[0].position_mm, kPhaseMm + kPitchMm);
  EXPECT_TRUE(fb.axis[0].index_latched);
  EXPECT_DOUBLE_EQ(fb.axis[0].index_position_mm, 0.3);
  EXPECT_EQ(b.can.drives[0]->index_latches(), 1);
  // Disarm: cleared from the next cycle's feedback on; re-arm: not latched until a new pulse (the
  // old status is not taken).
  cmd.index_arm[0] = false;
  fb = b.cycle(cmd);
  fb = b.cycle(cmd);
  EXPECT_FALSE(fb.axis[0].index_latched);
  cmd.index_arm[0] = true;
  for (int j = 0; j < 5; ++j) {
    fb = b.cycle(cmd);
    EXPECT_FALSE(fb.axis[0].index_latched) << j;
  }
  const double next_mm = kPhaseMm + kPitchMm * std::ceil((b.can.drives[0]->position_mm() - kPhaseMm) / kPitchMm);
  for (k = 0; k < 3000 && !fb.axis[0].index_latched; ++k) fb = b.cycle(cmd);
  ASSERT_TRUE(fb.axis[0].index_latched);
  EXPECT_DOUBLE_EQ(b.can.drives[0]->last_index_mm(), next_mm);
  EXPECT_DOUBLE_EQ(fb.axis[0].index_position_mm,
                   static_cast<double>(std::llround(next_mm * 2000.0)) / 2000.0);
  EXPECT_EQ(b.can.drives[0]->index_latches(), 2);
  // A disarm whose RPDO is lost: the drive never saw the 0 (its status still shows the old
  // latch). The bus sends 0 until a status shows touch probe 1 off, so the old latch is not taken
  // and the arm is an edge at the drive: the next pulse.
  cmd.index_arm[0] = false;
  b.can.drop_rpdo1 = 1;
  b.cycle(cmd);
  cmd.index_arm[0] = true;
  for (int j = 0; j < 5; ++j) {
    fb = b.cycle(cmd);
    EXPECT_FALSE(fb.axis[0].index_latched) << j;
  }
  EXPECT_EQ(b.can.drives[0]->touch_probe_function(), co::kTouchProbe1ArmIndex);
  for (k = 0; k < 3000 && !fb.axis[0].index_latched; ++k) fb = b.cycle(cmd);
  ASSERT_TRUE(fb.axis[0].index_latched);
  EXPECT_EQ(b.can.drives[0]->index_latches(), 3);
  EXPECT_DOUBLE_EQ(fb.axis[0].index_position_mm,
                   static_cast<double>(std::llround(b.can.drives[0]->last_index_mm() * 2000.0)) / 2000.0);
  // A disarm and re-arm in consecutive cycles still arms on an edge at the drive.
  cmd.index_arm[0] = false;
  b.cycle(cmd);
  cmd.index_arm[0] = true;
  for (int j = 0; j < 5; ++j) {
    fb = b.cycle(cmd);
    EXPECT_FALSE(fb.axis[0].index_latched) << j;
  }
  for (k = 0; k < 3000 && !fb.axis[0].index_latched; ++k) fb = b.cycle(cmd);
  ASSERT_TRUE(fb.axis[0].index_latched);
  EXPECT_EQ(b.can.drives[0]->index_latches(), 4);
  b.bus->stop();
  EXPECT_EQ(b.can.drives[0]->touch_probe_function(), 0);  // disarmed with the drives
}

// The drive's 32-bit position register wraps (1e8 counts/mm: at 21.47 mm); the latch is
// unwrapped like 0x6064, so index_position_mm is the pulse's position in position_mm's terms.
TEST(TouchProbeLoopback, TheLatchIsUnwrappedLikeThePosition) {
  Scratch s;
  constexpr double kCpm = 1e8;
  auto x = drive(1, "X", kCpm);
  x.index_pitch_mm = 100.0;
  x.index_phase_mm = 21.6;  // past the wrap
  Bench b(s.load(machine(true, kCpm)), x);
  b.start();
  daemon::AxisCommands cmd;
  daemon::BusFeedback fb = b.enable(cmd);
  cmd.index_arm[0] = true;
  cmd.velocity_mm_s[0] = 20.0;  // 2e9 counts/s, inside 0x60FF's range
  for (int k = 0; k < 3000 && !fb.axis[0].index_latched; ++k) fb = b.cycle(cmd);
  ASSERT_TRUE(fb.axis[0].index_latched);
  EXPECT_LT(b.bus->master()->node(0).touch_probe_position_raw, 0);  // the register wrapped
  EXPECT_NEAR(fb.axis[0].index_position_mm, 21.6, 0.5 / kCpm);
  EXPECT_GT(fb.axis[0].position_mm, 21.6);
  EXPECT_LT(fb.axis[0].position_mm, 21.7);
}

// The same drives on a thread of their own, behind fixed rings: the master's thread allocates
// nothing in the fake, so an allocation counted there is the bus' (the simulated drive's object
// dictionary allocates on every frame, on its own thread).
class ThreadedLoopback final : public drivers::CanBus {
 public:
  ThreadedLoopback() {
    worker_ = std::thread([this] { run(); });
  }
  ~ThreadedLoopback() override {
    {
      std::lock_guard<std::mutex> g(m_);
      stop_ = true;
    }
    cv_.notify_all();
    worker_.join();
  }
  void add(sim::SimDriveSetup s) {
    std::lock_guard<std::mutex> g(m_);
    drives_.push_back(std::make_unique<sim::SimDrive>(std::move(s), [this](const CanFrame& f) {
      to_master_.push(f);  // (the worker holds m_ while a drive runs)
    }));
    drives_.back()->power_on();
  }
  SendResult send(const CanFrame& f) noexcept override {
    {
      std::lock_guard<std::mutex> g(m_);
      if (!to_drives_.push(f)) return SendResult::kDropped;
    }
    cv_.notify_all();
    return SendResult::kOk;
  }
  bool receive(CanFrame& f) noexcept override {
    std::lock_guard<std::mutex> g(m_);
    return to_master_.pop(f);
  }
  bool wait_readable(std::int64_t timeout_ns) noexcept override {
    std::unique_lock<std::mutex> l(m_);
    return cv_.wait_for(l, std::chrono::nanoseconds(timeout_ns), [this] { return !to_master_.empty(); });
  }
  CanStats stats() const noexcept override { return {}; }
  BusState bus_state() const noexcept override { return BusState::kErrorActive; }
  void clear_bus_state() noexcept override {}

 private:
  struct Ring {
    std::array<CanFrame, 4096> f{};
    std::size_t head = 0, tail = 0;
    bool push(const CanFrame& x) {
      if (head - tail == f.size()) return false;
      f[head++ % f.size()] = x;
      return true;
    }
    bool pop(CanFrame& x) {
      if (head == tail) return false;
      x = f[tail++ % f.size()];
      return true;
    }
    [[nodiscard]] bool empty() const { return head == tail; }
  };
  void run() {
    std::unique_lock<std::mutex> l(m_);
    for (;;) {
      cv_.wait(l, [this] { return stop_ || !to_drives_.empty(); });
      if (stop_) return;
      CanFrame f;
      while (to_drives_.pop(f))
        for (auto& d : drives_) d->on_frame(f);
      cv_.notify_all();
    }
  }
  std::mutex m_;
  std::condition_variable cv_;
  Ring to_drives_, to_master_;
  std::vector<std::unique_ptr<sim::SimDrive>> drives_;
  bool stop_ = false;
  std::thread worker_;
};

TEST(TouchProbeLoopback, TheArmAndLatchCyclesDoNotAllocate) {
  Scratch s;
  const config::Config cfg = s.load(machine(true));
  ThreadedLoopback can;
  can.add(drive(1, "X"));
  can.add(drive(2, "Y"));
  daemon::CanopenBus bus(cfg, can, daemon::CanopenBus::Log{});
  bus.set_event_thread(false);
  bus.start();
  daemon::AxisCommands cmd;
  cmd.mode = daemon::DriveMode::kEnabled;
  daemon::BusFeedback fb;
  for (int k = 0; k < 50; ++k) {
    bus.begin_cycle();
    bus.read(fb);
    bus.write(cmd);
  }
  ASSERT_TRUE(fb.axis[0].enabled);
  cmd.velocity_mm_s[0] = 7.0;
  int latched = 0, latches = 0;
  test::AllocCounts counts;
  {
    test::AllocGuard guard;
    bool was = false;
    for (int k = 0; k < 10000; ++k) {
      cmd.index_arm[0] = (k / 1000) % 2 == 0;  // arm, latch, disarm, re-arm ...
      bus.begin_cycle();
      bus.read(fb);
      bus.write(cmd);
      latched += fb.axis[0].index_latched ? 1 : 0;
      latches += fb.axis[0].index_latched && !was ? 1 : 0;
      was = fb.axis[0].index_latched;
    }
    counts = guard.counts();
  }
  EXPECT_EQ(latches, 5);  // every arm found a pulse (7 mm per arm, one every 5 mm)
  EXPECT_GT(latched, 1000);
  EXPECT_EQ(counts.news, 0u);
  EXPECT_EQ(counts.mallocs, 0u);
  bus.stop();
}

TEST(TouchProbeLoopback, DriveWithoutTheTouchProbeStopsTheStartUpNamingNodeAndObject) {
  Scratch s;
  Bench b(s.load(machine(true)));
  b.can.drives.clear();
  auto x = drive(1, "X");
  x.quirks.missing = {{0x60B8, -1}, {0x60B9, -1}, {0x60BA, -1}};
  b.can.add(x);
  b.can.add(drive(2, "Y"));
  try {
    b.start();
    FAIL() << "started without the touch probe";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("node 1 (X)"), std::string::npos) << what;
    EXPECT_NE(what.find("0x60B8:00 touch probe function"), std::string::npos) << what;
    EXPECT_NE(what.find("home.use_index"), std::string::npos) << what;
    EXPECT_NE(what.find("0x06020000"), std::string::npos) << what;
  }
  // Only 0x60BA missing: named too.
  Bench c(s.load(machine(true)));
  c.can.drives.clear();
  x.quirks.missing = {{0x60BA, -1}};
  c.can.add(x);
  c.can.add(drive(2, "Y"));
  try {
    c.start();
    FAIL() << "started without 0x60BA";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("0x60BA:00 touch probe 1 positive edge position"),
              std::string::npos)
        << e.what();
  }
  // Without use_index the same drive starts.
  Bench plain(s.load(machine(false)));
  plain.can.drives.clear();
  x.quirks.missing = {{0x60B8, -1}, {0x60B9, -1}, {0x60BA, -1}};
  plain.can.add(x);
  plain.can.add(drive(2, "Y"));
  EXPECT_NO_THROW(plain.start());
}

TEST(TouchProbeLoopback, OnePdoDriveIsRefusedNamingNodeAndPdo) {
  Scratch s;
  // One PDO each way: the home switch's TPDO2 is refused first; with the switch's own TPDO on a
  // two-PDO drive, the touch probe's TPDO3 is.
  Bench b(s.load(machine(true, 2000.0, "  nodes: [{node_id: 1, profile: one-pdo}]\n")));
  EXPECT_THROW(b.start(), std::runtime_error);
  const std::string two = "  nodes: [{node_id: 1, profile: two-pdo}]\n";
  std::string y = machine(true, 2000.0, two);
  y.replace(y.find("one-pdo: {rpdos: 1, tpdos: 1}"), 29, "two-pdo: {rpdos: 2, tpdos: 2}");
  Bench c(s.load(y));
  try {
    c.start();
    FAIL() << "a two-TPDO drive took 0x60FD and the touch probe";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("node 1 (X)"), std::string::npos) << what;
    EXPECT_NE(what.find("0x60B9/0x60BA touch probe"), std::string::npos) << what;
    EXPECT_NE(what.find("TPDO3"), std::string::npos) << what;
    EXPECT_NE(what.find("two-pdo"), std::string::npos) << what;
  }
}

}  // namespace
}  // namespace contour
