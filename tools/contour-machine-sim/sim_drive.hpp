#pragma once
// One simulated CiA 402 drive node for contour-machine-sim: object dictionary + SDO server,
// NMT slave, heartbeat producer, PDO mapping as configured by the master, CiA 402 power state
// machine with quick stop and fault reset, and the plant: control::FeedDrive (the ONE plant
// model) for an axis, a first-order speed lag for the spindle.
//
// Heartbeat consumer: when the master's heartbeat (0x1016:1) stops for its consumer time the
// drive sends EMCY 0x8130 (life guard / heartbeat error), reacts per 0x6007 abort connection
// option code (default 1: fault; 2: disable voltage; 3: quick stop; 0: none) and per 0x1029:1
// error behaviour (default 0: operational -> pre-operational, PDOs stop; 1: no change;
// 2: stopped). The plant keeps stepping on SYNC in pre-operational (physics does not pause).
//
// Lockstep: the plant advances exactly one period per SYNC received. At SYNC n the drive first
// samples and sends its TPDO (statusword, position of step n), then applies the RPDO latched
// since SYNC n-1 and steps the plant. The CAN transport therefore contributes one period of
// command delay; the FeedDrive inside gets (configured delay_cycles - 1) so that the whole loop
// has the configured delay, as contour-sim's in-process drive does. With
// SimQuirks::tpdo_after_step the order is reversed (apply, step, then sample and send): the
// feedback carries the step of this SYNC, the transport adds no period, and contour-machine-sim
// gives the FeedDrive the full delay_cycles.
//
// Homing mode 6 (0x6060 = 6, started by the rising edge of controlword bit 4): methods 17/18
// (limit switch), 19..22 (home switch), 35/37 (current position) on the switches below; statusword
// bits 10/12/13 as CiA 402 defines them for homing. A drive without homing support:
// --missing-object NODE:0x6098 (the master's write of 0x6098 is then aborted 0x06020000).
//
// Touch probe 1 (0x60B8 function, 0x60B9 status, 0x60BA positive-edge position, PDO-mappable;
// the master's encoder index latch for home.use_index): the axis' motor encoder has an index,
// one pulse per SimDriveSetup::index_pitch_mm of true travel at index_phase_mm + k x pitch
// (none while the pitch is 0). 0x60B8 is applied at SYNC with the RPDO (an SDO write at the next
// SYNC): bit 0 on sets 0x60B9 bit 0, off clears 0x60B9; bit 4 (positive edge) going 0 -> 1, or
// bit 0 going 0 -> 1 with bit 4 set, arms the latch and clears 0x60B9 bit 1; bit 4 off disarms
// and clears bit 1. Armed with trigger source 01 (bits 2..3: the encoder's zero impulse), the
// first pulse the plant crosses in a step (up: x0 < pulse <= x1; down: x1 <= pulse < x0; the
// plant moves monotonically within a step, so that is where the crossing is) is latched at its
// own position: 0x60BA = round(pulse x counts_per_mm) - the homing zero, i.e. quantised exactly
// as 0x6064 would read there, and 0x60B9 bit 1 set; first event (bit 1 = 0) disarms, continuous
// (bit 1 = 1) latches each pulse. Trigger source 00 (a touch probe input) has no input here:
// it never latches. A drive without the objects: --no-touch-probe NODE.
//
// Quirks (SimQuirks, contour-machine-sim --missing-object/--pdos/--expedited-only/
// --tpdo-sampling/--no-touch-probe): drives that are not a complete CiA 301/402 drive. A missing 0x605A/0x6085
// means the built-in quick stop (option 2, 1000000 counts/s^2).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "control/feed_drive.hpp"
#include "drivers/can/can_bus.hpp"
#include "drivers/canopen/codec.hpp"

