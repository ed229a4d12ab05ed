// Homing (issue 18): HomingSource (daemon/reference_sources.hpp) on an ideal axis whose home
// switch closes below a threshold, and the servo loop homing the simulated machine of
// config/sim.yaml from a power-up position that is not zero (SimBus::power_up_at).
#include <gtest/gtest.h>

#include <cmath>

#include "daemon/reference_sources.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

constexpr double kT = 0.001;

LiveLimits limits() {
  LiveLimits l;
  l.max_velocity_mm_s = {100.0, 100.0, 50.0};
  l.max_accel_mm_s2 = {1000.0, 1000.0, 500.0};
  return l;
}

// An axis that follows its reference one cycle late, with the home switch closed below
// `switch_mm` (per axis), sampled with the position.
struct IdealAxes {
  std::array<double, 3> switch_mm{-20.0, -20.0, -10.0};
  Feedback fb;
  IdealAxes() {
    for (std::size_t a = 0; a < 3; ++a) {
      fb.bus.axis[a].digital_inputs_present = true;
      fb.bus.axis[a].digital_inputs_fresh = true;
    }
  }
  void sense(const Eigen::Vector3d& pos) {
    fb.act_mm = pos;
    for (std::size_t a = 0; a < 3; ++a) {
      fb.bus.axis[a].digital_inputs = pos[static_cast<Eigen::Index>(a)] < switch_mm[a] ? HomingSource::kHomeSwitchBit : 0u;
    }
  }
};

HomingSource::AxisPlan plan(int sequence, double search, double latch, double offset, double position) {
  return {true, sequence, search, latch, offset, position, 100.0, false, false, 60.0};
}

struct HomingRun {
  int cycles = 0;
  double max_speed = 0.0;
  double max_accel = 0.0;
  std::array<double, 3> latch{};
  bool shifted = false;
};

// Steps the source to its end; at the shift, applies it as the loop does (latch -> offset).
HomingRun run(HomingSource& h, IdealAxes& ax, Eigen::Vector3d pos, int max_cycles = 200000) {
  HomingRun out;
  Eigen::Vector3d v_prev = Eigen::Vector3d::Zero();
  for (; out.cycles < max_cycles && h.active(); ++out.cycles) {
    ax.sense(pos);
    RefPoint r = h.step(ax.fb, limits(), kT);
    EXPECT_EQ(r.source, SourceKind::kHoming);
    EXPECT_TRUE(r.track);
    if (h.shift_pending()) {
      for (int i = 0; i < 3; ++i) {
        if ((h.group_mask() >> i & 1u) == 0) continue;
        out.latch[static_cast<std::size_t>(i)] = h.latch_mm(i);
        const double shift = h.offset_mm(i) - h.latch_mm(i);
        r.position_mm[i] += shift;
        pos[i] += shift;
        ax.switch_mm[static_cast<std::size_t>(i)] += shift;
      }
      h.shifted(r.position_mm);
      out.shifted = true;
    }
    const Eigen::Vector3d v = (r.position_mm - pos) / kT;
    for (int i = 0; i < 3; ++i) {
      out.max_speed = std::max(out.max_speed, std::abs(v[i]));
      out.max_accel = std::max(out.max_accel, std::abs(v[i] - v_prev[i]) / kT);
    }
    v_prev = v;
    pos = r.position_mm;
  }
  return out;
}

TEST(HomingSource, ReleaseEdgeLatchFindsTheSwitchAndEndsAtTheHomePosition) {
  // Search towards -, latch on the way back (+): LinuxCNC's opposite-sign HOME_LATCH_VEL.
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(0, -50.0, 1.0, -100.0, -90.0);
  IdealAxes ax;
  h.start(p, 3, Eigen::Vector3d(5.0, 1.0, 2.0));
  ASSERT_TRUE(h.active());
  const HomingRun r = run(h, ax, Eigen::Vector3d(5.0, 1.0, 2.0));
  EXPECT_FALSE(h.active());
  EXPECT_FALSE(h.failed());
  EXPECT_TRUE(r.shifted);
  // The edge is seen in the first cycle the axis is past it at 1 mm/s: within 1 um + one step.
  EXPECT_NEAR(r.latch[0], -20.0, 0.0011);
  EXPECT_LE(r.max_speed, 50.0 + 1e-9);
  EXPECT_LE(r.max_accel, 1000.0 * (1.0 + 1e-9));  // ramps at the live acceleration limit
  EXPECT_EQ(h.phase(0), HomingSource::Phase::kDone);
  EXPECT_EQ(h.phase(1), HomingSource::Phase::kIdle);  // not homed by this run: never moved
}

