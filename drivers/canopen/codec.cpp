#include "drivers/canopen/codec.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace contour::drivers::canopen {

// ---------------------------------------------------------------- NMT / SYNC / heartbeat
CanFrame nmt_frame(NmtCommand cmd, std::uint8_t node_id) noexcept {
  CanFrame f;
  f.id = kCobNmt;
  f.dlc = 2;
  f.data[0] = static_cast<std::uint8_t>(cmd);
  f.data[1] = node_id;
  return f;
}

CanFrame sync_frame() noexcept {
  CanFrame f;
  f.id = kCobSync;
  f.dlc = 0;
  return f;
}

CanFrame heartbeat_frame(std::uint8_t node_id, NmtState s) noexcept {
  CanFrame f;
  f.id = kCobHeartbeat + node_id;
  f.dlc = 1;
  f.data[0] = static_cast<std::uint8_t>(s);
  return f;
}

std::optional<NmtState> decode_heartbeat(const CanFrame& f) noexcept {
  if (f.error || f.rtr || f.extended || f.dlc != 1) return std::nullopt;
  if (node_of(f.id, kCobHeartbeat) == 0) return std::nullopt;
  // Bit 7 is the node-guarding toggle; heartbeat sends it as 0, mask it anyway.
  switch (f.data[0] & 0x7F) {
    case 0x00: return NmtState::kBootUp;
    case 0x04: return NmtState::kStopped;
    case 0x05: return NmtState::kOperational;
    case 0x7F: return NmtState::kPreOperational;
    default: return std::nullopt;
  }
}

const char* nmt_state_name(NmtState s) noexcept {
  switch (s) {
    case NmtState::kBootUp: return "boot-up";
    case NmtState::kStopped: return "stopped";
    case NmtState::kOperational: return "operational";
    case NmtState::kPreOperational: return "pre-operational";
    case NmtState::kUnknown: return "unknown";
  }
  return "?";
}

// ---------------------------------------------------------------- SDO
const char* sdo_abort_reason(std::uint32_t code) noexcept {
  switch (code) {
    case 0x05030000: return "toggle bit not alternated";
    case 0x05040000: return "SDO protocol timed out";
    case 0x05040001: return "client/server command specifier not valid or unknown";
    case 0x05040002: return "invalid block size";
    case 0x05040003: return "invalid sequence number";
    case 0x05040004: return "CRC error";
    case 0x05040005: return "out of memory";
    case 0x06010000: return "unsupported access to an object";
    case 0x06010001: return "attempt to read a write only object";
    case 0x06010002: return "attempt to write a read only object";
    case 0x06020000: return "object does not exist in the object dictionary";
    case 0x06040041: return "object cannot be mapped to the PDO";
    case 0x06040042: return "the number and length of the objects to be mapped would exceed PDO length";
    case 0x06040043: return "general parameter incompatibility reason";
    case 0x06040047: return "general internal incompatibility in the device";
    case 0x06060000: return "access failed due to a hardware error";
    case 0x06070010: return "data type does not match, length of service parameter does not match";
    case 0x06070012: return "data type does not match, length of service parameter too high";
    case 0x06070013: return "data type does not match, length of service parameter too low";
    case 0x06090011: return "sub-index does not exist";
    case 0x06090030: return "invalid value for parameter (download only)";
    case 0x06090031: return "value of parameter written too high (download only)";
    case 0x06090032: return "value of parameter written too low (download only)";
    case 0x06090036: return "maximum value is less than minimum value";
    case 0x060A0023: return "resource not available: SDO connection";
    case 0x08000000: return "general error";
    case 0x08000020: return "data cannot be transferred or stored to the application";
    case 0x08000021: return "data cannot be transferred or stored to the application because of local control";
    case 0x08000022: return "data cannot be transferred or stored to the application because of the present device state";
    case 0x08000023: return "object dictionary dynamic generation fails or no object dictionary is present";
    case 0x08000024: return "no data available";
    default: return "";
  }
}

std::string sdo_abort_text(std::uint32_t code) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%08X", code);
  const char* r = sdo_abort_reason(code);
  return std::string(buf) + " " + (*r != 0 ? r : "unknown abort code");
}