namespace contour::sim {

struct SimFaults {
  long drop_tpdo_from = -1;   // SYNC count (since NMT start) from which TPDOs are dropped
  long drop_tpdo_count = 0;   // 0 = forever
  // The same for the node's TPDO2..4 only (0x60FD digital inputs, touch probe): TPDO1, the
  // position, still comes. Not counted in tpdo_dropped (the master's missed_total is TPDO1's).
  long drop_tpdo2_from = -1;
  long drop_tpdo2_count = 0;
  long fault_at = -1;         // raise a drive fault (EMCY + statusword) at this SYNC count
  std::uint16_t fault_code = 0x2310;
  // Raise the fault this many SYNCs after the first SYNC at which the drive, in operation
  // enabled, applies a non-zero target (motion start): "mid-run" independently of how long the
  // master idled before the program started.
  long fault_after_motion = -1;
  long stop_heartbeat_at = -1;
  std::optional<std::uint32_t> sdo_abort_object;  // index << 8 | sub
  std::uint32_t sdo_abort_code = 0x06090030;
  long malformed_at = -1;  // send a burst of malformed frames at this SYNC count
  long drop_sdo_requests = 0;  // ignore this many SDO requests (initiate frames) from power-on
};

struct SimQuirks {
  struct Object {
    std::uint16_t index = 0;
    int sub = -1;  // -1: every sub-index
  };
  std::vector<Object> missing;  // objects removed from the object dictionary
  int pdos = 4;                 // RPDOs and TPDOs the drive has (1..4)
  int pdo_max_entries = 8;      // mapping entries per PDO (1..8)
  bool expedited_only = false;  // SDO server: segmented transfers are aborted (0x05040001)
  bool tpdo_after_step = false;  // TPDO sampled after the step (see the header comment)
  // Master-heartbeat consumer (0x1016) timed on the drive's own wall clock, as a real drive does,
  // instead of in SYNCs (lockstep, the default: results independent of scheduling).
  bool wall_clock_consumer = false;
};

// A switch on the axis (a cam on the carriage): bit `bit` of 0x60FD is on while the plant's
// position is above `threshold_mm` (on_above) or below it. Defaults (main.cpp): negative_limit
// (bit 0) below machine.axes[].min_mm - 2 mm, positive_limit (1) above max_mm + 2 mm, home_switch
// (2) below min_mm + 0.5 mm, as the in-process SimBus; --input-switch adds more.
struct InputSwitch {
  int bit = 0;
  double threshold_mm = 0.0;
  bool on_above = true;
};

// A CiA 401 generic I/O module instead of a drive (contour-machine-sim --io-module): 0x1000
// device type 401 (+ bits 16..19 for the kinds of I/O present), `digital_inputs` bytes of 0x6000,
// `digital_outputs` of 0x6200, `analog_inputs` INTEGER16 of 0x6401, `analog_outputs` of 0x6411
// (0..8 each), PDO-mappable as the master configures them; no CiA 402 objects, no plant. Each
// SYNC (operational): the outputs are looped to the inputs (0x6000:k = 0x6200:k, 0x6401:k =
// 0x6411:k for the sub-indices both have) unless `fixed_inputs` pins 0x6000:k, then the TPDOs
// are sampled and sent (--drop-tpdo and the heartbeat faults act as on a drive). RPDO values are
// stored at once (the next SYNC samples them).
struct SimIoModule {
  bool enabled = false;
  int digital_inputs = 2, digital_outputs = 2, analog_inputs = 2, analog_outputs = 2;
  std::vector<std::pair<int, int>> fixed_inputs;  // {sub-index of 0x6000, byte value}
};

struct SimDriveSetup {
  std::uint8_t node_id = 1;
  std::string name = "X";
  bool spindle = false;
  double counts_per_mm = 2000.0;       // axis scaling (spindle: counts per revolution)
  control::FeedDriveParams plant{};   // axis plant (delay already reduced by the CAN period)
  double spindle_tau_s = 0.2;
  double period_s = 0.001;
  std::uint32_t vendor_id = 0x00000C7D;
  std::uint32_t product_code = 402;
  std::uint32_t revision = 0x00010000;
  std::uint32_t serial = 0;
  SimFaults faults;
  SimQuirks quirks;
  std::vector<InputSwitch> switches;  // 0x60FD, sampled with the TPDOs
  // The motor encoder's index (touch probe 1, see the header comment): one pulse per
  // index_pitch_mm of true travel (0: none) at index_phase_mm + k x pitch.
  double index_pitch_mm = 0.0;
  double index_phase_mm = 0.0;
  SimIoModule io;                     // io.enabled: a CiA 401 module, not a drive
};

class SimDrive {
 public:
  using Send = std::function<void(const drivers::CanFrame&)>;
  SimDrive(SimDriveSetup setup, Send send);

  void power_on();  // sends the boot-up, enters pre-operational
  void on_frame(const drivers::CanFrame& f);
  // Wall-clock tick for the heartbeat producer outside lockstep (pre-operational, or no SYNC).
  // The wall-clock time of the frames about to be handled (on_frame stamps SYNC and the master's
  // heartbeat with it). Set before each queued frame; tick_wall runs the wall-clock checks only
  // after the queue is drained, so frames that waited while this process was descheduled count
  // as received, not as silence.
  void set_wall(std::int64_t now_ns) { now_wall_ns_ = now_ns; }
  void tick_wall(std::int64_t now_ns);

