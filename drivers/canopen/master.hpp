#pragma once
// Fixed-function CANopen master for CiA 402 drives (CiA 301 NMT/SDO/PDO/SYNC/EMCY/heartbeat),
// and CiA 401 generic I/O modules beside them (NodeKind::kIoModule: no power state machine; their
// TPDOs are taken in by collect() with the drives', their RPDOs sent by send_rpdos()).
//
// Threads: construction, start_up() and the SDO calls are non-RT (they block, allocate, throw
// StartupError). begin_cycle(), collect(), send_rpdos() and the request setters are the RT
// cycle: noexcept, allocation-free, O(nodes + frames received), returning a CycleStatus.
// Budget: begin_cycle + send_rpdos are one write() per frame (~5 us each on vcan); collect()
// blocks at most until the TPDO deadline (tpdo_deadline_us after the SYNC).
//
// Units: device units only (counts, counts/s, raw words). Scaling to mm is the caller's edge
// (codec.hpp: counts_to_mm, mm_s_to_counts_s).
//
// Time: the RT functions take `now_ns` from the caller (CLOCK_MONOTONIC in the daemon, the
// lockstep cycle time in tests) for the master's heartbeat-CONSUMER timeouts; the TPDO receive
// deadline is wall-clock (CLOCK_MONOTONIC) because it bounds the cycle. The master's own heartbeat
// (PRODUCER) is always sent on CLOCK_MONOTONIC: the drives consume it with a consumer time in
// milliseconds of their own clock (0x1016 = 3 x master_heartbeat_ms), so cycles that run slower
// than real time (lockstep on a loaded host) must not stretch it (issue 16: they used to, and
// the drives timed out with EMCY 0x8130). It is also sent every master_heartbeat_ms worth of
// cycles, so a burst of cycles faster than real time (catching up after a stall) does not
// stretch it for a consumer that counts SYNCs either.
//
// Faults are latched per node (drive fault, heartbeat lost, missed-TPDO streak, unexpected
// boot-up) and reported as MasterEvents through a fixed ring (pop_event, non-RT describe()).
// The master never decides motion: the supervisor calls quick_stop_all() on a fault.
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "drivers/can/can_bus.hpp"
#include "drivers/canopen/codec.hpp"