CanFrame sdo_abort_frame(std::uint8_t node_id, bool from_server, std::uint16_t index,
                         std::uint8_t sub, std::uint32_t code) noexcept {
  CanFrame f;
  f.id = (from_server ? kCobSdoTx : kCobSdoRx) + node_id;
  f.dlc = 8;
  f.data[0] = 0x80;
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  put_u32(&f.data[4], code);
  return f;
}

CanFrame SdoTransfer::request() const noexcept {
  CanFrame f;
  f.id = kCobSdoRx + node_;
  f.dlc = 8;
  return f;
}

CanFrame SdoTransfer::fail(std::uint32_t code) {
  status_ = Status::kAborted;
  abort_code_ = code;
  abort_from_server_ = false;
  phase_ = Phase::kNone;
  return sdo_abort_frame(node_, false, index_, sub_, code);
}

CanFrame SdoTransfer::start_download(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                                     std::span<const std::uint8_t> data) {
  node_ = node_id;
  index_ = index;
  sub_ = sub;
  expedited_only_ = false;
  data_.assign(data.begin(), data.end());
  offset_ = 0;
  toggle_ = false;
  abort_code_ = 0;
  abort_from_server_ = false;
  status_ = Status::kWaiting;
  phase_ = Phase::kDlInitiate;
  CanFrame f = request();
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  if (data_.size() <= 4 && !data_.empty()) {
    // Expedited, size indicated: ccs=1, n = 4 - size in bits 3..2, e=1, s=1.
    f.data[0] = static_cast<std::uint8_t>(0x23 | ((4 - data_.size()) << 2));
    std::copy(data_.begin(), data_.end(), f.data.begin() + 4);
    offset_ = data_.size();
  } else {
    f.data[0] = 0x21;  // segmented, size indicated
    put_u32(&f.data[4], static_cast<std::uint32_t>(data_.size()));
  }
  return f;
}

CanFrame SdoTransfer::start_upload(std::uint8_t node_id, std::uint16_t index, std::uint8_t sub,
                                   bool expedited_only) {
  expedited_only_ = expedited_only;
  node_ = node_id;
  index_ = index;
  sub_ = sub;
  data_.clear();
  offset_ = 0;
  toggle_ = false;
  size_known_ = false;
  size_indicated_ = 0;
  abort_code_ = 0;
  abort_from_server_ = false;
  status_ = Status::kWaiting;
  phase_ = Phase::kUlInitiate;
  CanFrame f = request();
  f.data[0] = 0x40;
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  return f;
}

CanFrame SdoTransfer::next_download_segment() {
  CanFrame f = request();
  const std::size_t n = std::min<std::size_t>(7, data_.size() - offset_);
  const bool last = offset_ + n >= data_.size();
  f.data[0] = static_cast<std::uint8_t>((toggle_ ? 0x10 : 0x00) | ((7 - n) << 1) | (last ? 1 : 0));
  std::copy(data_.begin() + static_cast<std::ptrdiff_t>(offset_),
            data_.begin() + static_cast<std::ptrdiff_t>(offset_ + n), f.data.begin() + 1);
  offset_ += n;
  phase_ = Phase::kDlSegment;
  return f;
}

CanFrame SdoTransfer::timeout_abort() { return fail(0x05040000); }