  [[nodiscard]] std::uint8_t node_id() const { return s_.node_id; }
  [[nodiscard]] drivers::canopen::Cia402State state() const { return state_; }
  [[nodiscard]] drivers::canopen::NmtState nmt() const { return nmt_; }
  [[nodiscard]] double position_mm() const { return plant_.position_mm(); }
  [[nodiscard]] double velocity_mm_s() const { return plant_.velocity_mm_s(); }
  [[nodiscard]] double spindle_rpm() const { return spindle_rpm_; }
  [[nodiscard]] bool is_spindle() const { return s_.spindle; }
  [[nodiscard]] bool is_io_module() const { return s_.io.enabled; }
  // CiA 401 module: sub-indices 1..n of `index` (0x6000, 0x6200, 0x6401, 0x6411) as they are now.
  [[nodiscard]] std::vector<std::int64_t> io_values(std::uint16_t index) const;
  [[nodiscard]] long syncs() const { return syncs_; }
  // 0x60FD as last sampled; 0x60FE:01 as last written (RPDO2 at SYNC, or SDO).
  [[nodiscard]] std::uint32_t digital_inputs() const { return u32(0x60FD, 0); }
  [[nodiscard]] std::uint32_t digital_outputs() const { return u32(0x60FE, 1); }
  // Touch probe 1: 0x60B8 as last applied, 0x60B9, 0x60BA as they are now; the pulses latched
  // so far and the true position (mm) of the last one.
  [[nodiscard]] std::uint16_t touch_probe_function() const { return tp_fn_; }
  [[nodiscard]] std::uint16_t touch_probe_status() const {
    return static_cast<std::uint16_t>(read_int(0x60B9, 0) & 0xFFFF);
  }
  [[nodiscard]] std::int32_t touch_probe_position_counts() const {
    return static_cast<std::int32_t>(read_int(0x60BA, 0));
  }
  [[nodiscard]] long index_latches() const { return tp_latches_; }
  [[nodiscard]] double last_index_mm() const { return tp_last_index_mm_; }

  // Re-armable fault injection (contour-machine-sim --storm, storm.hpp). Each call is one event
  // and may be repeated any time after the previous one; all act on SYNC (lockstep).
  // Withhold the next `count` TPDOs this node would transmit (counted in TPDOs, not SYNCs).
  void drop_tpdos(long count) { storm_drop_left_ += std::max(0L, count); }
  // Raise a drive fault (statusword Fault reaction active -> Fault, EMCY `code`) at the next
  // SYNC, where --fault raises its one-shot fault. Ignored if the drive is in Fault by then.
  // The operator's fault reset (controlword bit 7 edge) clears it as any other fault.
  void inject_fault(std::uint16_t code) { injected_fault_ = code; }
  // Send no heartbeat (lockstep or wall-clock) for the next `syncs` SYNCs.
  void suppress_heartbeat(long syncs) { hb_gap_left_ = std::max(hb_gap_left_, syncs); }
  // TPDO frames withheld so far (--drop-tpdo and drop_tpdos) while the TPDO was due: NMT
  // operational, PDO valid, transmission type's SYNC. Each is one missed TPDO for the master.
  [[nodiscard]] std::uint64_t tpdo_dropped() const { return tpdo_dropped_; }
  // EMCY frames caused by inject_fault(): the fault EMCY and, once the operator's reset clears
  // that fault, the error-reset EMCY (code 0x0000).
  [[nodiscard]] std::uint64_t injected_emcy_sent() const { return injected_emcy_sent_; }

 private:
  struct Entry {
    std::vector<std::uint8_t> value;
    bool writable = false;
    bool readable = true;
  };
  void build_od();
  void build_io_od();
  void build_pdo_objects();
  void io_loopback();
  void reset_communication();
  void on_sync();
  void sample_and_transmit();  // TPDO (and --malformed burst) of this SYNC
  void apply_and_step();       // RPDO latched since the previous SYNC, CiA 402, plant step
  std::int64_t read_int_or(std::uint16_t index, std::uint8_t sub, std::int64_t fixed) const;
  void on_sdo(const drivers::CanFrame& f);
  void on_rpdo(const drivers::CanFrame& f, std::uint16_t k);
  std::optional<std::uint32_t> write_object(std::uint16_t index, std::uint8_t sub,
                                            const std::vector<std::uint8_t>& data);
  std::uint32_t u32(std::uint16_t index, std::uint8_t sub) const;
  std::int64_t read_int(std::uint16_t index, std::uint8_t sub) const;
  void set_int(std::uint16_t index, std::uint8_t sub, std::int64_t v);
  Entry* find(std::uint16_t index, std::uint8_t sub);
  bool pdo_mapping_ok(bool rx, std::uint8_t count, std::uint16_t map_index, std::uint32_t& abort) const;
  drivers::canopen::PdoMapping mapping(bool rx, std::uint16_t k = 0) const;
  void send_sdo(std::uint8_t cs, std::uint16_t index, std::uint8_t sub, const std::uint8_t* d, std::size_t n);
  void abort(std::uint16_t index, std::uint8_t sub, std::uint32_t code);
  void raise_fault(std::uint16_t code);
  void step_homing(std::uint16_t cw);  // CiA 402 homing mode 6, one period (apply_and_step)
  void touch_probe_apply();  // 0x60B8 at SYNC: enable, arm edges (apply_and_step, before the step)
  void touch_probe_watch(double x0_mm, double x1_mm);  // index pulses crossed by the step
  [[nodiscard]] std::uint32_t inputs_at(double x_mm) const;
  void home_here(double x_mm);
  void heartbeat();
  void on_master_heartbeat(const drivers::CanFrame& f);
  void master_heartbeat_lost();

