#pragma once
// AxisBus over the CANopen master (drivers/canopen::Master) on SocketCAN: contourd driving real
// or vcan CiA 402 drives (`bus.type: socketcan`).
//
// Axis i of the bus is machine.axes[i] (every axis needs a node_id); the spindle node, when
// configured (bus.spindle), follows the axes. Scaling happens here, at the one edge:
//   position_mm   = unwrapped 0x6064 counts / counts_per_mm
//   velocity_mm_s = 0x606C counts/s / counts_per_mm when mapped in the TPDO, else the
//                   difference of the last two position readings over their time apart
//                   (codec.hpp counts_velocity_mm_s; the default TPDO {0x6041, 0x6064} has no
//                   room for 0x606C in 8 bytes). ServoLoop's acceleration clamp uses it.
//   0x60FF target = round(velocity_mm_s * counts_per_mm) counts/s (integer: the drive's unit)
//   spindle 0x60FF = round(spindle_rpm) (the simulated spindle drive's unit is rpm)
//   CSP axes: 0x607A = the integral of the velocity commands, from the actual position at enable
//   (the offline model, SimBus, models CSV drives only)
//   digital I/O (axes a plc.signals cia402 binding names; daemon/PLC.md "Drive I/O"): 0x60FD
//   from TPDO2 -> AxisFeedback::digital_inputs (present, fresh when TPDO2 came this cycle);
//   AxisCommands::digital_outputs & mask -> 0x60FE:01 in RPDO2; 0 on stop()
//   encoder index latch (axes homed on a switch with home.use_index: the drive's touch probe 1,
//   NodeSetup::touch_probe): AxisCommands::index_arm -> 0x60B8 = 0x0015 (touch probe 1 on,
//   first event, trigger = the encoder's zero impulse, positive edge), false -> 0x0000. An arm
//   is an edge at the drive: it is sent only once a 0x60B9 received after the disarm shows touch
//   probe 1 off (bit 0 clear: the drive has seen the 0, and bit 1 of an earlier arm is gone), so
//   0x60B9 bits 0 + 1 received after that are this arm's latch: AxisFeedback::index_latched, and
//   index_position_mm = 0x60BA of the same TPDO, unwrapped against this cycle's 0x6064 (the
//   32-bit difference added to the unwrapped position) / counts_per_mm: the coordinates of
//   position_mm exactly. index_present for exactly these axes. 0x60B8 = 0 on stop().
//   CiA 401 I/O modules (nodes plc.signals cia401 bindings name; daemon/PLC.md "CAN I/O
//   modules"): their TPDOs -> BusFeedback::io (0x6000:xx, 0x6401:xx), AxisCommands::io ->
//   their RPDOs (0x6200:xx, 0x6411:xx), matched by node-id; 0 on stop()
// DriveMode -> CiA 402 request for every axis node (the master's sequencer walks the power state
// machine one controlword per cycle): kEnabled -> enable operation, kDisabled -> disable
// voltage, kQuickStop -> quick stop. A change from not-enabled to kEnabled sends the fault-reset
// edge (Master::reset_faults) so an operator reset can clear a drive fault.
//
// Threads:
//  - start()/stop(), describe(), set_position(): non-RT (start() blocks on SDO, may throw).
//  - begin_cycle()/read()/write(): the RT cycle, noexcept, allocation-free, lock-free, no log.
//    begin_cycle = SYNC (+ master heartbeat); read = collect TPDOs until all are in or the
//    deadline; write = RPDOs. Budget: ~5 us per frame sent plus the TPDO wait.
//  - Homing by the drive (AxisCommands::drive_home, home.method drive; drivers/README.md
//    "Homing by the drive"): a per-axis state machine stepped in write(), every SDO through the
//    master's non-blocking expedited client (one request frame per step, the answer consumed by
//    the next cycles' receive path): 0x6098, 0x6099:01/02, 0x609A, 0x6060 = 6, 0x6061 read back;
//    the rising edge of controlword bit 4; statusword bits 12 + 10 (attained) or 13 (error) from
//    the TPDO; 0x6060 = the cyclic mode, 0x6061 read back; then kAttained. An abort on any of
//    them is kUnsupported naming the object. While the drive homes its position step at the home
//    point is not a velocity: the difference velocity holds its last value across a step larger
//    than 2 x max_velocity x period (the unwrapper sees a step, not a wrap: < 2^31 counts).
//  - Master events (EMCY with code and text, drive fault, heartbeat loss, missed-TPDO streak,
//    unexpected boot-up, bus state) are moved by read() from the master's ring into an SPSC ring
//    of fixed-size records; an event thread started by start() drains it every 20 ms, turns each
//    into text (Master::describe) and passes it to the BusLog given at construction (the daemon
//    logs it). drain_events() does the same on the caller's thread (tests).
//
// Time: with `bus.lockstep: true` (simulated drives in lockstep, contour-machine-sim) the
// master waits up to Config::kLockstepTpdoWaitMs for every TPDO and heartbeat time is the cycle
// count times the period, so a cycle that wakes late cannot change any number (the drives only
// advance on SYNC). Otherwise the TPDO deadline is loop.tpdo_deadline_us after the SYNC and
// heartbeat time is CLOCK_MONOTONIC.
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "config/config.hpp"
#include "daemon/axis_bus.hpp"
#include "daemon/spsc_ring.hpp"
#include "drivers/can/can_bus.hpp"
#include "drivers/canopen/master.hpp"