std::optional<CanFrame> SdoTransfer::on_frame(const CanFrame& f) {
  if (status_ != Status::kWaiting) return std::nullopt;
  if (f.error || f.rtr || f.extended || f.id != kCobSdoTx + node_) return std::nullopt;
  if (f.dlc != 8) return fail(0x05040001);  // SDO frames are always 8 bytes (CiA 301 7.2.4.3)
  const std::uint8_t cs = f.data[0];
  if (cs == 0x80) {
    status_ = Status::kAborted;
    abort_code_ = get_u32(&f.data[4]);
    abort_from_server_ = true;
    phase_ = Phase::kNone;
    return std::nullopt;
  }
  const std::uint8_t scs = cs & 0xE0;
  const bool mux_ok = get_u16(&f.data[1]) == index_ && f.data[3] == sub_;
  switch (phase_) {
    case Phase::kDlInitiate:
      if (scs != 0x60) return fail(0x05040001);
      if (!mux_ok) return fail(0x08000000);
      if (offset_ >= data_.size() && !data_.empty()) {
        status_ = Status::kDone;
        phase_ = Phase::kNone;
        return std::nullopt;
      }
      return next_download_segment();
    case Phase::kDlSegment: {
      if (scs != 0x20) return fail(0x05040001);
      if (((cs & 0x10) != 0) != toggle_) return fail(0x05030000);
      toggle_ = !toggle_;
      if (offset_ >= data_.size()) {
        status_ = Status::kDone;
        phase_ = Phase::kNone;
        return std::nullopt;
      }
      return next_download_segment();
    }
    case Phase::kUlInitiate: {
      if (scs != 0x40) return fail(0x05040001);
      if (!mux_ok) return fail(0x08000000);
      const bool expedited = (cs & 0x02) != 0;
      const bool size_ind = (cs & 0x01) != 0;
      if (expedited) {
        const std::size_t n = size_ind ? 4u - ((cs >> 2) & 0x03u) : 4u;
        data_.assign(f.data.begin() + 4, f.data.begin() + 4 + static_cast<std::ptrdiff_t>(n));
        status_ = Status::kDone;
        phase_ = Phase::kNone;
        return std::nullopt;
      }
      if (expedited_only_) return fail(0x06010000);
      size_known_ = size_ind;
      size_indicated_ = size_ind ? get_u32(&f.data[4]) : 0;
      phase_ = Phase::kUlSegment;
      toggle_ = false;
      CanFrame r = request();
      r.data[0] = 0x60;
      return r;
    }
    case Phase::kUlSegment: {
      if (scs != 0x00) return fail(0x05040001);
      if (((cs & 0x10) != 0) != toggle_) return fail(0x05030000);
      const std::size_t n = 7u - ((cs >> 1) & 0x07u);
      data_.insert(data_.end(), f.data.begin() + 1, f.data.begin() + 1 + static_cast<std::ptrdiff_t>(n));
      if ((cs & 0x01) != 0) {
        if (size_known_ && data_.size() != size_indicated_) return fail(0x06070010);
        status_ = Status::kDone;
        phase_ = Phase::kNone;
        return std::nullopt;
      }
      if (data_.size() > (1u << 20)) return fail(0x05040005);
      toggle_ = !toggle_;
      CanFrame r = request();
      r.data[0] = static_cast<std::uint8_t>(0x60 | (toggle_ ? 0x10 : 0x00));
      return r;
    }
    case Phase::kNone: break;
  }
  return std::nullopt;
}

// ---------------------------------------------------------------- EMCY
std::optional<Emcy> decode_emcy(const CanFrame& f) noexcept {
  if (f.error || f.rtr || f.extended || f.dlc != 8) return std::nullopt;
  if (node_of(f.id, kCobEmcy) == 0) return std::nullopt;
  Emcy e;
  e.code = get_u16(&f.data[0]);
  e.error_register = f.data[2];
  std::copy(f.data.begin() + 3, f.data.end(), e.vendor.begin());
  return e;
}

CanFrame emcy_frame(std::uint8_t node_id, const Emcy& e) noexcept {
  CanFrame f;
  f.id = kCobEmcy + node_id;
  f.dlc = 8;
  put_u16(&f.data[0], e.code);
  f.data[2] = e.error_register;
  std::copy(e.vendor.begin(), e.vendor.end(), f.data.begin() + 3);
  return f;
}

