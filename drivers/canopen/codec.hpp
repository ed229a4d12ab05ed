#pragma once
// Pure CANopen (CiA 301) / CiA 402 codecs: no I/O, no clock, no allocation in anything marked
// noexcept. COB-IDs follow the predefined connection set (see drivers/README.md):
//   NMT 0x000, SYNC 0x080, EMCY 0x080+n, TPDO1..4 0x180/0x280/0x380/0x480+n,
//   RPDO1..4 0x200/0x300/0x400/0x500+n, SDO tx 0x580+n (server->client), SDO rx 0x600+n,
//   heartbeat/boot-up 0x700+n.
// All multi-byte values are little-endian (CiA 301 7.1).
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/can/can_bus.hpp"

namespace contour::drivers::canopen {

inline constexpr std::uint32_t kCobNmt = 0x000;
inline constexpr std::uint32_t kCobSync = 0x080;
inline constexpr std::uint32_t kCobEmcy = 0x080;
inline constexpr std::uint32_t kCobTpdo[4] = {0x180, 0x280, 0x380, 0x480};
inline constexpr std::uint32_t kCobRpdo[4] = {0x200, 0x300, 0x400, 0x500};
inline constexpr std::uint32_t kCobSdoTx = 0x580;  // server -> client (responses)
inline constexpr std::uint32_t kCobSdoRx = 0x600;  // client -> server (requests)
inline constexpr std::uint32_t kCobHeartbeat = 0x700;

// ---- little-endian helpers
inline void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v & 0xFF);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>((v >> (8 * i)) & 0xFF);
}
inline std::uint16_t get_u16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

// ---- NMT
enum class NmtCommand : std::uint8_t {
  kStart = 0x01,
  kStop = 0x02,
  kPreOperational = 0x80,
  kResetNode = 0x81,
  kResetCommunication = 0x82,
};
enum class NmtState : std::uint8_t {
  kBootUp = 0x00,
  kStopped = 0x04,
  kOperational = 0x05,
  kPreOperational = 0x7F,
  kUnknown = 0xFF,
};
CanFrame nmt_frame(NmtCommand cmd, std::uint8_t node_id) noexcept;  // node 0 = all nodes
CanFrame sync_frame() noexcept;
CanFrame heartbeat_frame(std::uint8_t node_id, NmtState s) noexcept;
// Heartbeat/boot-up decode: the state, or nullopt for a frame of the wrong shape.
std::optional<NmtState> decode_heartbeat(const CanFrame& f) noexcept;
const char* nmt_state_name(NmtState s) noexcept;

// Function code helpers: node-id of a frame in [base+1, base+127], or 0.
inline std::uint8_t node_of(std::uint32_t cob, std::uint32_t base) noexcept {
  return (cob > base && cob <= base + 127) ? static_cast<std::uint8_t>(cob - base) : 0;
}

// ---- SDO
// Abort code -> CiA 301 text ("0x06020000 object does not exist in the object dictionary").
std::string sdo_abort_text(std::uint32_t code);
const char* sdo_abort_reason(std::uint32_t code) noexcept;  // text only, "" for unknown

CanFrame sdo_abort_frame(std::uint8_t node_id, bool from_server, std::uint16_t index,
                         std::uint8_t sub, std::uint32_t code) noexcept;

// Client-side state machine for one SDO transfer (expedited or segmented, upload or download).
// Feed it the server's responses; it produces the next request. Pure, deterministic, testable
// against scripted frames; timeouts are the caller's business (it only tracks the state).
class SdoTransfer {
 public:
  enum class Status { kIdle, kWaiting, kDone, kAborted };

  // Returns the first request frame (COB 0x600+node).
  CanFrame start_download(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                          std::span<const std::uint8_t> data);
  // expedited_only: a server answering with a segmented upload is aborted by the client with
  // 0x06010000 (unsupported access) instead of being asked for segments.
  CanFrame start_upload(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                        bool expedited_only = false);

