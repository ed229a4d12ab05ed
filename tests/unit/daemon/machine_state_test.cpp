#include "daemon/machine_state.hpp"

#include <gtest/gtest.h>

using namespace contour::daemon;

TEST(StateMachine, NormalCycle) {
  StateMachine m;
  EXPECT_EQ(m.state(), MachineState::kDisabled);
  EXPECT_FALSE(m.apply(Request::kRun).accepted) << "run while disabled must be refused";
  EXPECT_TRUE(m.apply(Request::kEnable).accepted);
  EXPECT_TRUE(m.apply(Request::kEnabled).accepted);
  EXPECT_EQ(m.state(), MachineState::kReady);
  EXPECT_TRUE(m.apply(Request::kRun).accepted);
  EXPECT_TRUE(m.apply(Request::kHold).accepted);
  EXPECT_EQ(m.state(), MachineState::kHold);
  EXPECT_FALSE(m.apply(Request::kHold).accepted);
  EXPECT_TRUE(m.apply(Request::kResume).accepted);
  EXPECT_TRUE(m.apply(Request::kDone).accepted);
  EXPECT_EQ(m.state(), MachineState::kReady);
}

TEST(StateMachine, FaultLatchesFirstCauseAndResetNeedsCauseGone) {
  StateMachine m;
  m.apply(Request::kEnable);
  m.apply(Request::kEnabled);
  m.apply(Request::kRun);
  EXPECT_TRUE(m.fault(FaultCause::kFollowingError).accepted);
  EXPECT_FALSE(m.fault(FaultCause::kSoftLimit).accepted);
  EXPECT_EQ(m.cause(), FaultCause::kFollowingError);
  EXPECT_FALSE(m.apply(Request::kRun).accepted);
  EXPECT_FALSE(m.reset(false).accepted);
  EXPECT_EQ(m.state(), MachineState::kFault);
  EXPECT_TRUE(m.reset(true).accepted);
  EXPECT_EQ(m.state(), MachineState::kDisabled);
  EXPECT_EQ(m.cause(), FaultCause::kNone);
}

TEST(StateMachine, EstopOverridesFault) {
  StateMachine m;
  m.fault(FaultCause::kDriveFault);
  EXPECT_TRUE(m.estop(FaultCause::kEstopInput).accepted);
  EXPECT_EQ(m.state(), MachineState::kEstop);
  EXPECT_EQ(m.cause(), FaultCause::kEstopInput);
  EXPECT_FALSE(m.fault(FaultCause::kDriveFault).accepted);
  EXPECT_EQ(to_string(m.state()), "ESTOP");
}