const char* emcy_code_text(std::uint16_t code) noexcept {
  switch (code) {  // exact CiA 301 / CiA 402 codes first
    case 0x0000: return "error reset or no error";
    case 0x1000: return "generic error";
    case 0x2310: return "continuous over-current";
    case 0x2320: return "short circuit / earth leakage";
    case 0x3210: return "DC link over-voltage";
    case 0x3220: return "DC link under-voltage";
    case 0x4210: return "excess temperature device";
    case 0x4310: return "excess temperature drive";
    case 0x5530: return "EEPROM / data storage error";
    case 0x6320: return "parameter error";
    case 0x7121: return "motor blocked";
    case 0x7305: return "incremental sensor 1 fault";
    case 0x8110: return "CAN overrun (objects lost)";
    case 0x8120: return "CAN in error passive mode";
    case 0x8130: return "life guard or heartbeat error";
    case 0x8140: return "recovered from bus off";
    case 0x8210: return "PDO not processed due to length error";
    case 0x8220: return "PDO length exceeded";
    case 0x8611: return "following error";
    case 0x8612: return "reference limit";
    default: break;
  }
  switch (code >> 8) {  // classes
    case 0x21: return "current, device input side";
    case 0x22: return "current inside the device";
    case 0x23: return "current, device output side";
    case 0x31: return "mains voltage";
    case 0x32: return "voltage inside the device";
    case 0x33: return "output voltage";
    case 0x41: return "ambient temperature";
    case 0x42: return "device temperature";
    case 0x50: return "device hardware";
    case 0x61: return "internal software";
    case 0x62: return "user software";
    case 0x63: return "data set";
    case 0x70: return "additional modules";
    case 0x81: return "communication";
    case 0x82: return "protocol error";
    case 0x90: return "external error";
    case 0xF0: return "additional functions";
    case 0xFF: return "device specific";
    default: break;
  }
  switch (code >> 12) {
    case 0x2: return "current";
    case 0x3: return "voltage";
    case 0x4: return "temperature";
    case 0x7: return "additional modules";
    case 0x8: return "monitoring";
    default: return "unknown error code";
  }
}

// ---------------------------------------------------------------- PDO
std::size_t PdoMapping::bytes() const noexcept {
  std::size_t bits = 0;
  for (std::size_t i = 0; i < count && i < kMaxEntries; ++i) bits += entries[i].bits;
  return bits / 8;
}

int PdoMapping::find(std::uint16_t index, std::uint8_t sub) const noexcept {
  for (std::size_t i = 0; i < count && i < kMaxEntries; ++i)
    if (entries[i].index == index && entries[i].sub == sub) return static_cast<int>(i);
  return -1;
}

std::string PdoMapping::validate() const {
  if (count > kMaxEntries) return "more than 8 mapped objects";
  std::size_t bits = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const auto b = entries[i].bits;
    if (b != 8 && b != 16 && b != 32) return "mapped object bit length must be 8, 16 or 32";
    bits += b;
  }
  if (bits > 64) return "mapping exceeds 64 bits (8 bytes)";
  return {};
}

void pack_pdo(const PdoMapping& m, const PdoValues& values, CanFrame& f) noexcept {
  std::size_t pos = 0;
  f.data.fill(0);
  for (std::size_t i = 0; i < m.count && i < PdoMapping::kMaxEntries; ++i) {
    const std::size_t nb = m.entries[i].bits / 8u;
    const auto v = static_cast<std::uint64_t>(values[i]);
    for (std::size_t b = 0; b < nb && pos < 8; ++b, ++pos)
      f.data[pos] = static_cast<std::uint8_t>((v >> (8 * b)) & 0xFF);
  }
  f.dlc = static_cast<std::uint8_t>(pos);
}

bool unpack_pdo(const PdoMapping& m, const CanFrame& f, PdoValues& values) noexcept {
  if (f.dlc < m.bytes()) return false;
  std::size_t pos = 0;
  for (std::size_t i = 0; i < m.count && i < PdoMapping::kMaxEntries; ++i) {
    const std::size_t nb = m.entries[i].bits / 8u;
    std::uint64_t v = 0;
    for (std::size_t b = 0; b < nb && pos < 8; ++b, ++pos)
      v |= static_cast<std::uint64_t>(f.data[pos]) << (8 * b);
    values[i] = static_cast<std::int64_t>(v);
  }
  return true;
}

// ---------------------------------------------------------------- CiA 402
Cia402State decode_statusword(std::uint16_t sw) noexcept {
  if ((sw & 0x4F) == 0x00) return Cia402State::kNotReadyToSwitchOn;
  if ((sw & 0x4F) == 0x40) return Cia402State::kSwitchOnDisabled;
  if ((sw & 0x6F) == 0x21) return Cia402State::kReadyToSwitchOn;
  if ((sw & 0x6F) == 0x23) return Cia402State::kSwitchedOn;
  if ((sw & 0x6F) == 0x27) return Cia402State::kOperationEnabled;
  if ((sw & 0x6F) == 0x07) return Cia402State::kQuickStopActive;
  if ((sw & 0x4F) == 0x0F) return Cia402State::kFaultReactionActive;
  if ((sw & 0x4F) == 0x08) return Cia402State::kFault;
  return Cia402State::kUnknown;
}

