#include "daemon/machine_state.hpp"

namespace contour::daemon {

std::string_view to_string(MachineState s) noexcept {
  switch (s) {
    case MachineState::kDisabled: return "DISABLED";
    case MachineState::kEnabling: return "ENABLING";
    case MachineState::kReady: return "READY";
    case MachineState::kRunning: return "RUNNING";
    case MachineState::kHold: return "HOLD";
    case MachineState::kFault: return "FAULT";
    case MachineState::kEstop: return "ESTOP";
  }
  return "?";
}

std::string_view to_string(FaultCause c) noexcept {
  switch (c) {
    case FaultCause::kNone: return "none";
    case FaultCause::kFollowingError: return "following error";
    case FaultCause::kContourError: return "contour error limit";
    case FaultCause::kSoftLimit: return "soft limit";
    case FaultCause::kVelocityLimit: return "velocity limit";
    case FaultCause::kDriveFault: return "drive fault";
    case FaultCause::kDriveDisabled: return "drive disabled";
    case FaultCause::kSpindleFault: return "spindle fault";
    case FaultCause::kSpindleNotAtSpeed: return "spindle not at speed";
    case FaultCause::kHeartbeatLost: return "heartbeat lost";
    case FaultCause::kMissedTpdo: return "missed TPDO streak";
    case FaultCause::kForceStale: return "force sample stale";
    case FaultCause::kForceCeiling: return "force ceiling";
    case FaultCause::kBusError: return "bus error";
    case FaultCause::kQueueUnderrun: return "segment queue underrun";
    case FaultCause::kEstopInput: return "E-stop input";
    case FaultCause::kEstopCommand: return "E-stop command";
    case FaultCause::kDriveEmcy: return "drive emergency (EMCY)";
    case FaultCause::kNmtStateChange: return "drive left NMT operational";
    case FaultCause::kStandstillTimeout: return "standstill timeout";
    case FaultCause::kLimitCycle: return "limit cycle";
    case FaultCause::kPlcEstop: return "machine logic E-stop";
    case FaultCause::kPlcFault: return "machine logic fault";
    case FaultCause::kIoModule: return "I/O module fault";
    case FaultCause::kInternal: return "internal error";
  }
  return "?";
}

std::string_view to_string(Request r) noexcept {
  switch (r) {
    case Request::kEnable: return "enable";
    case Request::kEnabled: return "enabled";
    case Request::kRun: return "run";
    case Request::kHold: return "hold";
    case Request::kResume: return "resume";
    case Request::kStop: return "stop";
    case Request::kStopped: return "stopped";
    case Request::kDone: return "done";
    case Request::kReset: return "reset";
    case Request::kDisable: return "disable";
  }
  return "?";
}

Transition StateMachine::go(MachineState to) noexcept {
  Transition t{true, state_, to};
  if (state_ != to) ++transitions_;
  state_ = to;
  return t;
}

Transition StateMachine::apply(Request r) noexcept {
  using S = MachineState;
  const Transition refused{false, state_, state_};
  switch (r) {
    case Request::kEnable:
      return state_ == S::kDisabled ? go(S::kEnabling) : refused;
    case Request::kEnabled:
      return state_ == S::kEnabling ? go(S::kReady) : refused;
    case Request::kRun:
      return state_ == S::kReady ? go(S::kRunning) : refused;
    case Request::kHold:
      return state_ == S::kRunning ? go(S::kHold) : refused;
    case Request::kResume:
      return state_ == S::kHold ? go(S::kRunning) : refused;
    case Request::kStop:  // decelerate and flush; READY once stopped (kStopped)
      return (state_ == S::kRunning || state_ == S::kHold) ? go(S::kHold) : refused;
    case Request::kStopped:
    case Request::kDone:
      return (state_ == S::kRunning || state_ == S::kHold) ? go(S::kReady) : refused;
    case Request::kReset:
      return refused;  // use reset(cause_gone)
    case Request::kDisable:
      return (state_ == S::kReady || state_ == S::kEnabling) ? go(S::kDisabled) : refused;
  }
  return refused;
}

Transition StateMachine::fault(FaultCause c) noexcept {
  if (state_ == MachineState::kEstop) return {false, state_, state_};
  if (state_ == MachineState::kFault) return {false, state_, state_};  // first cause latched
  cause_ = c;
  return go(MachineState::kFault);
}

Transition StateMachine::estop(FaultCause c) noexcept {
  if (state_ == MachineState::kEstop) return {false, state_, state_};
  cause_ = c;
  return go(MachineState::kEstop);
}

Transition StateMachine::reset(bool cause_gone) noexcept {
  if ((state_ != MachineState::kFault && state_ != MachineState::kEstop) || !cause_gone) {
    return {false, state_, state_};
  }
  cause_ = FaultCause::kNone;
  return go(MachineState::kDisabled);
}

}  // namespace contour::daemon