namespace contour::drivers::canopen {

enum class DriveMode : std::int8_t { kProfileVelocity = 3, kCsp = 8, kCsv = 9 };

// When the drive samples what its TPDO carries (statusword, 0x6064, 0x606C) relative to its own
// step on a SYNC: kAtSync = on the SYNC, before it applies the RPDO received in the previous
// cycle (the feedback is one period older: the CAN link adds one period to the loop's delay);
// kAfterStep = after it applied that RPDO and stepped (no extra period). The master reports it
// (log, NodeSetup); the loop's delay model (control: delay_cycles) is configured separately.
enum class FeedbackTiming : std::uint8_t { kAtSync, kAfterStep };

// One object of the object dictionary; sub = kAllSubs stands for every sub-index of `index`.
struct ObjectRef {
  static constexpr int kAllSubs = -1;
  std::uint16_t index = 0;
  int sub = kAllSubs;
  [[nodiscard]] bool matches(std::uint16_t i, std::uint8_t s) const noexcept {
    return index == i && (sub == kAllSubs || sub == s);
  }
};

// What a drive model lacks or limits (a drive profile, config/drive_profiles.hpp, mapped by the
// composition root). The default is a complete CiA 301/402 drive (today's contour-machine-sim).
struct DriveQuirks {
  std::string profile = "generic";  // name, for messages
  // Optional objects the drive does not have: the master never reads or writes them. Only
  // optional_objects() may be listed (the constructor refuses others).
  std::vector<ObjectRef> skip;
  std::uint8_t rpdos = 4, tpdos = 4;  // PDOs the drive has (1..4); the master disables 2..n
  std::uint8_t rpdo_max_entries = 8, tpdo_max_entries = 8;  // mapping entries per PDO (1..8)
  bool expedited_only = false;  // SDO: no segmented transfers (0x1008 is then not read)
  FeedbackTiming feedback = FeedbackTiming::kAtSync;
};

// The objects start_up() may do without: skipped when the profile lists them, and skipped with a
// log line when the drive answers 0x06020000 (object does not exist) or 0x06090011 (sub-index
// does not exist). 0x1016 (heartbeat consumer) is optional only by profile: a drive that lacks
// it does not stop when the master dies, so an unexpected abort on it stops the boot.
// {0x1006, 0x1007, 0x1008, 0x1016, 0x605A, 0x6085, 0x60C2}.
std::span<const std::uint16_t> optional_objects() noexcept;

enum class NodeKind : std::uint8_t { kDrive, kIoModule };

// CiA 401 objects an I/O module node maps: bit k of each mask = sub-index k + 1 is used
// (0x6000 digital inputs and 0x6200 digital outputs, 8 bits per sub-index; 0x6401 analog inputs
// and 0x6411 analog outputs, INTEGER16 per sub-index). Only what is used is mapped: inputs into
// TPDO1.. (digital bytes first, then analog words, in sub-index order, at most 8 bytes a PDO),
// outputs into RPDO1.. the same way (io_module_pdos()).
inline constexpr int kIoChannels = 8;
struct IoModuleMap {
  std::uint8_t digital_inputs = 0;
  std::uint8_t digital_outputs = 0;
  std::uint8_t analog_inputs = 0;
  std::uint8_t analog_outputs = 0;
};

struct NodeSetup {
  std::uint8_t node_id = 0;
  // kIoModule: a CiA 401 module (0x1000 device type profile 401 checked at start-up); `rpdo`,
  // `tpdo`, `mode`, the quick stop and the digital I/O fields below are not used, `io` says what
  // is mapped (at least one object).
  NodeKind kind = NodeKind::kDrive;
  IoModuleMap io{};
  std::string name;  // "X", "spindle": used in messages
  DriveMode mode = DriveMode::kCsv;
  std::uint16_t heartbeat_ms = 50;
  std::uint16_t heartbeat_timeout_ms = 200;
  std::uint32_t sync_window_us = 0;
  std::uint8_t sync_every = 1;  // PDO transmission type
  std::int16_t quick_stop_option = 2;
  std::uint32_t quick_stop_decel = 2000000;  // counts/s^2
  std::optional<std::uint32_t> device_type, vendor_id, product_code, revision;
  PdoMapping rpdo;  // RPDO1, must contain 0x6040
  PdoMapping tpdo;  // TPDO1, must contain 0x6041
  DriveQuirks quirks;
  // CiA 402 digital I/O (the PLC's cia402 bindings). `digital_inputs`: 0x60FD:00 (32 bits) is
  // mapped alone into TPDO2 (COB-ID 0x280 + node-id, same transmission type as TPDO1).
  // `digital_output_mask` != 0: 0x60FE:01 (32 bits) alone into RPDO2 (0x300 + node-id), and the
  // mask written to 0x60FE:02 at start-up (the drive drives only these bits). Both off (the
  // default): TPDO2/RPDO2 stay disabled and the node's traffic is what it was without them.
  // A drive with one PDO per direction, or without the object, is refused at start-up (the
  // constructor / start_up() name the node and the object).
  bool digital_inputs = false;
  std::uint32_t digital_output_mask = 0;
  // CiA 402 touch probe 1 (the encoder index latch of home.use_index): 0x60B8 (touch probe
  // function, 16 bits) is appended to RPDO1 when RPDO1 has 2 bytes and an entry to spare (the
  // default {0x6040, 0x60FF|0x607A} has), else mapped alone into the next free RPDO (RPDO2, or
  // RPDO3 after the digital outputs); 0x60B9 (status, 16 bits) + 0x60BA (touch probe 1
  // positive-edge position, 32 bits) into a TPDO of their own, the next free one (TPDO2, or
  // TPDO3 after the digital inputs), same transmission type as TPDO1. Off (the default): nothing
  // of it is mapped. A drive without the three objects, or without the PDOs, is refused at
  // start-up naming the node and the object (touch_probe_pdos() says where they went).
  bool touch_probe = false;
};

// Where NodeSetup::touch_probe went (Master::touch_probe_pdos): PDO numbers from 0 (0: PDO1),
// -1 when the node has no touch probe mapped. rpdo 0: 0x60B8 rides in RPDO1.
struct TouchProbePdos {
  std::int8_t rpdo = -1;
  std::int8_t tpdo = -1;
};

struct MasterConfig {
  std::vector<NodeSetup> nodes;
  std::uint32_t period_us = 1000;
  std::uint32_t bitrate = 1000000;
  double load_ceiling = 0.80;  // worst-case fraction
  std::uint8_t master_node_id = 0x7F;
  std::uint16_t master_heartbeat_ms = 100;
  int boot_timeout_ms = 2000;
  int sdo_timeout_ms = 500;
  int sdo_retries = 2;
  int tpdo_deadline_us = 800;
  int missed_tpdo_fault = 3;
};

class StartupError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// An SDO transfer aborted by the drive (from_server) or by the master; `code` is the abort code.
class SdoAbortError : public StartupError {
 public:
  SdoAbortError(const std::string& what, std::uint32_t code, bool from_server)
      : StartupError(what), code_(code), from_server_(from_server) {}
  [[nodiscard]] std::uint32_t code() const noexcept { return code_; }
  [[nodiscard]] bool from_server() const noexcept { return from_server_; }