TEST(HomingSource, SameSignLatchBacksOffAndLatchesOnTheSlowApproach) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(0, -50.0, -1.0, 0.0, 10.0);
  IdealAxes ax;
  h.start(p, 3, Eigen::Vector3d::Zero());
  bool saw_approach = false;
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();
  double latch = 0.0;
  for (int n = 0; n < 200000 && h.active(); ++n) {
    ax.sense(pos);
    RefPoint r = h.step(ax.fb, limits(), kT);
    saw_approach = saw_approach || h.phase(0) == HomingSource::Phase::kApproach;
    if (h.shift_pending()) {
      latch = h.latch_mm(0);
      r.position_mm[0] += h.offset_mm(0) - latch;
      ax.switch_mm[0] += h.offset_mm(0) - latch;
      h.shifted(r.position_mm);
    }
    pos = r.position_mm;
  }
  EXPECT_TRUE(saw_approach);
  EXPECT_NEAR(latch, -20.0, 0.0011);  // closing edge, approached at -1 mm/s
  EXPECT_NEAR(pos[0], 10.0, 1e-9);
  EXPECT_FALSE(h.failed());
}

TEST(HomingSource, SequenceGroupsHomeInOrderAndTogetherWithinAGroup) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(1, -50.0, 1.0, 0.0, 0.0);
  p[1] = plan(1, -50.0, 1.0, 0.0, 0.0);
  p[2] = plan(0, -20.0, 1.0, 0.0, 0.0);
  IdealAxes ax;
  h.start(p, 3, Eigen::Vector3d::Zero());
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();
  bool xy_moved_before_z_done = false;
  bool x_and_y_searched_together = false;
  for (int n = 0; n < 400000 && h.active(); ++n) {
    ax.sense(pos);
    RefPoint r = h.step(ax.fb, limits(), kT);
    if (h.phase(2) != HomingSource::Phase::kDone && (r.position_mm[0] != 0.0 || r.position_mm[1] != 0.0)) {
      xy_moved_before_z_done = true;
    }
    x_and_y_searched_together = x_and_y_searched_together ||
                                (h.phase(0) == HomingSource::Phase::kSearch &&
                                 h.phase(1) == HomingSource::Phase::kSearch);
    if (h.shift_pending()) {
      for (int i = 0; i < 3; ++i) {
        if ((h.group_mask() >> i & 1u) == 0) continue;
        const double s = h.offset_mm(i) - h.latch_mm(i);
        r.position_mm[i] += s;
        ax.switch_mm[static_cast<std::size_t>(i)] += s;
      }
      h.shifted(r.position_mm);
    }
    pos = r.position_mm;
  }
  EXPECT_FALSE(xy_moved_before_z_done);
  EXPECT_TRUE(x_and_y_searched_together);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(h.phase(i), HomingSource::Phase::kDone) << i;
}

TEST(HomingSource, ASwitchThatNeverClosesFailsAfterTheSearchDistanceAndStops) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(0, -50.0, 1.0, 0.0, 0.0);
  p[0].search_distance_mm = 30.0;
  IdealAxes ax;
  ax.switch_mm[0] = -1000.0;  // out of reach
  h.start(p, 3, Eigen::Vector3d::Zero());
  const HomingRun r = run(h, ax, Eigen::Vector3d::Zero());
  EXPECT_FALSE(h.active());
  ASSERT_TRUE(h.failed());
  EXPECT_EQ(h.failed_axis(), 0);
  EXPECT_EQ(h.failure_code(), 2);
  EXPECT_GT(h.failure_value(), 30.0);
  EXPECT_FALSE(r.shifted);
  EXPECT_LE(r.max_accel, 1000.0 * (1.0 + 1e-9));  // braked at the limit, no jump
}