  SimDriveSetup s_;
  Send send_;
  std::map<std::uint32_t, Entry> od_;
  std::map<std::uint32_t, Entry> od_defaults_;
  drivers::canopen::NmtState nmt_ = drivers::canopen::NmtState::kBootUp;
  drivers::canopen::Cia402State state_ = drivers::canopen::Cia402State::kNotReadyToSwitchOn;
  control::FeedDrive plant_;
  double spindle_rpm_ = 0.0, spindle_rev_ = 0.0;
  double v_cmd_mm_s_ = 0.0;  // velocity command actually applied (ramps in quick stop)
  std::uint16_t cw_ = 0, prev_cw_ = 0;
  // Homing mode 6 (0x6098 method, 0x6099 speeds, 0x609A acceleration, 0x607C home offset): the
  // methods 17..22 (limit / home switches of SimDriveSetup::switches) and 35/37 (here); others are
  // a homing error. After homing 0x6064 reads 0x607C at the home point: pos_zero_counts_ is
  // subtracted from the plant's counts (and added to a CSP target).
  enum class HomeStage : std::uint8_t { kNotStarted, kSearch, kAway, kApproach, kBrake, kAttained, kError, kInterrupted };
  HomeStage home_stage_ = HomeStage::kNotStarted;
  HomeStage home_after_brake_ = HomeStage::kAttained;
  double home_v_mm_s_ = 0.0;
  std::int64_t pos_zero_counts_ = 0;
  std::int32_t rx_target_ = 0;
  bool rx_latched_ = false;
  std::uint16_t rx_cw_ = 0;
  std::optional<std::uint32_t> rx_do_;  // 0x60FE:01 received in an RPDO, applied at SYNC
  std::optional<std::uint16_t> rx_tp_;  // 0x60B8 received in an RPDO, applied at SYNC
  std::uint16_t tp_fn_ = 0;     // 0x60B8 as applied at the last SYNC (its edges arm the latch)
  bool tp_watch_ = false;       // armed on the encoder index
  long tp_latches_ = 0;
  double tp_last_index_mm_ = std::nan("");
  long syncs_ = 0;
  long motion_started_at_ = -1;  // SYNC count of the first non-zero target applied
  long sdo_dropped_ = 0;         // SDO requests ignored so far (SimFaults::drop_sdo_requests)
  // Re-armable injection (drop_tpdos, inject_fault, suppress_heartbeat).
  long storm_drop_left_ = 0;
  std::optional<std::uint16_t> injected_fault_;
  bool injected_fault_latched_ = false;  // the drive's current fault came from inject_fault()
  long hb_gap_left_ = 0;
  std::uint64_t tpdo_dropped_ = 0;
  std::uint64_t injected_emcy_sent_ = 0;
  std::int64_t last_hb_ns_ = 0;
  std::int64_t last_sync_wall_ns_ = 0;
  std::int64_t now_wall_ns_ = 0;
  // Heartbeat consumer (0x1016:1, the master's heartbeat). CiA 301: monitoring starts with the
  // first heartbeat received. Lockstep while SYNC flows (timeout counted in SYNC periods, so the
  // reaction does not depend on wall-clock scheduling); wall-clock when SYNC has stopped too for
  // max(5 x consumer time, 2 s) (the master process is gone).
  bool master_hb_armed_ = false;
  long master_hb_sync_ = 0;  // syncs_ at the last master heartbeat
  std::int64_t master_hb_wall_ns_ = 0;
  // Segmented transfers (one at a time per node, as CiA 301 allows).
  std::vector<std::uint8_t> seg_buf_;
  std::size_t seg_pos_ = 0;
  bool seg_toggle_ = false;
  bool seg_upload_ = false, seg_download_ = false;
  std::uint16_t seg_index_ = 0;
  std::uint8_t seg_sub_ = 0;
  std::uint32_t seg_size_ = 0;
};

}  // namespace contour::sim