 private:
  std::uint32_t code_;
  bool from_server_;
};

enum class CycleStatus : std::uint8_t { kOk, kFault };

enum class NodeFault : std::uint8_t {
  kNone = 0,
  kDriveFault = 1,
  kHeartbeatLost = 2,
  kTpdoMissed = 4,
  kUnexpectedBootUp = 8,
};

struct MasterEvent {
  enum class Kind : std::uint8_t {
    kEmcy,
    kDriveFault,
    kHeartbeatLost,
    kTpdoMissedFault,
    kUnexpectedBootUp,
    kNmtStateChange,
    kBusState,
  };
  Kind kind = Kind::kEmcy;
  std::uint8_t node_id = 0;
  std::uint16_t code = 0;       // EMCY code, statusword, NMT state, bus state
  std::uint8_t error_register = 0;
  std::uint64_t cycle = 0;
};

// A non-blocking expedited SDO transfer started from the RT cycle (Master::sdo_async_*): one per
// node at a time; the response is consumed by the cycle's receive path, the timeout counted in
// cycles (sdo_timeout_ms). Only expedited transfers (<= 4 bytes): no segmented protocol here.
struct AsyncSdo {
  enum class State : std::uint8_t { kIdle, kBusy, kDone, kAborted, kTimedOut };
  State state = State::kIdle;
  bool upload = false;
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::uint32_t value = 0;       // download: written; upload: the value read (little-endian)
  std::uint32_t abort_code = 0;  // kAborted: from the drive (or 0x06010000: a segmented answer)
  std::int32_t cycles_left = 0;
};

struct NodeRuntime {
  Cia402State state = Cia402State::kUnknown;
  std::uint16_t statusword = 0;
  std::int32_t position_raw = 0;       // 0x6064 as received (wraps)
  std::int64_t position_counts = 0;    // unwrapped
  std::int32_t velocity_counts_s = 0;  // 0x606C when mapped
  NmtState nmt = NmtState::kUnknown;
  std::int64_t last_heartbeat_ns = 0;
  std::uint32_t missed_streak = 0;
  std::uint64_t missed_total = 0;
  std::uint64_t tpdo_received = 0;
  std::uint8_t faults = 0;  // NodeFault bits, latched
  // A heartbeat frame arrived after the heartbeat-lost latch was set: only then can reset_faults()
  // clear it (acknowledging does not bring a silent drive back).
  bool heartbeat_since_loss = true;
  // Latched until reset_faults(): the last EMCY error code (0x0000 "error reset" not latched) and a
  // departure from NMT operational while cycling. nmt_lost clears only when the node is operational.
  std::uint16_t emcy_code = 0;
  bool nmt_lost = false;
  DriveRequest request = DriveRequest::kDisabled;
  std::int32_t target = 0;  // CSV/PV: counts/s; CSP: counts
  std::uint16_t controlword = 0;
  bool tpdo_fresh = false;
  // NodeSetup::digital_inputs: 0x60FD as last received (TPDO2), and whether it came this cycle.
  std::uint32_t digital_inputs = 0;
  bool digital_inputs_fresh = false;
  std::uint64_t digital_inputs_missed = 0;  // cycles TPDO2 was due and did not come
  std::uint32_t digital_outputs = 0;        // 0x60FE:01 sent in RPDO2 (masked)
  // NodeSetup::touch_probe: 0x60B8 sent each cycle (set_touch_probe_function), 0x60B9 and 0x60BA
  // (raw: the drive's 32-bit position register, wraps like 0x6064) as last received, and whether
  // they came this cycle.
  std::uint16_t touch_probe_function = 0;
  std::uint16_t touch_probe_status = 0;
  std::int32_t touch_probe_position_raw = 0;
  bool touch_probe_fresh = false;
  std::uint64_t touch_probe_missed = 0;  // cycles its TPDO was due and did not come
  // NodeKind::kIoModule: the inputs as last received (sub-index k + 1 at [k]; only the mapped
  // ones change), which of its TPDOs came this cycle (bit p: TPDO p+1; tpdo_fresh once all
  // have), and the outputs sent in its RPDOs (set_io_outputs).
  std::array<std::uint8_t, kIoChannels> io_digital_in{};
  std::array<std::int16_t, kIoChannels> io_analog_in{};
  std::array<std::uint8_t, kIoChannels> io_digital_out{};
  std::array<std::int16_t, kIoChannels> io_analog_out{};
  std::uint8_t io_tpdos_in = 0;
  // Operation-mode specific controlword bits (4..6, 8) OR'd into the controlword while the drive
  // is in operation enabled and enable is requested (homing: bit 4 "homing operation start").
  std::uint16_t controlword_extra = 0;
  // 0x6060 sent in an RPDO that maps it (0: NodeSetup::mode), e.g. 6 while homing.
  std::int8_t rpdo_mode = 0;
  AsyncSdo sdo{};
};

struct MasterCounters {
  std::uint64_t cycles = 0;
  std::uint64_t unknown_frames = 0;    // COB-IDs the master does not consume
  std::uint64_t malformed_frames = 0;  // known COB-ID, wrong length/content
  std::uint64_t emcy_frames = 0;
  std::uint64_t late_or_stray_frames = 0;
  std::uint64_t tx_dropped = 0;
  std::uint64_t rx_frames = 0;
};

class Master {
 public:
  using Log = std::function<void(const std::string&)>;