TEST(HomingSource, NoDigitalInputsFailsAtOnceWithoutMoving) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[1] = plan(0, -50.0, 1.0, 0.0, 0.0);
  IdealAxes ax;
  ax.fb.bus.axis[1].digital_inputs_present = false;
  h.start(p, 3, Eigen::Vector3d::Zero());
  const HomingRun r = run(h, ax, Eigen::Vector3d::Zero());
  ASSERT_TRUE(h.failed());
  EXPECT_EQ(h.failure_code(), 1);
  EXPECT_EQ(r.max_speed, 0.0);
}

TEST(HomingSource, AbortBrakesMonotonicallyAndEndsWithoutHoming) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(0, -50.0, 1.0, 0.0, 0.0);
  IdealAxes ax;
  h.start(p, 3, Eigen::Vector3d::Zero());
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();
  for (int n = 0; n < 100; ++n) {  // at speed (50 mm/s after 50 ms)
    ax.sense(pos);
    pos = h.step(ax.fb, limits(), kT).position_mm;
  }
  h.abort();
  double speed_prev = 1e9;
  int n = 0;
  for (; n < 10000 && h.active(); ++n) {
    ax.sense(pos);
    const Eigen::Vector3d next = h.step(ax.fb, limits(), kT).position_mm;
    const double speed = std::abs(next[0] - pos[0]) / kT;
    EXPECT_LE(speed, speed_prev + 1e-9) << "cycle " << n;
    speed_prev = speed;
    pos = next;
  }
  EXPECT_FALSE(h.active());
  EXPECT_FALSE(h.failed());
  EXPECT_LE(n, 52);  // 50 mm/s at 1000 mm/s^2: 50 cycles
  EXPECT_EQ(h.phase(0), HomingSource::Phase::kIdle);
}