const char* cia402_state_name(Cia402State s) noexcept {
  switch (s) {
    case Cia402State::kNotReadyToSwitchOn: return "not ready to switch on";
    case Cia402State::kSwitchOnDisabled: return "switch on disabled";
    case Cia402State::kReadyToSwitchOn: return "ready to switch on";
    case Cia402State::kSwitchedOn: return "switched on";
    case Cia402State::kOperationEnabled: return "operation enabled";
    case Cia402State::kQuickStopActive: return "quick stop active";
    case Cia402State::kFaultReactionActive: return "fault reaction active";
    case Cia402State::kFault: return "fault";
    case Cia402State::kUnknown: return "unknown";
  }
  return "?";
}

std::uint16_t statusword_for(Cia402State s) noexcept {
  constexpr std::uint16_t kRemote = 0x0200, kVoltage = 0x0010;
  switch (s) {
    case Cia402State::kNotReadyToSwitchOn: return kRemote;
    case Cia402State::kSwitchOnDisabled: return 0x0040 | kRemote;
    case Cia402State::kReadyToSwitchOn: return 0x0021 | kVoltage | kRemote;
    case Cia402State::kSwitchedOn: return 0x0023 | kVoltage | kRemote;
    case Cia402State::kOperationEnabled: return 0x0027 | kVoltage | kRemote;
    case Cia402State::kQuickStopActive: return 0x0007 | kVoltage | kRemote;
    case Cia402State::kFaultReactionActive: return 0x000F | kVoltage | kRemote;
    case Cia402State::kFault: return 0x0008 | kRemote;
    case Cia402State::kUnknown: return 0x0000;
  }
  return 0;
}

std::uint16_t Cia402Sequencer::next(Cia402State actual, DriveRequest req,
                                    bool fault_reset_allowed) noexcept {
  std::uint16_t cw = kCwDisableVoltage;
  switch (actual) {
    case Cia402State::kFault:
    case Cia402State::kFaultReactionActive:
      // Rising edge of bit 7: alternate 0x0000 / 0x0080 while the fault stays latched. Sent for
      // any request once the supervisor allows it (operator reset): CiA 402 fault reset leads to
      // Switch on disabled, which is also where a disabled request wants the drive.
      if (fault_reset_allowed && actual == Cia402State::kFault)
        cw = (last_ & kCwFaultReset) != 0 ? kCwDisableVoltage : kCwFaultReset;
      else
        cw = kCwDisableVoltage;
      break;
    default:
      switch (req) {
        case DriveRequest::kDisabled: cw = kCwDisableVoltage; break;
        case DriveRequest::kQuickStop: cw = kCwQuickStop; break;
        case DriveRequest::kEnabled:
          switch (actual) {
            case Cia402State::kNotReadyToSwitchOn:
            case Cia402State::kSwitchOnDisabled: cw = kCwShutdown; break;
            case Cia402State::kReadyToSwitchOn: cw = kCwSwitchOn; break;
            case Cia402State::kSwitchedOn:
            case Cia402State::kOperationEnabled: cw = kCwEnableOperation; break;
            // Leave quick stop through switch on disabled rather than resuming motion at once.
            case Cia402State::kQuickStopActive: cw = kCwDisableVoltage; break;
            default: cw = kCwShutdown; break;
          }
          break;
      }
  }
  last_ = cw;
  return cw;
}