  // Validates the mappings against each node's quirks (entry limits, skippable objects) and the
  // bus load (throws StartupError naming the node, or above the load ceiling).
  Master(CanBus& bus, MasterConfig cfg, Log log = {});

  // Non-RT. NMT reset communication, boot-up wait, per-node SDO configuration, NMT start.
  // Throws StartupError naming node, object and abort text.
  void start_up();

  // Non-RT SDO client (timeout sdo_timeout_ms, retries on timeout; server aborts are not
  // retried). Throws SdoAbortError("node 2 (Y): SDO download 0x6060:00: 0x06090030 ...") on an
  // abort, StartupError otherwise. For a node whose quirks say expedited_only, a download of more
  // than 4 bytes is refused before anything is sent, and an upload the drive starts as a
  // segmented transfer is aborted by the master (0x06010000): never a segmented transfer.
  std::vector<std::uint8_t> sdo_upload(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub);
  void sdo_download(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                    std::span<const std::uint8_t> data);
  void sdo_download_u8(std::uint8_t n, std::uint16_t i, std::uint8_t s, std::uint8_t v);
  void sdo_download_u16(std::uint8_t n, std::uint16_t i, std::uint8_t s, std::uint16_t v);
  void sdo_download_u32(std::uint8_t n, std::uint16_t i, std::uint8_t s, std::uint32_t v);
  std::uint32_t sdo_upload_u32(std::uint8_t n, std::uint16_t i, std::uint8_t s);

  // ---- RT cycle
  CycleStatus begin_cycle(std::int64_t now_ns) noexcept;  // SYNC first, then master heartbeat
  CycleStatus collect() noexcept;                          // TPDOs until all in or deadline
  CycleStatus send_rpdos() noexcept;                       // controlword + target per node

