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
#include <cstddef>
#include <cstdint>
#include <string>

namespace contour::daemon {

inline constexpr int kMaxAxes = 3;
// CiA 401 I/O modules on the bus (the PLC's cia401 bindings) and channels per object.
inline constexpr std::size_t kMaxIoModules = 8;
inline constexpr std::size_t kIoModuleChannels = 8;

enum class DriveMode : std::uint8_t { kDisabled, kEnabled, kQuickStop };

// Homing by the drive (CiA 402 homing mode 6, home.method drive), as the bus reports it per axis.
enum class DriveHoming : std::uint8_t {
  kIdle,         // not requested (or the request dropped and the drive is back in cyclic mode)
  kRunning,      // requested: the bus sets the drive up and the drive moves on its own
  kAttained,     // done (statusword bits 12 + 10): the drive stands, is back in the cyclic mode
                 // and its position 0 is the home point it found; holds while still requested
  kError,        // the drive reported a homing error (statusword bit 13); holds while requested
  kUnsupported,  // the drive refused the homing objects (SDO abort): detail = object
};
const char* to_string(DriveHoming h) noexcept;

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
  // CiA 402 digital inputs 0x60FD (bit 0 negative limit, 1 positive limit, 2 home switch,
  // 3 interlock, 16..31 manufacturer). `digital_inputs_present`: this bus maps them for this
  // axis (CANopen: only drives a plc.signals cia402 binding names, in TPDO2). `digital_inputs_fresh`:
  // the value arrived with this cycle's feedback; otherwise `digital_inputs` is the last one
  // received (0 before the first) and the consumer judges its age (ServoLoop: at most
  // safety.missed_tpdo_streak - 1 cycles, like the position).
  bool digital_inputs_present = false;
  bool digital_inputs_fresh = false;
  std::uint32_t digital_inputs = 0;
  // Encoder index latch (homing with home.use_index, LinuxCNC's index-enable): `index_present`:
  // this bus can latch the index of this axis' encoder. While AxisCommands::index_arm is set the
  // drive watches for the next index pulse; `index_latched` then says it came and
  // `index_position_mm` is the encoder position at the pulse (the bus' position coordinates,
  // exact to the count: the drive latches it, not the cycle's sample). Disarming clears it.
  bool index_present = false;
  bool index_latched = false;
  double index_position_mm = 0.0;
  // Homing by the drive (AxisCommands::drive_home): `drive_homing_present`: this bus can ask the
  // drive of this axis to home itself; `drive_homing`: where that stands. While it runs, the drive
  // moves on its own (the velocity command is ignored) and position_mm follows it; at kAttained
  // the drive's position reads 0 at its home point. `drive_homing_detail`: kUnsupported: the
  // object refused, index << 8 | sub-index (e.g. 0x609800); kError: the statusword.
  bool drive_homing_present = false;
  DriveHoming drive_homing = DriveHoming::kIdle;
  std::uint32_t drive_homing_detail = 0;
};

// The spindle drive on the same bus (CANopen bus.spindle, or the simulated machine's spindle).
struct SpindleFeedback {
  bool present = false;     // this bus has a spindle with speed feedback
  bool fresh = false;       // a TPDO arrived this cycle (CAN spindles answer every n-th SYNC)
  double actual_rpm = 0.0;  // last reported speed, signed (+ = M3)
  bool enabled = false;     // CiA 402 "operation enabled"
  bool fault = false;
};

// A CiA 401 I/O module as this cycle's read saw it (CANopen: nodes the PLC's cia401 bindings
// name; other buses have none). `fresh`: every TPDO the module maps arrived this cycle (a module
// that maps no input is always fresh: only its heartbeat watches it). `missed_streak`: cycles in
// a row without them (the master's count, cleared by acknowledge_faults()). `emcy_code` (0:
// none) and `nmt_lost` are latched like a drive's. The values are the last received.
struct IoModuleFeedback {
  int node_id = 0;
  bool fresh = false;
  std::uint32_t missed_streak = 0;
  std::uint16_t emcy_code = 0;
  bool nmt_lost = false;
  std::array<std::uint8_t, kIoModuleChannels> digital{};  // 0x6000:01..08
  std::array<std::int16_t, kIoModuleChannels> analog{};   // 0x6401:01..08
};
// Its outputs for this cycle's write (0x6200:01..08, 0x6411:01..08); node_id 0: unused slot.
struct IoModuleCommands {
  int node_id = 0;
  std::array<std::uint8_t, kIoModuleChannels> digital{};
  std::array<std::int16_t, kIoModuleChannels> analog{};
};

struct BusFeedback {
  std::array<AxisFeedback, kMaxAxes> axis{};
  SpindleFeedback spindle{};
  int axes = 0;
  bool heartbeat_lost = false;
  int heartbeat_lost_node = 0;
  bool bus_error = false;       // bus-off / error-passive
  std::uint32_t emcy_count = 0; // EMCY frames received so far
  std::array<IoModuleFeedback, kMaxIoModules> io{};
  int io_modules = 0;
};

struct AxisCommands {
  std::array<double, kMaxAxes> velocity_mm_s{};
  DriveMode mode = DriveMode::kDisabled;
  double spindle_rpm = 0.0;
  // CiA 402 digital outputs 0x60FE:01 per axis: the bits in `digital_output_mask` are driven to
  // their value in `digital_outputs` (others 0). CANopen: RPDO2 of drives with a cia402 output
  // binding (0x60FE:02, the drive's enable mask, is written once at start-up); ignored for
  // axes that map no outputs.
  std::array<std::uint32_t, kMaxAxes> digital_outputs{};
  std::array<std::uint32_t, kMaxAxes> digital_output_mask{};
  // Arm the encoder index latch of the axis (AxisFeedback::index_latched); false disarms it.
  std::array<bool, kMaxAxes> index_arm{};
  // Home the axis by its drive (CiA 402 mode 6 with the axis' home.drive_method, speeds and
  // acceleration, given to the bus at construction): the rising edge starts it, holding it keeps
  // the result (AxisFeedback::drive_homing), false returns the drive to the cyclic mode (an
  // unfinished homing is abandoned: the drive stops under the velocity command).
  std::array<bool, kMaxAxes> drive_home{};
  // CiA 401 module outputs (the PLC's cia401 output bindings), matched by node_id.
  std::array<IoModuleCommands, kMaxIoModules> io{};
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