  // Handles a frame on 0x580+node. Returns the next request to send (segment or segment
  // request, or an abort the client raises on a protocol error), or nullopt when none.
  // Frames for other COB-IDs are ignored (nullopt, status unchanged).
  std::optional<CanFrame> on_frame(const CanFrame& f);

  // The abort the client sends on timeout (0x05040000); marks the transfer aborted.
  CanFrame timeout_abort();

  [[nodiscard]] Status status() const noexcept { return status_; }
  [[nodiscard]] std::uint32_t abort_code() const noexcept { return abort_code_; }
  [[nodiscard]] bool abort_from_server() const noexcept { return abort_from_server_; }
  [[nodiscard]] const std::vector<std::uint8_t>& data() const noexcept { return data_; }
  [[nodiscard]] std::uint16_t index() const noexcept { return index_; }
  [[nodiscard]] std::uint8_t sub() const noexcept { return sub_; }

 private:
  CanFrame request() const noexcept;
  CanFrame fail(std::uint32_t code);
  CanFrame next_download_segment();

  enum class Phase { kNone, kDlInitiate, kDlSegment, kUlInitiate, kUlSegment };
  Phase phase_ = Phase::kNone;
  Status status_ = Status::kIdle;
  std::uint8_t node_ = 0;
  std::uint16_t index_ = 0;
  std::uint8_t sub_ = 0;
  std::vector<std::uint8_t> data_;
  std::size_t offset_ = 0;
  bool toggle_ = false;
  std::uint32_t size_indicated_ = 0;
  bool size_known_ = false;
  bool expedited_only_ = false;
  std::uint32_t abort_code_ = 0;
  bool abort_from_server_ = false;
};

// ---- EMCY
struct Emcy {
  std::uint16_t code = 0;
  std::uint8_t error_register = 0;
  std::array<std::uint8_t, 5> vendor{};
};
std::optional<Emcy> decode_emcy(const CanFrame& f) noexcept;  // needs dlc 8
CanFrame emcy_frame(std::uint8_t node_id, const Emcy& e) noexcept;
// CiA 301/402 error-code class text, e.g. 0x2310 -> "continuous over-current";
// 0x0000 -> "error reset or no error".
const char* emcy_code_text(std::uint16_t code) noexcept;

// ---- PDO mapping
struct PdoEntry {
  std::uint16_t index = 0;
  std::uint8_t sub = 0;
  std::uint8_t bits = 0;  // 8, 16 or 32
  [[nodiscard]] std::uint32_t mapping_word() const noexcept {
    return (static_cast<std::uint32_t>(index) << 16) | (static_cast<std::uint32_t>(sub) << 8) |
           bits;
  }
  static PdoEntry from_word(std::uint32_t w) noexcept {
    return PdoEntry{static_cast<std::uint16_t>(w >> 16), static_cast<std::uint8_t>((w >> 8) & 0xFF),
                    static_cast<std::uint8_t>(w & 0xFF)};
  }
  bool operator==(const PdoEntry&) const = default;
};

struct PdoMapping {
  static constexpr std::size_t kMaxEntries = 8;
  std::array<PdoEntry, kMaxEntries> entries{};
  std::size_t count = 0;
  [[nodiscard]] std::size_t bytes() const noexcept;  // sum of bits / 8
  // Position of `index` in the mapping, or -1.
  [[nodiscard]] int find(std::uint16_t index, std::uint8_t sub = 0) const noexcept;
  // Setup-time validation: entries of 8/16/32 bits, total <= 64 bits. Empty string when valid.
  [[nodiscard]] std::string validate() const;
};

// Values are raw integers (sign-extended into int64 on unpack for signed objects is the
// caller's choice: unpack returns the raw unsigned bits; see as_i32/as_i16).
using PdoValues = std::array<std::int64_t, PdoMapping::kMaxEntries>;
// Packs values[i] (truncated to entries[i].bits) little-endian into f.data; sets dlc.
void pack_pdo(const PdoMapping& m, const PdoValues& values, CanFrame& f) noexcept;
// Returns false when the frame is shorter than the mapping (malformed).
bool unpack_pdo(const PdoMapping& m, const CanFrame& f, PdoValues& values) noexcept;
inline std::int32_t as_i32(std::int64_t raw) noexcept {
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(raw & 0xFFFFFFFF));
}
inline std::int16_t as_i16(std::int64_t raw) noexcept {
  return static_cast<std::int16_t>(static_cast<std::uint16_t>(raw & 0xFFFF));
}

