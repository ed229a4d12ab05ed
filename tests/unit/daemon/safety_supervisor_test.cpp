// SafetySupervisor (daemon/safety_supervisor.hpp): each rule on a Feedback snapshot, its
// precedence, and the reset rule. No loop, bus or daemon.
#include <gtest/gtest.h>

#include "daemon/safety_supervisor.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::sim_config;

struct Sup {
  Sup() : cfg(sim_config()), sup(cfg, false), lim(live_limits_from(cfg)) {
    for (auto& a : fb.bus.axis) {
      a.fresh = true;
      a.enabled = true;
    }
  }
  config::Config cfg;
  SafetySupervisor sup;
  LiveLimits lim;
  Feedback fb;
};

TEST(SafetySupervisor, AHealthySnapshotRaisesNothing) {
  Sup s;
  EXPECT_FALSE(s.sup.check_bus(s.fb, true));
  EXPECT_FALSE(s.sup.check_estop(s.fb));
  EXPECT_FALSE(s.sup.check_motion(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                  Eigen::Vector3d::Zero(), 0.0, s.lim));
  EXPECT_TRUE(s.sup.causes_gone(s.fb, false));
}

TEST(SafetySupervisor, BusRulesNameTheAxisAndKeepTheirPrecedence) {
  Sup s;
  s.fb.bus.axis[1].fault = true;
  s.fb.bus.heartbeat_lost = true;
  s.fb.bus.heartbeat_lost_node = 3;
  FaultReport f = s.sup.check_bus(s.fb, true);
  EXPECT_EQ(f.cause, FaultCause::kDriveFault);
  EXPECT_EQ(f.axis, 1);
  s.fb.bus.axis[1].fault = false;
  f = s.sup.check_bus(s.fb, true);
  EXPECT_EQ(f.cause, FaultCause::kHeartbeatLost);
  EXPECT_EQ(f.axis, 3) << "the heartbeat fault names the node";
  s.fb.bus.heartbeat_lost = false;
  s.fb.bus.bus_error = true;
  EXPECT_EQ(s.sup.check_bus(s.fb, true).cause, FaultCause::kBusError);
  s.fb.bus.bus_error = false;
  s.fb.bus.spindle.fault = true;
  EXPECT_EQ(s.sup.check_bus(s.fb, true).cause, FaultCause::kSpindleFault);
}

TEST(SafetySupervisor, ADriveLeavingOperationEnabledFaultsOnlyWhileServoingOnFreshFeedback) {
  Sup s;
  s.fb.bus.axis[2].enabled = false;
  EXPECT_FALSE(s.sup.check_bus(s.fb, false)) << "not servoing (ENABLING): no fault";
  const FaultReport f = s.sup.check_bus(s.fb, true);
  EXPECT_EQ(f.cause, FaultCause::kDriveDisabled);
  EXPECT_EQ(f.axis, 2);
  s.fb.bus.axis[2].fresh = false;
  EXPECT_FALSE(s.sup.check_bus(s.fb, true)) << "stale feedback does not judge the enable state";
}

TEST(SafetySupervisor, MissedTpdoStreakFaultsAtTheConfiguredLength) {
  Sup s;
  const int limit = s.cfg.safety.missed_tpdo_streak;
  s.fb.missed_streak[0] = limit - 1;
  EXPECT_FALSE(s.sup.check_bus(s.fb, true));
  s.fb.missed_streak[0] = limit;
  const FaultReport f = s.sup.check_bus(s.fb, true);
  EXPECT_EQ(f.cause, FaultCause::kMissedTpdo);
  EXPECT_EQ(f.value, limit);
  EXPECT_EQ(f.limit, limit);
}

// CiA 401 modules of the PLC (BusFeedback::io): missing TPDOs at the drives' streak, an EMCY or
// an NMT change fault the machine; the report names the node (axis field, as for a heartbeat).
TEST(SafetySupervisor, AnIoModuleFaultNamesItsNode) {
  Sup s;
  const int limit = s.cfg.safety.missed_tpdo_streak;
  s.fb.bus.io_modules = 2;
  s.fb.bus.io[0].node_id = 5;
  s.fb.bus.io[1].node_id = 9;
  s.fb.bus.io[1].missed_streak = static_cast<std::uint32_t>(limit - 1);
  EXPECT_FALSE(s.sup.check_bus(s.fb, true));
  s.fb.bus.io[1].missed_streak = static_cast<std::uint32_t>(limit);
  FaultReport f = s.sup.check_bus(s.fb, true);
  EXPECT_EQ(f.cause, FaultCause::kIoModule);
  EXPECT_EQ(f.axis, 9);
  EXPECT_EQ(f.detail, static_cast<std::uint8_t>(IoModuleFault::kTpdoMissed));
  EXPECT_EQ(f.value, limit);
  s.fb.bus.io[0].emcy_code = 0x5000;  // what a module said comes before what was inferred
  f = s.sup.check_bus(s.fb, true);
  EXPECT_EQ(f.axis, 5);
  EXPECT_EQ(f.detail, static_cast<std::uint8_t>(IoModuleFault::kEmcy));
  EXPECT_EQ(f.value, 0x5000);
  s.fb.bus.axis[0].fault = true;  // a drive fault first
  EXPECT_EQ(s.sup.check_bus(s.fb, true).cause, FaultCause::kDriveFault);
  s.fb.bus.axis[0].fault = false;
  s.fb.bus.io[0] = IoModuleFeedback{};
  s.fb.bus.io[0].node_id = 5;
  s.fb.bus.io[0].nmt_lost = true;
  const ResetBlock b = s.sup.reset_block(s.fb, false);
  EXPECT_EQ(b.cause, FaultCause::kIoModule);
  EXPECT_EQ(b.node, 5);
  EXPECT_NE(describe(b).find("node 5"), std::string::npos) << describe(b);
}

