// HIL: closed loop and faults over vcan0 against contour-machine-sim in lockstep (config/hil.yaml).
// The loop is a plain P controller on a straight 3-axis line (the contour-control library is a
// separate issue); the reference is the same loop on in-process control::FeedDrive with the
// configured delay (1 period = the synchronous-RPDO transport delay) and the same velocity
// quantisation (counts/s) as the CAN path.
#include <atomic>
#include <cmath>
#include <cstdio>

#include "control/feed_drive.hpp"
#include "tests/hil/canopen_hil_support.hpp"

namespace {

namespace co = contour::drivers::canopen;
using co::CycleStatus;

struct LineLoop {
  double kp = 0.6;
  std::array<double, 3> dir_mm_s = {20.0, -12.0, 5.0};
  double command_mm_s(int axis, int k, double y_mm, double gain_per_s, double period_s) const {
    const double r = dir_mm_s[static_cast<std::size_t>(axis)] * k * period_s;
    return gain_per_s * kp * (r - y_mm);
  }
};

// Runs `cycles` loop cycles over CAN; returns positions [cycle][axis] in mm.
std::vector<std::array<double, 3>> run_can(contour::test::Rig& rig, const contour::config::Config& cfg,
                                           int cycles, const LineLoop& loop, bool* fault = nullptr) {
  auto& m = *rig.master;
  std::vector<std::array<double, 3>> out;
  for (int k = 0; k < cycles; ++k) {
    auto a = m.begin_cycle(rig.cycle * rig.period_ns);
    auto b = m.collect();
    std::array<double, 3> y{};
    for (int i = 0; i < 3; ++i) {
      const auto& ax = cfg.machine.axes[static_cast<std::size_t>(i)];
      y[static_cast<std::size_t>(i)] = co::counts_to_mm(m.node(static_cast<std::size_t>(i)).position_counts, ax.counts_per_mm);
      const double v = loop.command_mm_s(i, k, y[static_cast<std::size_t>(i)], ax.drive.gain_per_s, 1e-3);
      m.set_target(static_cast<std::size_t>(i), co::mm_s_to_counts_s(v, ax.counts_per_mm));
    }
    if ((a == CycleStatus::kFault || b == CycleStatus::kFault) && fault != nullptr && !*fault) {
      *fault = true;
      m.quick_stop_all();  // the supervisor's reaction: controlled stop of every axis
    }
    m.send_rpdos();
    ++rig.cycle;
    out.push_back(y);
  }
  return out;
}

std::vector<std::array<double, 3>> run_reference(const contour::config::Config& cfg, int cycles,
                                                 const LineLoop& loop) {
  std::array<contour::control::FeedDrive, 3> d;
  for (std::size_t i = 0; i < 3; ++i) {
    auto p = cfg.machine.axes[i].drive;
    p.period_s = 1e-3;
    d[i].configure(p);
  }
  std::vector<std::array<double, 3>> out;
  for (int k = 0; k < cycles; ++k) {
    std::array<double, 3> y{};
    for (int i = 0; i < 3; ++i) {
      const auto& ax = cfg.machine.axes[static_cast<std::size_t>(i)];
      auto& di = d[static_cast<std::size_t>(i)];
      y[static_cast<std::size_t>(i)] = di.measured_mm();
      const double v = loop.command_mm_s(i, k, y[static_cast<std::size_t>(i)], ax.drive.gain_per_s, 1e-3);
      di.step_velocity(co::mm_s_to_counts_s(v, ax.counts_per_mm) / ax.counts_per_mm);
    }
    out.push_back(y);
  }
  return out;
}

struct Started {
  contour::config::Config cfg = contour::test::hil_config();
  contour::test::MachineSim sim;
  contour::test::Rig rig;
  explicit Started(std::vector<std::string> flags, bool filters = false)
      : sim(std::move(flags)), rig(contour::test::hil_master_config(cfg), filters) {}
};

}  // namespace