// ---- CiA 402
// 0x60B8 touch probe function bits (CiA 402): bit 0 enables touch probe 1, bit 1 = 0 latches the
// first event only (1: continuous), bits 2..3 the trigger (00 the touch probe 1 input, 01 the
// position encoder's zero impulse, i.e. its index), bit 4 enables the latch on the positive edge
// (bit 5: negative edge). A new arm needs bit 0 or bit 4 to go 0 -> 1 at the drive.
inline constexpr std::uint16_t kTouchProbe1Enable = 0x0001;
inline constexpr std::uint16_t kTouchProbe1Continuous = 0x0002;
inline constexpr std::uint16_t kTouchProbe1TriggerIndex = 0x0004;
inline constexpr std::uint16_t kTouchProbe1TriggerMask = 0x000C;
inline constexpr std::uint16_t kTouchProbe1PositiveEdge = 0x0010;
// Armed on the encoder index, first event, positive edge: 0x0015.
inline constexpr std::uint16_t kTouchProbe1ArmIndex =
    kTouchProbe1Enable | kTouchProbe1TriggerIndex | kTouchProbe1PositiveEdge;
// 0x60B9 bits: touch probe 1 enabled, its positive-edge position (0x60BA) stored.
inline constexpr std::uint16_t kTouchProbe1Enabled = 0x0001;
inline constexpr std::uint16_t kTouchProbe1PositiveStored = 0x0002;

enum class Cia402State {
  kNotReadyToSwitchOn,
  kSwitchOnDisabled,
  kReadyToSwitchOn,
  kSwitchedOn,
  kOperationEnabled,
  kQuickStopActive,
  kFaultReactionActive,
  kFault,
  kUnknown,
};
Cia402State decode_statusword(std::uint16_t sw) noexcept;
const char* cia402_state_name(Cia402State s) noexcept;
// Statusword the drive reports for a state (used by the simulator; bits 4 voltage enabled and 9
// remote set as drives do).
std::uint16_t statusword_for(Cia402State s) noexcept;

inline constexpr std::uint16_t kCwShutdown = 0x0006;
inline constexpr std::uint16_t kCwSwitchOn = 0x0007;
inline constexpr std::uint16_t kCwEnableOperation = 0x000F;
inline constexpr std::uint16_t kCwDisableVoltage = 0x0000;
inline constexpr std::uint16_t kCwQuickStop = 0x0002;
inline constexpr std::uint16_t kCwFaultReset = 0x0080;

// What the master wants from a drive.
enum class DriveRequest { kDisabled, kEnabled, kQuickStop };

// Controlword sequencing toward a requested state, one call per cycle (noexcept, O(1)).
// Fault reset is a rising edge of bit 7: from Fault it sends 0x0000 then 0x0080 (held while the
// drive is still in Fault), then continues with shutdown. `fault_reset_allowed` gates the edge
// (a supervisor sets it on an operator reset).
class Cia402Sequencer {
 public:
  std::uint16_t next(Cia402State actual, DriveRequest req, bool fault_reset_allowed) noexcept;
  [[nodiscard]] std::uint16_t last() const noexcept { return last_; }

 private:
  std::uint16_t last_ = kCwDisableVoltage;
};

// Drive-side CiA 402 transitions for a received controlword (pure; used by the simulator and
// by tests as the reference). quick_stop_option 0x605A: 1/2 -> switch on disabled after the
// ramp, 5/6 -> stay in quick stop active. Returns the new state; `ramp_done` tells whether the
// quick-stop ramp has finished.
Cia402State drive_transition(Cia402State s, std::uint16_t cw, std::uint16_t prev_cw,
                             int quick_stop_option, bool ramp_done) noexcept;