TEST(SafetySupervisor, FollowingErrorBandGrowsWithSpeedLikeLinuxCnc) {
  Sup s;
  const double mfe = s.lim.min_ferror_mm, fe = s.lim.ferror_mm;
  const Eigen::Vector3d ref(0, 0, 0);
  // At standstill the band is MIN_FERROR.
  EXPECT_FALSE(s.sup.check_motion(ref, Eigen::Vector3d(mfe * 0.99, 0, 0), Eigen::Vector3d::Zero(), 0, s.lim));
  FaultReport f = s.sup.check_motion(ref, Eigen::Vector3d(mfe * 1.01, 0, 0), Eigen::Vector3d::Zero(), 0, s.lim);
  EXPECT_EQ(f.cause, FaultCause::kFollowingError);
  EXPECT_EQ(f.axis, 0);
  EXPECT_NEAR(f.limit, mfe, 1e-12);
  // At the axis' maximum velocity it is FERROR.
  const Eigen::Vector3d vmax(0, s.lim.max_velocity_mm_s[1], 0);
  EXPECT_FALSE(s.sup.check_motion(ref, Eigen::Vector3d(0, fe * 0.99, 0), vmax, 0, s.lim));
  f = s.sup.check_motion(ref, Eigen::Vector3d(0, fe * 1.01, 0), vmax, 0, s.lim);
  EXPECT_EQ(f.axis, 1);
  EXPECT_NEAR(f.limit, fe, 1e-12);
}

TEST(SafetySupervisor, SoftLimitsOnTheReferenceAndTheContourErrorLimit) {
  Sup s;
  const auto& ax = s.cfg.machine.axes[0];
  const Eigen::Vector3d out(ax.max_mm + 0.001, 0, 0);
  FaultReport f = s.sup.check_motion(out, out, Eigen::Vector3d::Zero(), 0, s.lim);
  EXPECT_EQ(f.cause, FaultCause::kSoftLimit);
  EXPECT_EQ(f.limit, ax.max_mm);
  f = s.sup.check_motion(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                         s.lim.contour_error_limit_mm * 1.1, s.lim);
  EXPECT_EQ(f.cause, FaultCause::kContourError);
  EXPECT_EQ(f.axis, -1);
}

TEST(SafetySupervisor, SpindleWaitTimesOutAfterTheConfiguredTime) {
  Sup s;
  const auto n = static_cast<std::int64_t>(s.cfg.spindle.at_speed_timeout_s / s.cfg.machine.period_s);
  EXPECT_FALSE(s.sup.check_spindle_wait(n, 100.0, 3000.0));
  const FaultReport f = s.sup.check_spindle_wait(n + 1, 100.0, 3000.0);
  EXPECT_EQ(f.cause, FaultCause::kSpindleNotAtSpeed);
  EXPECT_EQ(f.value, 100.0);
  EXPECT_EQ(f.limit, 3000.0);
}

TEST(SafetySupervisor, StaleForceIsAFaultOnlyWhenConfiguredSo) {
  Sup s;
  EXPECT_FALSE(s.sup.check_force_stale(true, 0.5, 0.02));
  SafetySupervisor strict(s.cfg, true);
  EXPECT_EQ(strict.check_force_stale(true, 0.5, 0.02).cause, FaultCause::kForceStale);
  EXPECT_FALSE(strict.check_force_stale(false, 0.5, 0.02));
}

TEST(SafetySupervisor, ResetNeedsEveryCauseGone) {
  Sup s;
  s.fb.bus.axis[0].fault = true;
  EXPECT_FALSE(s.sup.causes_gone(s.fb, false));
  s.fb.bus.axis[0].fault = false;
  EXPECT_FALSE(s.sup.causes_gone(s.fb, true)) << "E-stop input still tripped";
  s.fb.bus.spindle.fault = true;
  EXPECT_FALSE(s.sup.causes_gone(s.fb, false));
  s.fb.bus.spindle.fault = false;
  s.fb.bus.heartbeat_lost = true;
  EXPECT_FALSE(s.sup.causes_gone(s.fb, false));
  s.fb.bus.heartbeat_lost = false;
  EXPECT_TRUE(s.sup.causes_gone(s.fb, false));
}

TEST(SafetySupervisor, EstopInputIsRaisedInTheCycleItIsSeen) {
  Sup s;
  s.fb.estop_input = true;
  EXPECT_EQ(s.sup.check_estop(s.fb).cause, FaultCause::kEstopInput);
}

TEST(SafetySupervisor, NoAllocationInTheRules) {
  Sup s;
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int n = 0; n < 1000; ++n) {
      s.fb.missed_streak[0] = n % 10;
      (void)s.sup.check_bus(s.fb, true);
      (void)s.sup.check_motion(Eigen::Vector3d::Zero(), Eigen::Vector3d(1e-3 * n, 0, 0),
                               Eigen::Vector3d::Zero(), 0.0, s.lim);
      (void)s.sup.check_spindle_wait(n, 0.0, 0.0);
      (void)s.sup.causes_gone(s.fb, false);
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
}

}  // namespace
}  // namespace contour::daemon