  void set_request(std::size_t i, DriveRequest r) noexcept { rt_[i].request = r; }
  void set_request_all(DriveRequest r) noexcept;
  void quick_stop_all() noexcept { set_request_all(DriveRequest::kQuickStop); }
  void set_target(std::size_t i, std::int32_t v) noexcept { rt_[i].target = v; }
  // 0x60FE:01 for the next RPDO2 (NodeSetup::digital_output_mask bits only; others sent as 0).
  void set_digital_outputs(std::size_t i, std::uint32_t v) noexcept {
    rt_[i].digital_outputs = v & cfg_.nodes[i].digital_output_mask;
  }
  // 0x60B8 for the next cycle's RPDO (NodeSetup::touch_probe; ignored otherwise). RT-safe.
  void set_touch_probe_function(std::size_t i, std::uint16_t v) noexcept {
    rt_[i].touch_probe_function = v;
  }
  // CiA 401 outputs of I/O module node i (0x6200:01..08, 0x6411:01..08) for its next RPDOs;
  // sub-indices it does not map are not sent. RT-safe (copies 24 bytes).
  void set_io_outputs(std::size_t i, const std::array<std::uint8_t, kIoChannels>& digital,
                      const std::array<std::int16_t, kIoChannels>& analog) noexcept {
    rt_[i].io_digital_out = digital;
    rt_[i].io_analog_out = analog;
  }
  // Test hook (HIL): stop/resume the master's own heartbeat (the drives consume it, 0x1016), to
  // prove the drives' reaction to a dead master without killing the process. RT-safe.
  void set_heartbeat_producer(bool on) noexcept { heartbeat_on_ = on; }
  // Operation-mode specific controlword bits for node i (NodeRuntime::controlword_extra): only
  // bits 4, 5, 6 and 8 are taken. RT-safe.
  void set_controlword_extra(std::size_t i, std::uint16_t bits) noexcept {
    rt_[i].controlword_extra = static_cast<std::uint16_t>(bits & 0x0170u);
  }
  void set_rpdo_mode(std::size_t i, std::int8_t mode) noexcept { rt_[i].rpdo_mode = mode; }
  // Non-blocking expedited SDO from the RT cycle (AsyncSdo): sends the request now (one frame)
  // and returns false when node i already has one in flight or the frame could not be queued.
  // The result shows in sdo_async(i) after a later collect()/begin_cycle(); sdo_async_clear(i)
  // makes the slot free again after kDone/kAborted/kTimedOut. `bytes` 1..4. RT-safe.
  bool sdo_async_download(std::size_t i, std::uint16_t index, std::uint8_t sub, std::uint32_t value,
                          std::uint8_t bytes) noexcept;
  bool sdo_async_upload(std::size_t i, std::uint16_t index, std::uint8_t sub) noexcept;
  [[nodiscard]] const AsyncSdo& sdo_async(std::size_t i) const noexcept { return rt_[i].sdo; }
  void sdo_async_clear(std::size_t i) noexcept {
    if (rt_[i].sdo.state != AsyncSdo::State::kBusy) rt_[i].sdo.state = AsyncSdo::State::kIdle;
  }
  // Lets the sequencers send the fault-reset edge and clears the latched master-side faults.
  void reset_faults() noexcept;

  [[nodiscard]] bool all_enabled() const noexcept;
  [[nodiscard]] bool any_fault() const noexcept;
  [[nodiscard]] std::size_t size() const noexcept { return rt_.size(); }
  [[nodiscard]] const NodeRuntime& node(std::size_t i) const noexcept { return rt_[i]; }
  [[nodiscard]] const NodeSetup& setup(std::size_t i) const noexcept { return cfg_.nodes[i]; }
  [[nodiscard]] int index_of(std::uint8_t node_id) const noexcept;
  [[nodiscard]] TouchProbePdos touch_probe_pdos(std::size_t i) const noexcept { return probe_pdos_[i]; }
  [[nodiscard]] const MasterCounters& counters() const noexcept { return counters_; }
  [[nodiscard]] const BusLoad& bus_load() const noexcept { return load_; }
  [[nodiscard]] const MasterConfig& config() const noexcept { return cfg_; }

  bool pop_event(MasterEvent& e) noexcept;
  // Non-RT text: "EMCY node 2 (Y): 0x2310 continuous over-current, error register 0x03".
  std::string describe(const MasterEvent& e) const;