TEST(HomingSource, NoAllocationInStep) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(0, -50.0, 1.0, 0.0, 0.0);
  IdealAxes ax;
  h.start(p, 3, Eigen::Vector3d::Zero());
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 3000; ++n) {
      ax.sense(pos);
      pos = h.step(ax.fb, limits(), kT).position_mm;
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

// The loop on config/sim.yaml's simulated machine, which must be homed (allow_unhomed: false)
// and powers up away from zero.
config::Config homing_config() {
  config::Config c = test_rig::sim_config();
  c.machine.allow_unhomed = false;
  c.machine.axes[0].sim_power_up_mm = -150.0;
  c.machine.axes[1].sim_power_up_mm = 120.0;
  c.machine.axes[2].sim_power_up_mm = -80.0;
  return c;
}

// The loop rig on that machine, enabled.
struct HomingRig {
  config::Config cfg = homing_config();
  test_rig::Rig rig{cfg};
  bool enabled = false;
  HomingRig() {
    configure_sim_machine(rig.bus, cfg);
    enabled = rig.enable();
  }
};

TEST(HomingLoop, RunIsRefusedUntilHomedThenTheMachineCoordinatesAreTheTruePositions) {
  HomingRig h;
  test_rig::Rig& rig = h.rig;
  ASSERT_TRUE(h.enabled);
  EXPECT_EQ(rig.loop.status().homed_mask, 0u);
  // Not homed: the encoders read 0 where the axes powered up.
  EXPECT_NEAR(rig.loop.status().act_mm[0], 0.0, 1e-3);
  auto job = rig.load("G1 X1 F600\nM2\n", 1);
  rig.events.clear();
  rig.loop.post({CommandKind::kRun});
  rig.step(5);
  EXPECT_NE(rig.loop.status().state, MachineState::kRunning);
  bool refused = false;
  for (const auto& e : rig.events) refused = refused || (e.kind == EventKind::kCommandRefused && e.command == CommandKind::kRun);
  EXPECT_TRUE(refused);
  rig.loop.post({CommandKind::kStop});  // unload
  rig.step(5);

  rig.loop.post({CommandKind::kHome, -1});
  rig.step(3);
  ASSERT_TRUE(rig.loop.status().homing);
  int n = 0;
  for (; n < 120000 && rig.loop.status().homing; n += 100) rig.step(100);
  ASSERT_FALSE(rig.loop.status().homing) << "homing did not end";
  EXPECT_EQ(rig.loop.status().homed_mask, 7u);
  EXPECT_EQ(rig.loop.status().homing_failure, 0);
  EXPECT_EQ(rig.loop.status().state, MachineState::kReady);
  rig.step(1000);  // settle at home_position_mm (0)
  for (int i = 0; i < 3; ++i) {
    // The machine position equals the plant's true position within the latch resolution
    // (1 um at latch_vel 60 mm/min) plus the encoder's BLU (0.5 um).
    EXPECT_NEAR(rig.loop.status().act_mm[static_cast<std::size_t>(i)], rig.bus.true_position_mm(i), 0.0016) << i;
    EXPECT_NEAR(rig.loop.status().ref_mm[static_cast<std::size_t>(i)], 0.0, 1e-9) << i;
  }
  EXPECT_NEAR(rig.loop.status().home_shift_mm[0], -150.0, 0.0016);
  EXPECT_NEAR(rig.loop.status().home_shift_mm[1], 120.0, 0.0016);
  // Homed: a program runs.
  auto job2 = rig.load("G1 X1 F600\nM2\n", 2);
  rig.loop.post({CommandKind::kRun});
  rig.step(5);
  EXPECT_EQ(rig.loop.status().state, MachineState::kRunning);
}

TEST(HomingLoop, UnhomedJogIsSlowAndIgnoresTheSoftLimits) {
  HomingRig h;
  test_rig::Rig& rig = h.rig;
  const config::Config& cfg = h.cfg;
  ASSERT_TRUE(h.enabled);
  // 300 mm down from the power-up position: past min_mm -200 in encoder coordinates.
  rig.loop.post({CommandKind::kJog, 0, 50.0, -300.0});
  rig.step(3);
  ASSERT_TRUE(rig.loop.status().jogging);
  double vmax = 0.0;
  double prev = rig.loop.status().ref_mm[0];
  for (int n = 0; n < 2000; ++n) {
    rig.step();
    const double x = rig.loop.status().ref_mm[0];
    vmax = std::max(vmax, std::abs(x - prev) / cfg.machine.period_s);
    prev = x;
  }
  // home.unhomed_jog_mm_min defaults to 600 mm/min: 10 mm/s, not the 50 asked for.
  EXPECT_NEAR(vmax, 10.0, 1e-6);
  EXPECT_EQ(rig.loop.status().state, MachineState::kReady);
}

TEST(HomingLoop, StopAbortsHomingAndTheAxesStayUnhomed) {
  HomingRig h;
  test_rig::Rig& rig = h.rig;
  ASSERT_TRUE(h.enabled);
  rig.loop.post({CommandKind::kHome, -1});
  rig.step(200);
  ASSERT_TRUE(rig.loop.status().homing);
  rig.loop.post({CommandKind::kStop});
  rig.step(500);
  EXPECT_FALSE(rig.loop.status().homing);
  EXPECT_EQ(rig.loop.status().homed_mask, 0u);
  EXPECT_EQ(rig.loop.status().homing_failure, 5);
  EXPECT_EQ(rig.loop.status().state, MachineState::kReady);
}

}  // namespace
}  // namespace contour::daemon

