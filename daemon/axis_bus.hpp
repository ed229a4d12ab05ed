#pragma once
// The daemon's view of the drives: one small interface, two implementations — SimBus (the
// in-process simulated machine, config/sim.yaml) and the CANopen bus over SocketCAN.
//
// Cycle protocol (RT thread, in this order, all noexcept and allocation-free):
//   begin_cycle()  SYNC: the drives latch the last commands and sample their encoders
//   read(fb)       feedback of this SYNC (TPDOs collected until the receive deadline)
//   write(cmd)     commands computed this cycle (RPDOs); they act from the NEXT SYNC, which is the
//                  one-cycle transport delay of CANopen synchronous PDOs.
// Units at this interface are machine units (mm, mm/s): the CANopen implementation scales counts
// at its edge.
#include <array>
#include <cstdint>
#include <string>

namespace contour::daemon {

inline constexpr int kMaxAxes = 3;

enum class DriveMode : std::uint8_t { kDisabled, kEnabled, kQuickStop };

struct AxisFeedback {
  double position_mm = 0.0;
  double velocity_mm_s = 0.0;
  bool fresh = false;          // a TPDO arrived this cycle
  bool enabled = false;        // CiA 402 "operation enabled"
  bool fault = false;          // drive fault bit
  std::uint16_t statusword = 0;
  int node_id = 0;             // CANopen node-id (0: not a CANopen drive)
  // Communication events latched by the bus until acknowledge_faults() (CANopen: the master):
  // the last EMCY error code of this drive (0: none; 0x0000 "error reset" is not latched) and
  // whether it left NMT operational (boot-up, stopped, pre-operational) while the loop cycled.
  std::uint16_t emcy_code = 0;
  bool nmt_lost = false;
};

// The spindle drive on the same bus (CANopen bus.spindle, or the simulated machine's spindle).
struct SpindleFeedback {
  bool present = false;     // this bus has a spindle with speed feedback
  bool fresh = false;       // a TPDO arrived this cycle (CAN spindles answer every n-th SYNC)
  double actual_rpm = 0.0;  // last reported speed, signed (+ = M3)
  bool enabled = false;     // CiA 402 "operation enabled"
  bool fault = false;
};

struct BusFeedback {
  std::array<AxisFeedback, kMaxAxes> axis{};
  SpindleFeedback spindle{};
  int axes = 0;
  bool heartbeat_lost = false;
  int heartbeat_lost_node = 0;
  bool bus_error = false;       // bus-off / error-passive
  std::uint32_t emcy_count = 0; // EMCY frames received so far
};

struct AxisCommands {
  std::array<double, kMaxAxes> velocity_mm_s{};
  DriveMode mode = DriveMode::kDisabled;
  double spindle_rpm = 0.0;
};

class AxisBus {
 public:
  virtual ~AxisBus() = default;
  // Non-RT start-up (configuration, NMT, enable sequencing happens per cycle). Throws
  // std::runtime_error with a message naming the node/object on failure.
  virtual void start() = 0;
  virtual void stop() noexcept = 0;

  virtual void begin_cycle() noexcept = 0;
  virtual void read(BusFeedback& fb) noexcept = 0;
  virtual void write(const AxisCommands& cmd) noexcept = 0;

  // RT, from `reset`: acknowledge faults the bus side latches (CANopen: the CiA 402 fault-reset
  // edge to drives in Fault, the master's latched heartbeat/missed-TPDO/bus faults). A cause that
  // persists shows again in the following cycles' feedback. Default: nothing latched.
  virtual void acknowledge_faults() noexcept {}

  // Sim/absolute encoders: set the current position (home/set-position). Non-RT, only while the
  // loop is not running motion. Returns false when the bus cannot do it.
  virtual bool set_position(int axis, double position_mm) = 0;
  [[nodiscard]] virtual std::string describe() const = 0;
};

}  // namespace contour::daemon