namespace contour::daemon {

class CanopenBus final : public AxisBus {
 public:
  using Log = std::function<void(const std::string&)>;

  // Validates the config (throws std::runtime_error naming the key): 1..3 axes, each with a
  // node_id and counts_per_mm > 0. Opens nothing yet.
  CanopenBus(const config::Config& cfg, Log log);
  // Tests: run over an injected CanBus (a scripted fake) instead of opening SocketCAN.
  CanopenBus(const config::Config& cfg, drivers::CanBus& can, Log log);
  ~CanopenBus() override;
  CanopenBus(const CanopenBus&) = delete;
  CanopenBus& operator=(const CanopenBus&) = delete;

  // Opens the interface (std::runtime_error "bus.interface vcan9: SIOCGIFINDEX: No such
  // device" / "... interface is down"), then Master::start_up() (NMT reset, boot-up wait, SDO
  // configuration, PDO mapping, NMT start; errors name node, object and abort text). Starts the
  // event thread.
  void start() override;
  // Brings every drive to switch-on-disabled (a few cycles of controlwords, quick stop first if
  // still enabled), puts the nodes into NMT pre-operational (PDOs stop), stops the event thread
  // after a last drain. Call only when the RT loop no longer runs.
  void stop() noexcept override;

  void begin_cycle() noexcept override;
  void read(BusFeedback& fb) noexcept override;
  void write(const AxisCommands& cmd) noexcept override;

  // Positions come from the drives' encoders: not settable over this bus (returns false).
  bool set_position(int axis, double position_mm) override;
  // Operator reset: fault-reset edge to drives in Fault, master latches cleared (RT-safe).
  void acknowledge_faults() noexcept override {
    if (master_) master_->reset_faults();
  }
  [[nodiscard]] std::string describe() const override;

  // Non-RT: describes and passes every pending master event to `sink`; returns how many.
  // Safe beside the RT thread (SPSC consumer side) and beside the event thread (the consumers
  // share a mutex; the RT producer never touches it).
  std::size_t drain_events(const Log& sink);
  void set_event_thread(bool on) { event_thread_wanted_ = on; }  // before start(); default on

  // Non-RT, tests and status: the master (nullptr before start()).
  [[nodiscard]] const drivers::canopen::Master* master() const { return master_.get(); }
  drivers::canopen::Master* master() { return master_.get(); }

 private:
  void init(const config::Config& cfg);
  void step_drive_homing(std::size_t a, bool request) noexcept;