namespace contour::daemon {
namespace {

// home.use_index on a bus that cannot latch the index: homing fails at once (code 6), unmoved.
TEST(HomingSource, UseIndexWithoutAnIndexLatchFailsAtOnce) {
  HomingSource h;
  std::array<HomingSource::AxisPlan, kMaxAxes> p{};
  p[0] = plan(0, -50.0, 1.0, -100.0, -90.0);
  p[0].use_index = true;
  IdealAxes ax;  // digital inputs, no index
  h.start(p, 3, Eigen::Vector3d::Zero());
  const HomingRun r = run(h, ax, Eigen::Vector3d::Zero());
  EXPECT_TRUE(h.failed());
  EXPECT_EQ(h.failure_code(), 6);
  EXPECT_FALSE(r.shifted);
  EXPECT_LT(r.max_speed, 0.1);
  EXPECT_NE(std::string(homing_failure_text(6)).find("index"), std::string::npos);
}

// Index homing on the simulated machine (LinuxCNC's HOME_USE_INDEX): X searches its switch,
// backs off at a latch speed ten times sim.yaml's (10 mm/s: a switch latch would be ~10 um off)
// and goes on to the encoder's next index pulse (every 5 mm of true travel, at 0.25 + 5k mm):
// the first one past the switch's release point (-199.5) is at -194.75 true, which
// home_offset_mm names, so the machine position is the true position to the count, from any
// power-up position.
TEST(HomingLoop, IndexHomingIsExactToTheCountFromAnyPowerUpPosition) {
  for (const double power_up : {-150.0, -37.3}) {
    config::Config cfg = homing_config();
    cfg.machine.axes[0].sim_power_up_mm = power_up;
    auto& x = cfg.machine.axes[0];
    x.home.use_index = true;
    x.home.latch_vel_mm_s = 10.0;
    x.home.home_offset_mm = -194.75;
    x.sim_index_pitch_mm = 5.0;
    x.sim_index_phase_mm = 0.25;
    test_rig::Rig rig{cfg};
    configure_sim_machine(rig.bus, cfg);
    ASSERT_TRUE(rig.enable());
    rig.loop.post({CommandKind::kHome, 0});
    rig.step(3);
    ASSERT_TRUE(rig.loop.status().homing);
    bool saw_index_phase = false;
    for (int n = 0; n < 200000 && rig.loop.status().homing; ++n) {
      rig.step(1);
      saw_index_phase = saw_index_phase || rig.loop.status().home_phase[0] ==
                                               static_cast<std::uint8_t>(HomingSource::Phase::kIndex);
    }
    ASSERT_FALSE(rig.loop.status().homing) << "homing did not end";
    EXPECT_TRUE(saw_index_phase);
    EXPECT_EQ(rig.loop.status().homing_failure, 0);
    EXPECT_EQ(rig.loop.status().homed_mask & 1u, 1u);
    rig.step(1000);
    // Exact to the encoder's resolution (BLU 0.5 um), not to the latch speed's step (10 um).
    EXPECT_NEAR(rig.loop.status().act_mm[0], rig.bus.true_position_mm(0), 0.0006) << power_up;
    EXPECT_NEAR(rig.loop.status().ref_mm[0], 0.0, 1e-9);
  }
}

// The index must come: none within search_distance_mm after the switch edge fails the homing
// (code 7) and the axis stays unhomed.
TEST(HomingLoop, NoIndexWithinTheSearchDistanceFailsTheHoming) {
  config::Config cfg = homing_config();
  auto& x = cfg.machine.axes[0];
  x.home.use_index = true;
  x.home.search_distance_mm = 100.0;  // (the power-up at -150 finds the switch within 50 mm)
  x.sim_index_pitch_mm = 1000.0;       // next index past the switch: true 0, 199.5 mm on
  x.sim_index_phase_mm = 0.0;
  test_rig::Rig rig{cfg};
  configure_sim_machine(rig.bus, cfg);
  ASSERT_TRUE(rig.enable());
  rig.loop.post({CommandKind::kHome, 0});
  rig.step(3);
  for (int n = 0; n < 400000 && rig.loop.status().homing; n += 100) rig.step(100);
  EXPECT_FALSE(rig.loop.status().homing);
  EXPECT_EQ(rig.loop.status().homing_failure, 7);
  EXPECT_EQ(rig.loop.status().homed_mask & 1u, 0u);
}

}  // namespace
}  // namespace contour::daemon