// ---- scaling and wrap-around
// Extends successive 32-bit position readings into a continuous 64-bit count (handles the
// wrap from 0x7FFFFFFF to 0x80000000 and back): each step is the difference of two readings
// modulo 2^32 taken the shorter way round, -2^31 <= step < 2^31. noexcept, O(1).
//
// The difference is formed in uint32_t (well-defined modulo 2^32) and sign-folded in int64_t; no
// int32_t value is carried from one call to the next. The textbook form, last reading kept as
// int32_t and step = int32_t(uint32_t(raw) - uint32_t(last)), is valid C++20 and UBSan-clean,
// but g++ 12.2 (Debian 12) miscompiles it at -O3 (a variant without primed_ even at -O2) when
// update() is inlined into a loop whose readings are a 64-bit counter truncated to int32: the
// loop analysis takes the truncated readings for an int32 sequence that never wraps, and value
// range propagation then folds the stored last reading to its first value, so every step after
// the wrap is measured from the start. tests/unit/drivers/position_unwrapper_o3_test.cpp keeps
// those loop shapes (compiled at -O3 in every build) so that form cannot come back unnoticed.
class PositionUnwrapper {
 public:
  void reset(std::int32_t raw) noexcept {
    last_bits_ = static_cast<std::uint32_t>(raw);
    value_ = raw;
    primed_ = true;
  }
  std::int64_t update(std::int32_t raw) noexcept {
    if (!primed_) {
      reset(raw);
      return value_;
    }
    const auto bits = static_cast<std::uint32_t>(raw);
    const auto step = static_cast<std::int64_t>(bits - last_bits_);  // modulo 2^32: [0, 2^32)
    value_ += step >= kHalfRangeCounts ? step - 2 * kHalfRangeCounts : step;
    last_bits_ = bits;
    return value_;
  }
  [[nodiscard]] std::int64_t value() const noexcept { return value_; }

 private:
  static constexpr std::int64_t kHalfRangeCounts = std::int64_t{1} << 31;
  std::uint32_t last_bits_ = 0;  // the last reading's 32 bits
  std::int64_t value_ = 0;
  bool primed_ = false;
};
inline double counts_to_mm(std::int64_t counts, double counts_per_mm) noexcept {
  return static_cast<double>(counts) / counts_per_mm;
}
// Velocity estimated from two position readings `dt_s` apart (counts -> mm/s). Used where the
// TPDO carries no 0x606C; the daemon's CANopen bus and its offline model (SimBus) share this one
// expression so their results are bit-identical.
inline double counts_velocity_mm_s(std::int64_t delta_counts, double counts_per_mm,
                                   double dt_s) noexcept {
  return static_cast<double>(delta_counts) / counts_per_mm / dt_s;
}
// Rounds to the nearest count and wraps into int32 as a drive's 32-bit register does.
std::int32_t mm_to_counts_wrapped(double mm, double counts_per_mm) noexcept;
// Velocity command in counts/s, saturated to int32.
std::int32_t mm_s_to_counts_s(double mm_s, double counts_per_mm) noexcept;

// ---- bus load
// Bits of one classic frame with 11-bit id and n data bytes: nominal 47 + 8n; worst case adds
// the maximum stuff bits over the stuffed region (34 + 8n bits): floor((34 + 8n - 1) / 4),
// i.e. 55 + 10n for n = 0..8 (CiA / Bosch CAN 2.0; canopen-notes.md).
int frame_bits_nominal(int data_bytes) noexcept;
int frame_bits_worst(int data_bytes) noexcept;
struct BusLoad {
  double nominal = 0.0;     // fraction of the bit rate, averaged over the longest PDO period
  double worst_case = 0.0;  // same with worst-case bit stuffing
  double peak_cycle_worst = 0.0;  // the busiest single cycle, worst case
  int frames_per_cycle_avg_x1000 = 0;
};
struct CyclicFrame {
  int data_bytes = 0;
  int every_n_cycles = 1;  // transmission every n-th SYNC
};
BusLoad estimate_bus_load(std::span<const CyclicFrame> frames, double bitrate_bps,
                          double period_s) noexcept;

}  // namespace contour::drivers::canopen