 private:
  void dispatch(const CanFrame& f, bool in_cycle) noexcept;
  bool sdo_async_response(std::uint8_t node, const CanFrame& f) noexcept;
  void push_event(const MasterEvent& e) noexcept;
  void configure_node(const NodeSetup& n);
  // PDO `k` (0: PDO1) of a direction; then disable_pdos() switches off those from `from` on.
  void configure_pdo(const NodeSetup& n, bool rx, const PdoMapping& m, std::uint16_t k = 0);
  void disable_pdos(const NodeSetup& n, bool rx, std::uint16_t from);
  void check_digital_io(const NodeSetup& n);
  void check_touch_probe(const NodeSetup& n);
  void configure_io_module(const NodeSetup& n);
  // A TPDO's values if its length and mapping fit and it came inside the cycle; otherwise false,
  // counted as malformed or late.
  bool take_pdo(const PdoMapping& m, const CanFrame& f, bool in_cycle, PdoValues& v) noexcept;
  void dispatch_io_tpdo(std::size_t i, std::uint16_t pdo, const CanFrame& f,
                        bool in_cycle) noexcept;
  void send_io_rpdos(std::size_t i, bool& err) noexcept;
  // Optional object write/read: skipped when the quirks list it; a 0x06020000/0x06090011 abort
  // from the drive is logged and skipped. Returns whether the transfer happened.
  bool optional_download(const NodeSetup& n, std::uint16_t index, std::uint8_t sub,
                         std::span<const std::uint8_t> data);
  std::optional<std::vector<std::uint8_t>> optional_upload(const NodeSetup& n, std::uint16_t index,
                                                           std::uint8_t sub);
  std::vector<std::uint8_t> run_sdo(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                                    bool upload, std::span<const std::uint8_t> data);
  std::string node_label(std::uint8_t node_id) const;
  void wait_boot_ups();
  void wait_operational();
  void log(const std::string& s) const {
    if (log_) log_(s);
  }

  CanBus& bus_;
  MasterConfig cfg_;
  Log log_;
  BusLoad load_{};
  std::vector<NodeRuntime> rt_;
  std::vector<Cia402Sequencer> seq_;
  std::vector<PositionUnwrapper> unwrap_;
  struct IoPdos {
    std::array<PdoMapping, 4> tx{}, rx{};
    std::uint8_t ntx = 0, nrx = 0;
  };
  std::vector<IoPdos> io_pdos_;  // per node (empty mappings for drives)
  std::vector<TouchProbePdos> probe_pdos_;  // per node
  std::array<std::int16_t, 128> index_by_node_{};
  std::vector<bool> booted_;
  MasterCounters counters_{};
  std::array<MasterEvent, 256> events_{};
  std::size_t ev_head_ = 0, ev_tail_ = 0;
  std::int64_t now_ns_ = 0;
  std::int64_t last_master_hb_ns_ = -1;
  std::uint64_t last_master_hb_cycle_ = 0;  // counters_.cycles at the last master heartbeat
  std::int64_t sync_mono_ns_ = 0;
  bool fault_reset_ = false;
  bool cycling_ = false;
  bool heartbeat_on_ = true;
};

// Kernel receive filters for the master's socket: EMCY, TPDO1 (and the TPDOs of the digital
// inputs and the touch probe), SDO responses and heartbeats of the configured nodes
// (everything else is dropped by the kernel, not by the RT thread).
std::vector<CanFilter> master_rx_filters(const MasterConfig& cfg);

// The default leanest mappings (issue 7): RPDO {0x6040, 0x60FF|0x607A}, TPDO {0x6041, 0x6064}.
PdoMapping default_rpdo(DriveMode m);
PdoMapping default_tpdo();
// The digital I/O PDOs of NodeSetup::digital_inputs / digital_output_mask: TPDO2 {0x60FD:00},
// RPDO2 {0x60FE:01}.
PdoMapping digital_inputs_tpdo();
PdoMapping digital_outputs_rpdo();
// The touch probe PDOs of NodeSetup::touch_probe: TPDO {0x60B9:00, 0x60BA:00} (6 bytes), and
// the RPDO {0x60B8:00} used when 0x60B8 does not fit into RPDO1.
PdoMapping touch_probe_tpdo();
PdoMapping touch_probe_rpdo();
// The PDOs of a CiA 401 module (IoModuleMap): TPDOs (rx false) or RPDOs (rx true), in order,
// each at most 8 bytes; empty when the direction maps nothing.
std::vector<PdoMapping> io_module_pdos(const IoModuleMap& io, bool rx);

}  // namespace contour::drivers::canopen