TEST(CanopenLoop, ClosedLoopOverCanMatchesInProcessFeedDrive) {
  Started s({});
  ASSERT_TRUE(s.sim.ready()) << s.sim.stop();
  s.rig.master->start_up();
  ASSERT_GT(s.rig.enable_all(), 0);
  LineLoop loop;
  constexpr int kCycles = 1500;
  const auto can = run_can(s.rig, s.cfg, kCycles, loop);
  const auto ref = run_reference(s.cfg, kCycles, loop);
  double worst = 0.0;
  for (int k = 0; k < kCycles; ++k)
    for (std::size_t i = 0; i < 3; ++i)
      worst = std::max(worst, std::abs(can[static_cast<std::size_t>(k)][i] - ref[static_cast<std::size_t>(k)][i]));
  std::printf("[figure] closed loop over vcan vs in-process FeedDrive, %d cycles: max |dx| = %.3g mm; "
              "final X %.4f Y %.4f Z %.4f mm\n", kCycles, worst, can.back()[0], can.back()[1], can.back()[2]);
  EXPECT_LE(worst, 1e-6);
  EXPECT_GT(can.back()[0], 20.0);  // it moved: ~30 mm of the 20 mm/s line in 1.5 s minus lag
  EXPECT_LT(can.back()[1], -12.0);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(s.rig.master->node(i).missed_total, 0u);
}

TEST(CanopenLoop, DriveFaultMidRunBringsAllAxesToAControlledStop) {
  Started s({"--fault", "2:300:0x2310"});
  ASSERT_TRUE(s.sim.ready()) << s.sim.stop();
  s.rig.master->start_up();
  ASSERT_GT(s.rig.enable_all(), 0);
  bool fault = false;
  const auto y = run_can(s.rig, s.cfg, 800, LineLoop{}, &fault);
  ASSERT_TRUE(fault);
  const auto ev = s.rig.events();
  std::string all;
  for (const auto& e : ev) all += e + "\n";
  std::printf("%s", all.c_str());
  EXPECT_NE(all.find("EMCY node 2 (Y): 0x2310 continuous over-current"), std::string::npos) << all;
  EXPECT_NE(all.find("node 2 (Y): drive fault"), std::string::npos) << all;
  auto& m = *s.rig.master;
  EXPECT_EQ(m.node(1).state, co::Cia402State::kFault);
  EXPECT_EQ(m.node(0).state, co::Cia402State::kSwitchOnDisabled);  // quick stop option 2: ramp, then off
  EXPECT_EQ(m.node(2).state, co::Cia402State::kSwitchOnDisabled);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_NEAR(y.back()[i], y[y.size() - 50][i], 1e-9) << "axis " << i << " still moving";
    EXPECT_GT(std::abs(y.back()[i]), 0.1) << "axis " << i << " never moved";
  }
}

TEST(CanopenLoop, HeartbeatLossDetectedWithinItsTimeout) {
  Started s({"--stop-heartbeat", "3:100"});
  ASSERT_TRUE(s.sim.ready()) << s.sim.stop();
  s.rig.master->start_up();
  ASSERT_GT(s.rig.enable_all(), 0);
  std::int64_t detected_ns = -1;
  for (int k = 0; k < 1000 && detected_ns < 0; ++k) {
    if (s.rig.step() == CycleStatus::kFault) detected_ns = (s.rig.cycle - 1) * s.rig.period_ns;
  }
  ASSERT_GE(detected_ns, 0) << "heartbeat loss not detected";
  const auto& n = s.rig.master->node(2);
  EXPECT_NE(n.faults & static_cast<std::uint8_t>(co::NodeFault::kHeartbeatLost), 0);
  const double after_ms = static_cast<double>(detected_ns - n.last_heartbeat_ns) / 1e6;
  std::printf("[figure] heartbeat loss of node 3 detected %.0f ms (lockstep time) after its last "
              "heartbeat; timeout 200 ms\n", after_ms);
  EXPECT_GT(after_ms, 200.0);
  EXPECT_LE(after_ms, 202.0);
  for (std::size_t i : {0u, 1u, 3u}) EXPECT_EQ(s.rig.master->node(i).faults, 0) << i;
}