  // Homing by the drive (see the header comment): the SDO writes of the set-up, per axis.
  enum class HomeStep : std::uint8_t {
    kIdle, kSetup, kStartEdge, kRunning, kModeBack, kAttained, kError, kUnsupported,
  };
  struct HomeObject {
    std::uint16_t index = 0;
    std::uint8_t sub = 0;
    std::uint32_t value = 0;
    std::uint8_t bytes = 0;  // 0: an upload of 0x6061 that must read `value`
  };
  static constexpr std::size_t kHomeSetupObjects = 6;
  struct HomeSeq {
    bool configured = false;  // machine.axes[].home.method drive
    std::array<HomeObject, kHomeSetupObjects> setup{};
    std::array<HomeObject, 2> back{};  // 0x6060 = cyclic mode, 0x6061 read back
    HomeStep step = HomeStep::kIdle;
    std::size_t k = 0;           // the object in flight (setup or back)
    bool sent = false;           // its SDO request is out
    bool mode6 = false;          // 0x6060 = 6 was written: the way out writes the cyclic mode
    HomeStep result = HomeStep::kIdle;  // kModeBack: what follows (kAttained/kError/kIdle)
    int wait = 0;
    std::uint32_t detail = 0;
  };
  std::array<HomeSeq, kMaxAxes> home_{};
  // The encoder index latch (touch probe 1) of an axis, see the header comment.
  enum class ProbeStep : std::uint8_t { kOff, kArmed, kLatched };
  struct ProbeSeq {
    bool mapped = false;    // NodeSetup::touch_probe
    ProbeStep step = ProbeStep::kOff;
    bool off_seen = false;  // kOff: a 0x60B9 with bit 0 clear came since the disarm was sent
    std::int64_t latched_counts = 0;  // kLatched: 0x60BA, unwrapped
  };
  std::array<ProbeSeq, kMaxAxes> probe_{};
  std::array<double, kMaxAxes> max_step_counts_{};  // position step that is a reset, not motion
  void run_cycles_for_stop() noexcept;

  Log log_;
  drivers::canopen::MasterConfig mcfg_;
  std::string ifname_;
  bool lockstep_ = false;
  int axes_ = 0;
  int spindle_index_ = -1;  // node index of the spindle in the master, or -1
  // CiA 401 I/O modules (the PLC's cia401 bindings): their node indices in the master.
  std::array<int, kMaxIoModules> io_index_{};
  int io_count_ = 0;
  bool spindle_velocity_mapped_ = false;  // 0x606C in the spindle's TPDO: speed feedback
  std::array<double, kMaxAxes> counts_per_mm_{};
  std::array<bool, kMaxAxes> velocity_mapped_{};  // 0x606C in the axis' TPDO
  // CSP axes (bus mode csp): the velocity commands are integrated into a position target
  // (counts, kept as a double so sub-count steps accumulate), restarted from the actual position
  // whenever the drive is not in operation enabled (no jump at enable).
  std::array<bool, kMaxAxes> csp_{};
  std::array<double, kMaxAxes> csp_target_counts_{};
  double period_s_ = 0.001;
  // Velocity estimate from positions: last fresh reading and the cycle it came in.
  std::array<std::int64_t, kMaxAxes> last_counts_{};
  std::array<std::uint64_t, kMaxAxes> last_fresh_cycle_{};
  std::array<std::int64_t, kMaxAxes> last_fresh_ns_{};
  std::int64_t sync_ns_ = 0;  // time of this cycle's SYNC (see Time above)
  std::array<bool, kMaxAxes> have_last_{};
  std::int64_t period_ns_ = 1000000;

  std::unique_ptr<drivers::CanBus> owned_can_;
  drivers::CanBus* can_ = nullptr;
  std::unique_ptr<drivers::canopen::Master> master_;

  // RT state
  std::uint64_t cycle_ = 0;
  DriveMode last_mode_ = DriveMode::kDisabled;
  bool begin_fault_ = false;

  SpscRing<drivers::canopen::MasterEvent> events_{256};
  std::atomic<bool> stop_events_{false};
  bool event_thread_wanted_ = true;
  std::mutex drain_mutex_;
  std::thread event_thread_;
  bool started_ = false;
};

}  // namespace contour::daemon
