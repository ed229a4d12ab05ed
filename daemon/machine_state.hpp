#pragma once
// Machine state machine (architecture.md "States"):
//   DISABLED -> ENABLING -> READY -> RUNNING <-> HOLD -> READY, any -> FAULT, any -> ESTOP.
// FAULT: controlled stop at the configured deceleration, drives to quick stop / disabled.
// ESTOP: immediate quick stop, drive-enable output off. `reset` leaves FAULT/ESTOP only when the
// cause is gone (the caller says so), and goes to DISABLED (drives must be re-enabled).
// Pure logic, noexcept, no allocation: the RT thread owns the instance; other threads post
// requests through the command mailbox and read the published state.
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace contour::daemon {

enum class MachineState : std::uint8_t { kDisabled, kEnabling, kReady, kRunning, kHold, kFault, kEstop };

enum class FaultCause : std::uint8_t {
  kNone,
  kFollowingError,
  kContourError,
  kSoftLimit,
  kVelocityLimit,
  kDriveFault,
  kDriveDisabled,  // left operation enabled without a fault bit
  kSpindleFault,
  kSpindleNotAtSpeed,
  kHeartbeatLost,
  kMissedTpdo,
  kForceStale,
  kForceCeiling,
  kBusError,
  kQueueUnderrun,
  kEstopInput,
  kEstopCommand,
  kDriveEmcy,          // the drive sent an emergency message (EMCY) with an error code
  kNmtStateChange,     // the drive left NMT operational (boot-up, stopped, pre-operational)
  kStandstillTimeout,  // after a stop an axis still moved: the drives got the quick stop
  kLimitCycle,         // command chatter / clamp rate over the limit-cycle watchdog's fault level
  kPlcEstop,           // the machine logic requested an E-stop (issue 20)
  kPlcFault,           // the machine logic requested a fault, or its engine latched one (I/O
                       // stale, M-code / tool-change timeout, scan error)
  kIoModule,           // a CiA 401 I/O module of the PLC: TPDOs missing, EMCY, or it left NMT
                       // operational (FaultReport::axis: the node-id; detail: IoModuleFault)
  kInternal,
};
inline constexpr std::size_t kFaultCauseCount = static_cast<std::size_t>(FaultCause::kInternal) + 1;

enum class Request : std::uint8_t { kEnable, kEnabled, kRun, kHold, kResume, kStop, kStopped, kDone,
                                    kReset, kDisable };

std::string_view to_string(MachineState s) noexcept;
std::string_view to_string(FaultCause c) noexcept;
std::string_view to_string(Request r) noexcept;

// Result of applying a request: whether it was legal and the new state.
struct Transition {
  bool accepted = false;
  MachineState from = MachineState::kDisabled;
  MachineState to = MachineState::kDisabled;
};

class StateMachine {
 public:
  [[nodiscard]] MachineState state() const noexcept { return state_; }
  [[nodiscard]] FaultCause cause() const noexcept { return cause_; }
  [[nodiscard]] std::uint32_t transitions() const noexcept { return transitions_; }

  // A request from a command or from the loop itself. Illegal requests change nothing.
  Transition apply(Request r) noexcept;
  // Faults latch the first cause; an E-stop overrides a fault (and latches its own cause).
  Transition fault(FaultCause c) noexcept;
  Transition estop(FaultCause c) noexcept;
  // Leaves FAULT/ESTOP for DISABLED when cause_gone; otherwise refused.
  Transition reset(bool cause_gone) noexcept;

  // True in states where the drives may move the axes under program control.
  [[nodiscard]] bool motion_allowed() const noexcept {
    return state_ == MachineState::kReady || state_ == MachineState::kRunning ||
           state_ == MachineState::kHold;
  }

 private:
  Transition go(MachineState to) noexcept;
  MachineState state_ = MachineState::kDisabled;
  FaultCause cause_ = FaultCause::kNone;
  std::uint32_t transitions_ = 0;
};

}  // namespace contour::daemon