TEST(CanopenLoop, MalformedAndUnknownFramesAreCountedAndIgnored) {
  Started s({"--malformed", "1:50"});
  ASSERT_TRUE(s.sim.ready()) << s.sim.stop();
  s.rig.master->start_up();
  ASSERT_GT(s.rig.enable_all(), 0);
  for (int k = 0; k < 100; ++k) ASSERT_EQ(s.rig.step(), CycleStatus::kOk) << k;
  const auto& c = s.rig.master->counters();
  EXPECT_GE(c.malformed_frames, 3u);  // short TPDO, 3-byte EMCY, 2-byte heartbeat
  EXPECT_GE(c.late_or_stray_frames, 1u);  // unsolicited SDO response
  EXPECT_GE(c.unknown_frames, 1u);  // 0x7E5
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(s.rig.master->node(i).missed_total, 0u);
}

TEST(CanopenLoop, FloodOfUnrelatedFramesDoesNotBreakTheCycle) {
  Started s({}, /*filters=*/true);
  ASSERT_TRUE(s.sim.ready()) << s.sim.stop();
  s.rig.master->start_up();
  ASSERT_GT(s.rig.enable_all(), 0);
  std::atomic<bool> stop{false};
  std::atomic<long> sent{0};
  std::thread flood([&] {
    contour::drivers::SocketCan tx(contour::test::kIface);
    std::uint32_t x = 12345;
    while (!stop) {
      contour::drivers::CanFrame f;
      x = x * 1103515245u + 12345u;
      // 0x101..0x17F (unused by the predefined set) and 29-bit ids, random payloads
      f.extended = (x >> 16) % 3 == 0;
      f.id = f.extended ? (x & 0x1FFFFFFF) : 0x101 + (x >> 8) % 0x7F;
      f.dlc = static_cast<std::uint8_t>((x >> 4) % 9);
      f.data.fill(static_cast<std::uint8_t>(x));
      if (tx.send(f) == contour::drivers::SendResult::kOk) ++sent;
    }
  });
  LineLoop loop;
  const auto can = run_can(s.rig, s.cfg, 600, loop);
  stop = true;
  flood.join();
  const auto ref = run_reference(s.cfg, 600, loop);
  double worst = 0.0;
  for (std::size_t k = 0; k < can.size(); ++k)
    for (std::size_t i = 0; i < 3; ++i) worst = std::max(worst, std::abs(can[k][i] - ref[k][i]));
  std::printf("[figure] flood: %ld unrelated frames during 600 cycles; max |dx| vs reference %.3g mm\n",
              sent.load(), worst);
  EXPECT_GT(sent.load(), 1000);
  EXPECT_LE(worst, 1e-6);
  EXPECT_FALSE(s.rig.master->any_fault());
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(s.rig.master->node(i).missed_total, 0u);
}

TEST(CanopenLoop, DroppedTpdosAreCountedAndFaultAfterTheStreak) {
  Started s({"--drop-tpdo", "1:100:5"});
  ASSERT_TRUE(s.sim.ready()) << s.sim.stop();
  // Each dropped TPDO costs the whole (200 ms) deadline; a shorter one made the other nodes'
  // TPDOs miss it under the VM's steal time.
  auto& rig = s.rig;
  rig.master->start_up();
  ASSERT_GT(rig.enable_all(), 0);
  bool fault = false;
  for (int k = 0; k < 150; ++k) fault = rig.step() == CycleStatus::kFault || fault;
  EXPECT_TRUE(fault);
  EXPECT_EQ(rig.master->node(0).missed_total, 5u);
  EXPECT_EQ(rig.master->node(1).missed_total, 0u);
  const auto ev = rig.events();
  ASSERT_FALSE(ev.empty());
  EXPECT_NE(ev[0].find("node 1 (X): 3 TPDOs missed in a row"), std::string::npos) << ev[0];
}