Cia402State drive_transition(Cia402State s, std::uint16_t cw, std::uint16_t prev_cw,
                             int quick_stop_option, bool ramp_done) noexcept {
  const bool shutdown = (cw & 0x87) == 0x06;
  const bool switch_on = (cw & 0x8F) == 0x07;  // also "disable operation"
  const bool enable_op = (cw & 0x8F) == 0x0F;
  const bool disable_voltage = (cw & 0x82) == 0x00;
  const bool quick_stop = (cw & 0x86) == 0x02;
  const bool reset_edge = (cw & 0x80) != 0 && (prev_cw & 0x80) == 0;
  switch (s) {
    case Cia402State::kNotReadyToSwitchOn: return Cia402State::kSwitchOnDisabled;  // self-test done
    case Cia402State::kSwitchOnDisabled:
      return shutdown ? Cia402State::kReadyToSwitchOn : s;
    case Cia402State::kReadyToSwitchOn:
      if (disable_voltage || quick_stop) return Cia402State::kSwitchOnDisabled;
      if (switch_on || enable_op) return Cia402State::kSwitchedOn;
      return s;
    case Cia402State::kSwitchedOn:
      if (disable_voltage || quick_stop) return Cia402State::kSwitchOnDisabled;
      if (shutdown) return Cia402State::kReadyToSwitchOn;
      if (enable_op) return Cia402State::kOperationEnabled;
      return s;
    case Cia402State::kOperationEnabled:
      if (disable_voltage) return Cia402State::kSwitchOnDisabled;
      if (quick_stop) return Cia402State::kQuickStopActive;
      if (shutdown) return Cia402State::kReadyToSwitchOn;
      if (switch_on) return Cia402State::kSwitchedOn;
      return s;
    case Cia402State::kQuickStopActive:
      if (disable_voltage && !quick_stop) return Cia402State::kSwitchOnDisabled;
      if (ramp_done && quick_stop_option >= 1 && quick_stop_option <= 4)
        return Cia402State::kSwitchOnDisabled;
      if (enable_op && quick_stop_option >= 5 && quick_stop_option <= 8)
        return Cia402State::kOperationEnabled;
      return s;
    case Cia402State::kFaultReactionActive: return ramp_done ? Cia402State::kFault : s;
    case Cia402State::kFault: return reset_edge ? Cia402State::kSwitchOnDisabled : s;
    case Cia402State::kUnknown: return s;
  }
  return s;
}

// ---------------------------------------------------------------- scaling
std::int32_t mm_to_counts_wrapped(double mm, double counts_per_mm) noexcept {
  const double c = std::round(mm * counts_per_mm);
  if (!std::isfinite(c)) return 0;
  // Wrap modulo 2^32 as the drive's 32-bit position register does.
  const double m = std::fmod(c, 4294967296.0);
  const auto u = static_cast<std::uint32_t>(static_cast<std::int64_t>(m < 0 ? m + 4294967296.0 : m));
  return static_cast<std::int32_t>(u);
}

std::int32_t mm_s_to_counts_s(double mm_s, double counts_per_mm) noexcept {
  const double c = std::round(mm_s * counts_per_mm);
  if (!(c == c)) return 0;
  if (c >= 2147483647.0) return std::numeric_limits<std::int32_t>::max();
  if (c <= -2147483648.0) return std::numeric_limits<std::int32_t>::min();
  return static_cast<std::int32_t>(c);
}

// ---------------------------------------------------------------- bus load
int frame_bits_nominal(int n) noexcept { return 47 + 8 * n; }
int frame_bits_worst(int n) noexcept { return 47 + 8 * n + (34 + 8 * n - 1) / 4; }

BusLoad estimate_bus_load(std::span<const CyclicFrame> frames, double bitrate_bps,
                          double period_s) noexcept {
  BusLoad r;
  if (bitrate_bps <= 0 || period_s <= 0) return r;
  double nom = 0, worst = 0, peak = 0, fpc = 0;
  for (const auto& f : frames) {
    const double every = f.every_n_cycles < 1 ? 1.0 : static_cast<double>(f.every_n_cycles);
    nom += frame_bits_nominal(f.data_bytes) / every;
    worst += frame_bits_worst(f.data_bytes) / every;
    peak += frame_bits_worst(f.data_bytes);
    fpc += 1.0 / every;
  }
  const double bits_per_cycle = bitrate_bps * period_s;
  r.nominal = nom / bits_per_cycle;
  r.worst_case = worst / bits_per_cycle;
  r.peak_cycle_worst = peak / bits_per_cycle;
  r.frames_per_cycle_avg_x1000 = static_cast<int>(std::lround(fpc * 1000.0));
  return r;
}

}  // namespace contour::drivers::canopen
