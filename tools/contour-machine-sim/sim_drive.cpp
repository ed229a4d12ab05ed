#include "tools/contour-machine-sim/sim_drive.hpp"

#include <algorithm>
#include <cmath>

namespace contour::sim {

using drivers::CanFrame;
namespace co = drivers::canopen;

namespace {
constexpr std::uint32_t key(std::uint16_t index, std::uint8_t sub) {
  return (static_cast<std::uint32_t>(index) << 8) | sub;
}
std::vector<std::uint8_t> le(std::int64_t v, std::size_t n) {
  std::vector<std::uint8_t> out(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<std::uint8_t>((static_cast<std::uint64_t>(v) >> (8 * i)) & 0xFF);
  return out;
}
bool rx_mappable(std::uint16_t i, std::uint8_t sub) {
  if (i == 0x6200 || i == 0x6411) return sub >= 1;  // CiA 401 outputs (I/O module)
  if (i == 0x60FE) return sub == 1;  // digital outputs, physical outputs
  return sub == 0 && (i == 0x6040 || i == 0x607A || i == 0x60FF || i == 0x6060 || i == 0x60B8);
}
bool tx_mappable(std::uint16_t i, std::uint8_t sub) {
  if (i == 0x6000 || i == 0x6401) return sub >= 1;  // CiA 401 inputs (I/O module)
  return sub == 0 &&
         (i == 0x6041 || i == 0x6064 || i == 0x606C || i == 0x6061 || i == 0x603F || i == 0x60FD ||
          i == 0x60B9 || i == 0x60BA);
}
}  // namespace

SimDrive::SimDrive(SimDriveSetup setup, Send send) : s_(std::move(setup)), send_(std::move(send)) {
  plant_.configure(s_.plant);
  build_od();
}

void SimDrive::build_od() {
  od_.clear();
  auto ro = [&](std::uint16_t i, std::uint8_t s, std::int64_t v, std::size_t n) {
    od_[key(i, s)] = Entry{le(v, n), false, true};
  };
  auto rw = [&](std::uint16_t i, std::uint8_t s, std::int64_t v, std::size_t n) {
    od_[key(i, s)] = Entry{le(v, n), true, true};
  };
  if (s_.io.enabled) {
    build_io_od();
    return;
  }
  ro(0x1000, 0, 0x00020192, 4);  // CiA 402, servo drive
  ro(0x1001, 0, 0, 1);
  const std::string name = "contour-machine-sim " + s_.name;
  od_[key(0x1008, 0)] = Entry{std::vector<std::uint8_t>(name.begin(), name.end()), false, true};
  ro(0x1018, 0, 4, 1);
  ro(0x1018, 1, s_.vendor_id, 4);
  ro(0x1018, 2, s_.product_code, 4);
  ro(0x1018, 3, s_.revision, 4);
  ro(0x1018, 4, s_.serial != 0 ? s_.serial : 0x1000 + s_.node_id, 4);
  rw(0x1006, 0, 0, 4);
  rw(0x1007, 0, 0, 4);
  ro(0x1016, 0, 1, 1);
  rw(0x1016, 1, 0, 4);
  rw(0x1017, 0, 0, 2);
  build_pdo_objects();
  // Power-on mapping (a drive's own default, deliberately not the master's choice): RPDO1
  // {controlword}, TPDO1 {statusword}; the master must remap.
  set_int(0x1600, 1, 0x60400010);
  set_int(0x1600, 0, 1);
  set_int(0x1A00, 1, 0x60410010);
  set_int(0x1A00, 0, 1);
  ro(0x603F, 0, 0, 2);
  rw(0x6040, 0, 0, 2);
  ro(0x6041, 0, co::statusword_for(state_), 2);
  rw(0x605A, 0, 2, 2);
  rw(0x6007, 0, 1, 2);  // abort connection option code: 1 = fault
  ro(0x1029, 0, 1, 1);
  rw(0x1029, 1, 0, 1);  // error behaviour, communication error: 0 = pre-operational
  rw(0x6060, 0, 0, 1);
  ro(0x6061, 0, 0, 1);
  ro(0x6064, 0, 0, 4);
  ro(0x606C, 0, 0, 4);
  rw(0x607A, 0, 0, 4);
  rw(0x60FF, 0, 0, 4);
  rw(0x6085, 0, 1000000, 4);
  // Homing (mode 6): method, speeds (:01 search for switch, :02 search for zero), acceleration,
  // home offset (counts the home point reads after homing).
  rw(0x6098, 0, 0, 1);
  ro(0x6099, 0, 2, 1);
  rw(0x6099, 1, 0, 4);
  rw(0x6099, 2, 0, 4);
  rw(0x609A, 0, 0, 4);
  rw(0x607C, 0, 0, 4);
  // CiA 402 digital inputs (limit/home switches, SimDriveSetup::switches) and outputs: 0x60FE:01
  // is what the master drives, :02 the mask of the bits it may drive (stored as written).
  ro(0x60FD, 0, 0, 4);
  ro(0x60FE, 0, 2, 1);
  rw(0x60FE, 1, 0, 4);
  rw(0x60FE, 2, 0, 4);
  // Touch probe 1 (the encoder index latch): function, status, positive-edge position.
  rw(0x60B8, 0, 0, 2);
  ro(0x60B9, 0, 0, 2);
  ro(0x60BA, 0, 0, 4);
  ro(0x60C2, 0, 2, 1);
  rw(0x60C2, 1, 1, 1);
  rw(0x60C2, 2, -3, 1);
  for (const auto& m : s_.quirks.missing) {
    for (auto it = od_.begin(); it != od_.end();) {
      const bool hit = (it->first >> 8) == m.index &&
                       (m.sub < 0 || static_cast<int>(it->first & 0xFF) == m.sub);
      it = hit ? od_.erase(it) : std::next(it);
    }
  }
  od_defaults_ = od_;
}

// PDO communication (0x1400/0x1800) and mapping (0x1600/0x1A00) objects, quirks.pdos of each
// with quirks.pdo_max_entries entries: PDO 1 valid, the others invalid until the master maps them.
// Shared by the drive's and the I/O module's dictionary.
void SimDrive::build_pdo_objects() {
  auto ro = [&](std::uint16_t i, std::uint8_t s, std::int64_t v, std::size_t n) {
    od_[key(i, s)] = Entry{le(v, n), false, true};
  };
  auto rw = [&](std::uint16_t i, std::uint8_t s, std::int64_t v, std::size_t n) {
    od_[key(i, s)] = Entry{le(v, n), true, true};
  };
  const auto pdos = static_cast<std::uint16_t>(std::clamp(s_.quirks.pdos, 1, 4));
  const auto entries = static_cast<std::uint8_t>(std::clamp(s_.quirks.pdo_max_entries, 1, 8));
  for (std::uint16_t k = 0; k < pdos; ++k) {
    const auto n = s_.node_id;
    ro(static_cast<std::uint16_t>(0x1400 + k), 0, 2, 1);
    rw(static_cast<std::uint16_t>(0x1400 + k), 1, (k == 0 ? 0 : 0x80000000LL) + co::kCobRpdo[k] + n, 4);
    rw(static_cast<std::uint16_t>(0x1400 + k), 2, 0xFF, 1);
    ro(static_cast<std::uint16_t>(0x1800 + k), 0, 2, 1);
    rw(static_cast<std::uint16_t>(0x1800 + k), 1, (k == 0 ? 0 : 0x80000000LL) + co::kCobTpdo[k] + n, 4);
    rw(static_cast<std::uint16_t>(0x1800 + k), 2, 0xFF, 1);
    rw(static_cast<std::uint16_t>(0x1600 + k), 0, 0, 1);
    rw(static_cast<std::uint16_t>(0x1A00 + k), 0, 0, 1);
    for (std::uint8_t e = 1; e <= entries; ++e) {
      rw(static_cast<std::uint16_t>(0x1600 + k), e, 0, 4);
      rw(static_cast<std::uint16_t>(0x1A00 + k), e, 0, 4);
    }
  }
}

// The communication objects of build_od() and the CiA 401 I/O objects (SimIoModule).
void SimDrive::build_io_od() {
  auto ro = [&](std::uint16_t i, std::uint8_t s, std::int64_t v, std::size_t n) {
    od_[key(i, s)] = Entry{le(v, n), false, true};
  };
  auto rw = [&](std::uint16_t i, std::uint8_t s, std::int64_t v, std::size_t n) {
    od_[key(i, s)] = Entry{le(v, n), true, true};
  };
  const SimIoModule& io = s_.io;
  const auto count = [](int n) { return std::clamp(n, 0, 8); };
  std::int64_t type = 401;
  if (count(io.digital_inputs) > 0) type |= 0x10000;
  if (count(io.digital_outputs) > 0) type |= 0x20000;
  if (count(io.analog_inputs) > 0) type |= 0x40000;
  if (count(io.analog_outputs) > 0) type |= 0x80000;
  ro(0x1000, 0, type, 4);
  ro(0x1001, 0, 0, 1);
  const std::string name = "contour-machine-sim I/O " + std::to_string(s_.node_id);
  od_[key(0x1008, 0)] = Entry{std::vector<std::uint8_t>(name.begin(), name.end()), false, true};
  ro(0x1018, 0, 4, 1);
  ro(0x1018, 1, s_.vendor_id, 4);
  ro(0x1018, 2, 401, 4);
  ro(0x1018, 3, s_.revision, 4);
  ro(0x1018, 4, 0x1000 + s_.node_id, 4);
  rw(0x1006, 0, 0, 4);
  ro(0x1016, 0, 1, 1);
  rw(0x1016, 1, 0, 4);
  rw(0x1017, 0, 0, 2);
  ro(0x1029, 0, 1, 1);
  rw(0x1029, 1, 0, 1);
  build_pdo_objects();
  auto objects = [&](std::uint16_t index, int n, std::size_t bytes, bool writable) {
    if (n <= 0) return;
    ro(index, 0, n, 1);
    for (int k = 1; k <= n; ++k) {
      od_[key(index, static_cast<std::uint8_t>(k))] = Entry{le(0, bytes), writable, true};
    }
  };
  objects(0x6000, count(io.digital_inputs), 1, false);
  objects(0x6200, count(io.digital_outputs), 1, true);
  objects(0x6401, count(io.analog_inputs), 2, false);
  objects(0x6411, count(io.analog_outputs), 2, true);
  for (const auto& [sub, v] : io.fixed_inputs) set_int(0x6000, static_cast<std::uint8_t>(sub), v);
  // Power-on mapping (CiA 401's own default, not the master's choice): RPDO1 {0x6200:01},
  // TPDO1 {0x6000:01} when present; the master remaps.
  if (count(io.digital_outputs) > 0) {
    set_int(0x1600, 1, 0x62000108);
    set_int(0x1600, 0, 1);
  }
  if (count(io.digital_inputs) > 0) {
    set_int(0x1A00, 1, 0x60000108);
    set_int(0x1A00, 0, 1);
  }
  for (const auto& m : s_.quirks.missing) {
    for (auto it = od_.begin(); it != od_.end();) {
      const bool hit =
          (it->first >> 8) == m.index && (m.sub < 0 || static_cast<int>(it->first & 0xFF) == m.sub);
      it = hit ? od_.erase(it) : std::next(it);
    }
  }
  od_defaults_ = od_;
}

std::vector<std::int64_t> SimDrive::io_values(std::uint16_t index) const {
  std::vector<std::int64_t> v;
  for (int k = 1; k <= 8; ++k) {
    if (od_.count(key(index, static_cast<std::uint8_t>(k))) == 0) break;
    const std::int64_t x = read_int(index, static_cast<std::uint8_t>(k));
    v.push_back(index == 0x6000 || index == 0x6200 ? (x & 0xFF) : x);
  }
  return v;
}

void SimDrive::io_loopback() {
  for (int k = 1; k <= 8; ++k) {
    const auto sub = static_cast<std::uint8_t>(k);
    bool fixed = false;
    for (const auto& f : s_.io.fixed_inputs) fixed = fixed || f.first == k;
    if (!fixed && od_.count(key(0x6000, sub)) != 0 && od_.count(key(0x6200, sub)) != 0)
      set_int(0x6000, sub, read_int(0x6200, sub));
    if (od_.count(key(0x6401, sub)) != 0 && od_.count(key(0x6411, sub)) != 0)
      set_int(0x6401, sub, read_int(0x6411, sub));
  }
}

SimDrive::Entry* SimDrive::find(std::uint16_t index, std::uint8_t sub) {
  auto it = od_.find(key(index, sub));
  return it == od_.end() ? nullptr : &it->second;
}

std::int64_t SimDrive::read_int(std::uint16_t index, std::uint8_t sub) const {
  auto it = od_.find(key(index, sub));
  if (it == od_.end()) return 0;
  std::uint64_t v = 0;
  const auto& b = it->second.value;
  for (std::size_t i = 0; i < b.size() && i < 8; ++i) v |= static_cast<std::uint64_t>(b[i]) << (8 * i);
  // sign-extend to the object's width
  const std::size_t bits = 8 * b.size();
  if (bits > 0 && bits < 64 && (v >> (bits - 1)) != 0) v |= ~0ULL << bits;
  return static_cast<std::int64_t>(v);
}
std::int64_t SimDrive::read_int_or(std::uint16_t index, std::uint8_t sub,
                                  std::int64_t fixed) const {
  return od_.count(key(index, sub)) != 0 ? read_int(index, sub) : fixed;
}
std::uint32_t SimDrive::u32(std::uint16_t index, std::uint8_t sub) const {
  return static_cast<std::uint32_t>(read_int(index, sub) & 0xFFFFFFFF);
}
void SimDrive::set_int(std::uint16_t index, std::uint8_t sub, std::int64_t v) {
  auto it = od_.find(key(index, sub));
  if (it == od_.end()) return;
  it->second.value = le(v, it->second.value.size());
}

void SimDrive::power_on() {
  od_ = od_defaults_;
  state_ = co::Cia402State::kSwitchOnDisabled;
  set_int(0x6041, 0, co::statusword_for(state_));
  injected_fault_.reset();
  injected_fault_latched_ = false;  // an application reset clears the fault without an EMCY
  tp_fn_ = 0;
  tp_watch_ = false;
  reset_communication();
}

void SimDrive::reset_communication() {
  for (auto& [k, e] : od_)
    if ((k >> 8) >= 0x1000 && (k >> 8) < 0x2000) e = od_defaults_.at(k);
  nmt_ = co::NmtState::kPreOperational;
  master_hb_armed_ = false;
  syncs_ = 0;
  rx_latched_ = false;
  rx_do_.reset();
  rx_tp_.reset();
  seg_upload_ = seg_download_ = false;
  storm_drop_left_ = 0;  // a rebooted communication layer forgets injected PDO/heartbeat gaps
  hb_gap_left_ = 0;
  send_(co::heartbeat_frame(s_.node_id, co::NmtState::kBootUp));
}

void SimDrive::heartbeat() {
  if (s_.faults.stop_heartbeat_at >= 0 && syncs_ >= s_.faults.stop_heartbeat_at) return;
  if (hb_gap_left_ > 0) return;
  send_(co::heartbeat_frame(s_.node_id, nmt_));
}

void SimDrive::on_master_heartbeat(const CanFrame& f) {
  const std::uint32_t c = u32(0x1016, 1);
  const auto node = static_cast<std::uint8_t>((c >> 16) & 0x7F);
  if ((c & 0xFFFF) == 0 || node == 0 || f.id != co::kCobHeartbeat + node || f.dlc != 1) return;
  master_hb_armed_ = true;
  master_hb_sync_ = syncs_;
  master_hb_wall_ns_ = now_wall_ns_;
}

void SimDrive::master_heartbeat_lost() {
  master_hb_armed_ = false;  // one event per loss; re-armed by the next heartbeat
  co::Emcy e;
  e.code = 0x8130;
  e.error_register = 0x11;  // generic + communication
  send_(co::emcy_frame(s_.node_id, e));
  switch (read_int(0x6007, 0)) {
    case 1:
      if (state_ != co::Cia402State::kFault && state_ != co::Cia402State::kFaultReactionActive &&
          state_ != co::Cia402State::kSwitchOnDisabled &&
          state_ != co::Cia402State::kNotReadyToSwitchOn) {
        state_ = co::Cia402State::kFaultReactionActive;
        set_int(0x603F, 0, 0x8130);
        set_int(0x1001, 0, 0x11);
      }
      break;
    case 2:
      if (state_ != co::Cia402State::kFault && state_ != co::Cia402State::kFaultReactionActive)
        state_ = co::Cia402State::kSwitchOnDisabled;
      break;
    case 3:
      if (state_ == co::Cia402State::kOperationEnabled) state_ = co::Cia402State::kQuickStopActive;
      break;
    default:
      break;
  }
  const auto behaviour = read_int(0x1029, 1);
  if (behaviour == 0 && nmt_ == co::NmtState::kOperational) nmt_ = co::NmtState::kPreOperational;
  if (behaviour == 2) nmt_ = co::NmtState::kStopped;
  if (nmt_ != co::NmtState::kOperational) heartbeat();  // the state change is visible at once
}

void SimDrive::tick_wall(std::int64_t now_ns) {
  now_wall_ns_ = now_ns;
  if (master_hb_armed_ && s_.quirks.wall_clock_consumer) {
    const std::int64_t t_ns = static_cast<std::int64_t>(u32(0x1016, 1) & 0xFFFF) * 1000000LL;
    if (now_ns - master_hb_wall_ns_ > t_ns) master_heartbeat_lost();
  } else if (master_hb_armed_) {
    // SYNC stopped too (the master process is gone or frozen): the consumer falls back to the
    // wall clock, but only after max(5 x consumer time, 2 s) of silence. While SYNC flows the
    // consumer is lockstep (on_sync); a master merely descheduled for a few hundred ms on a
    // loaded VM (seen: > 300 ms while compiling) must not trip it, or lockstep results would
    // depend on scheduling.
    const std::int64_t t_ns = static_cast<std::int64_t>(u32(0x1016, 1) & 0xFFFF) * 1000000LL;
    const std::int64_t quiet_ns = std::max<std::int64_t>(5 * t_ns, 2000000000LL);
    if (now_ns - last_sync_wall_ns_ > quiet_ns && now_ns - master_hb_wall_ns_ > quiet_ns)
      master_heartbeat_lost();
  }
  const auto hb_ms = read_int(0x1017, 0);
  if (hb_ms <= 0) return;
  // In operational with SYNC flowing the heartbeat is lockstep (on_sync); otherwise wall-clock.
  const bool lockstep = nmt_ == co::NmtState::kOperational && now_ns - last_sync_wall_ns_ < 500000000LL;
  if (lockstep) return;
  if (now_ns - last_hb_ns_ >= hb_ms * 1000000LL) {
    last_hb_ns_ = now_ns;
    heartbeat();
  }
}

void SimDrive::on_frame(const CanFrame& f) {
  if (f.error || f.rtr || f.extended) return;
  if (f.id == co::kCobNmt) {
    if (f.dlc != 2 || (f.data[1] != 0 && f.data[1] != s_.node_id)) return;
    switch (f.data[0]) {
      case 0x01: nmt_ = co::NmtState::kOperational; syncs_ = 0; break;
      case 0x02: nmt_ = co::NmtState::kStopped; break;
      case 0x80: nmt_ = co::NmtState::kPreOperational; break;
      case 0x81: power_on(); break;
      case 0x82: reset_communication(); break;
      default: break;
    }
    return;
  }
  if (f.id > co::kCobHeartbeat && f.id <= co::kCobHeartbeat + 127) {
    on_master_heartbeat(f);
    return;
  }
  if (nmt_ == co::NmtState::kStopped) return;
  if (f.id == co::kCobSync) {
    // Pre-operational after a communication error: the plant keeps stepping, no PDOs.
    if (nmt_ == co::NmtState::kOperational || syncs_ > 0) on_sync();
    return;
  }
  if (f.id == co::kCobSdoRx + s_.node_id) {
    on_sdo(f);
    return;
  }
  if (nmt_ != co::NmtState::kOperational) return;
  const auto pdos = static_cast<std::uint16_t>(std::clamp(s_.quirks.pdos, 1, 4));
  for (std::uint16_t k = 0; k < pdos; ++k) {
    const std::uint32_t cob = u32(static_cast<std::uint16_t>(0x1400 + k), 1);
    if ((cob & 0x80000000u) == 0 && f.id == (cob & 0x7FF)) {
      on_rpdo(f, k);
      return;
    }
  }
}

co::PdoMapping SimDrive::mapping(bool rx, std::uint16_t pdo) const {
  co::PdoMapping m;
  const auto mi = static_cast<std::uint16_t>((rx ? 0x1600 : 0x1A00) + pdo);
  m.count = static_cast<std::size_t>(std::min<std::int64_t>(8, read_int(mi, 0) & 0xFF));
  for (std::size_t k = 0; k < m.count; ++k)
    m.entries[k] = co::PdoEntry::from_word(u32(mi, static_cast<std::uint8_t>(k + 1)));
  return m;
}

void SimDrive::on_rpdo(const CanFrame& f, std::uint16_t pdo) {
  const auto m = mapping(true, pdo);
  co::PdoValues v{};
  if (f.dlc < m.bytes() || !co::unpack_pdo(m, f, v)) {
    // CiA 301: a too-short RPDO is not processed; the drive reports 0x8210.
    co::Emcy e;
    e.code = 0x8210;
    e.error_register = 0x10;
    send_(co::emcy_frame(s_.node_id, e));
    return;
  }
  for (std::size_t k = 0; k < m.count; ++k) {
    const auto idx = m.entries[k].index;
    if (idx == 0x6040) rx_cw_ = static_cast<std::uint16_t>(v[k]);
    else if (idx == 0x60FF || idx == 0x607A) rx_target_ = co::as_i32(v[k]);
    else if (idx == 0x6060) set_int(0x6060, 0, static_cast<std::int8_t>(v[k] & 0xFF));
    else if (idx == 0x60FE) rx_do_ = static_cast<std::uint32_t>(v[k] & 0xFFFFFFFF);
    else if (idx == 0x60B8) rx_tp_ = static_cast<std::uint16_t>(v[k] & 0xFFFF);
    else if (s_.io.enabled && (idx == 0x6200 || idx == 0x6411))
      set_int(idx, m.entries[k].sub, v[k]);
  }
  // RPDO1 carries the controlword: only it latches the drive's command.
  if (m.find(0x6040) >= 0) rx_latched_ = true;
}

void SimDrive::raise_fault(std::uint16_t code) {
  state_ = co::Cia402State::kFaultReactionActive;
  set_int(0x603F, 0, code);
  set_int(0x1001, 0, 0x03);  // generic + current
  co::Emcy e;
  e.code = code;
  e.error_register = 0x03;
  send_(co::emcy_frame(s_.node_id, e));
}

void SimDrive::on_sync() {
  ++syncs_;
  last_sync_wall_ns_ = now_wall_ns_;
  if (master_hb_armed_ && !s_.quirks.wall_clock_consumer) {
    const long t_ms = static_cast<long>(u32(0x1016, 1) & 0xFFFF);
    const long limit =
        std::max<long>(1, std::lround(static_cast<double>(t_ms) * 1e-3 / s_.period_s));
    if (syncs_ - master_hb_sync_ > limit) master_heartbeat_lost();
  }
  auto lockstep_heartbeat = [&] {
    const auto hb_ms = read_int(0x1017, 0);
    if (hb_ms > 0 && nmt_ == co::NmtState::kOperational) {
      const long every =
          std::max<long>(1, std::lround(static_cast<double>(hb_ms) * 1e-3 / s_.period_s));
      if (syncs_ % every == 0) heartbeat();
    }
    if (hb_gap_left_ > 0) --hb_gap_left_;  // counted in SYNCs: the gap pauses when SYNC stops
  };
  if (s_.io.enabled) {
    // A CiA 401 module: outputs looped to the inputs, then the TPDOs of this SYNC.
    if (nmt_ == co::NmtState::kOperational) io_loopback();
    sample_and_transmit();
    lockstep_heartbeat();
  } else if (s_.quirks.tpdo_after_step) {
    apply_and_step();
    sample_and_transmit();
    lockstep_heartbeat();
  } else {
    sample_and_transmit();
    lockstep_heartbeat();
    apply_and_step();
  }
}

void SimDrive::sample_and_transmit() {
  const auto& fl = s_.faults;
  const bool operational = nmt_ == co::NmtState::kOperational;
  // sample and transmit (values of the state reached by the last step)
  const std::int64_t pos_counts =
      s_.spindle ? std::llround(spindle_rev_ * s_.counts_per_mm)
                 : std::llround(plant_.position_mm() * s_.counts_per_mm) - pos_zero_counts_;
  set_int(0x6064, 0, static_cast<std::int32_t>(static_cast<std::uint32_t>(pos_counts & 0xFFFFFFFF)));
  set_int(0x606C, 0, s_.spindle ? std::llround(spindle_rpm_)
                                : std::llround(plant_.velocity_mm_s() * s_.counts_per_mm));
  std::uint16_t sw = co::statusword_for(state_);
  const bool homing_mode = !s_.spindle && static_cast<std::int8_t>(read_int(0x6061, 0)) == 6;
  if (state_ == co::Cia402State::kOperationEnabled && homing_mode) {
    // CiA 402 homing: 13 error, 12 attained, 10 target reached (stopped / not started).
    const bool still = home_v_mm_s_ == 0.0;
    switch (home_stage_) {
      case HomeStage::kNotStarted:
      case HomeStage::kInterrupted: sw |= 0x0400; break;
      case HomeStage::kAttained: sw |= 0x1400; break;
      case HomeStage::kError: sw |= still ? 0x2400 : 0x2000; break;
      default: break;  // in progress
    }
  } else if (state_ == co::Cia402State::kOperationEnabled) {
    sw |= 0x1000;  // follows the command
  }
  set_int(0x6041, 0, sw);
  if (!s_.spindle) {
    std::uint32_t di = 0;
    di = inputs_at(plant_.position_mm());
    set_int(0x60FD, 0, di);
  }
  const auto tx_type = read_int(0x1800, 2) & 0xFF;
  const bool tx_valid = (u32(0x1800, 1) & 0x80000000u) == 0;
  const bool dropping = fl.drop_tpdo_from >= 0 && syncs_ >= fl.drop_tpdo_from &&
                        (fl.drop_tpdo_count == 0 || syncs_ < fl.drop_tpdo_from + fl.drop_tpdo_count);
  const bool tx_due =
      operational && tx_valid && tx_type >= 1 && tx_type <= 240 && syncs_ % tx_type == 0;
  // Only a TPDO that was due counts as dropped: that is exactly one missed TPDO for the master.
  bool withheld = false;
  if (tx_due && dropping) {
    withheld = true;
  } else if (tx_due && storm_drop_left_ > 0) {
    --storm_drop_left_;
    withheld = true;
  }
  if (withheld) ++tpdo_dropped_;
  const bool dropping2 = fl.drop_tpdo2_from >= 0 && syncs_ >= fl.drop_tpdo2_from &&
                         (fl.drop_tpdo2_count == 0 || syncs_ < fl.drop_tpdo2_from + fl.drop_tpdo2_count);
  if (tx_due && !withheld) {
    // TPDO1, then the other valid TPDOs of this transmission type (the master's TPDO2: 0x60FD);
    // a withheld SYNC withholds them all (one missed TPDO for the master).
    const auto pdos = static_cast<std::uint16_t>(std::clamp(s_.quirks.pdos, 1, 4));
    for (std::uint16_t p = 0; p < pdos; ++p) {
      const auto comm = static_cast<std::uint16_t>(0x1800 + p);
      if ((u32(comm, 1) & 0x80000000u) != 0) continue;
      if (p > 0) {
        if (dropping2) continue;
        const auto t = read_int(comm, 2) & 0xFF;
        if (t < 1 || t > 240 || syncs_ % t != 0) continue;
      }
      const auto m = mapping(false, p);
      co::PdoValues v{};
      for (std::size_t k = 0; k < m.count; ++k) v[k] = read_int(m.entries[k].index, m.entries[k].sub);
      CanFrame f;
      f.id = u32(comm, 1) & 0x7FF;
      co::pack_pdo(m, v, f);
      send_(f);
    }
  }
  if (fl.malformed_at >= 0 && syncs_ == fl.malformed_at) {
    CanFrame f;
    f.id = co::kCobTpdo[0] + s_.node_id;  // TPDO shorter than its mapping
    f.dlc = 1;
    send_(f);
    f.id = co::kCobEmcy + s_.node_id;  // EMCY must be 8 bytes
    f.dlc = 3;
    send_(f);
    f.id = co::kCobHeartbeat + s_.node_id;  // heartbeat must be 1 byte
    f.dlc = 2;
    send_(f);
    f.id = co::kCobSdoTx + s_.node_id;  // SDO response nobody asked for
    f.dlc = 8;
    send_(f);
    f.id = 0x7E5;  // LSS, not used by this master
    f.dlc = 8;
    send_(f);
  }
}

void SimDrive::apply_and_step() {
  const auto& fl = s_.faults;
  // apply the RPDO latched since the previous SYNC
  if (fl.fault_at >= 0 && syncs_ == fl.fault_at && state_ != co::Cia402State::kFault) raise_fault(fl.fault_code);
  if (injected_fault_) {
    if (state_ != co::Cia402State::kFault && state_ != co::Cia402State::kFaultReactionActive) {
      raise_fault(*injected_fault_);
      injected_fault_latched_ = true;
      ++injected_emcy_sent_;
    }
    injected_fault_.reset();
  }
  if (motion_started_at_ < 0 && state_ == co::Cia402State::kOperationEnabled && rx_latched_ &&
      rx_target_ != 0)
    motion_started_at_ = syncs_;
  if (fl.fault_after_motion >= 0 && motion_started_at_ >= 0 &&
      syncs_ == motion_started_at_ + fl.fault_after_motion && state_ != co::Cia402State::kFault)
    raise_fault(fl.fault_code);
  const std::uint16_t cw = rx_latched_ ? rx_cw_ : cw_;
  prev_cw_ = cw_;
  cw_ = cw;
  rx_latched_ = false;
  set_int(0x6040, 0, cw);
  if (rx_do_) {
    set_int(0x60FE, 1, *rx_do_);
    rx_do_.reset();
  }
  if (rx_tp_) {
    set_int(0x60B8, 0, *rx_tp_);
    rx_tp_.reset();
  }
  touch_probe_apply();
  const double x_before_mm = plant_.position_mm();
  const double T = s_.period_s;
  const double decel_mm_s2 =
      static_cast<double>(read_int_or(0x6085, 0, 1000000) & 0xFFFFFFFF) / s_.counts_per_mm;
  const bool ramping = state_ == co::Cia402State::kQuickStopActive ||
                       state_ == co::Cia402State::kFaultReactionActive;
  const bool ramp_done = ramping && std::abs(v_cmd_mm_s_) < 1e-12;
  const auto before = state_;
  state_ = co::drive_transition(state_, cw, prev_cw_, static_cast<int>(read_int_or(0x605A, 0, 2)), ramp_done);
  if (before == co::Cia402State::kFault && state_ != co::Cia402State::kFault) {
    set_int(0x603F, 0, 0);
    set_int(0x1001, 0, 0);
    send_(co::emcy_frame(s_.node_id, co::Emcy{}));  // error reset
    if (injected_fault_latched_) ++injected_emcy_sent_;
    injected_fault_latched_ = false;
  }
  // step the plant one period
  const std::int8_t mode = static_cast<std::int8_t>(read_int(0x6061, 0));
  if (s_.spindle) {
    double target = state_ == co::Cia402State::kOperationEnabled ? static_cast<double>(rx_target_) : 0.0;
    if (state_ != co::Cia402State::kOperationEnabled) target = 0.0;
    const double a = std::exp(-T / std::max(1e-6, s_.spindle_tau_s));
    spindle_rpm_ = a * spindle_rpm_ + (1.0 - a) * target;
    spindle_rev_ += spindle_rpm_ / 60.0 * T;
    return;
  }
  switch (state_) {
    case co::Cia402State::kOperationEnabled:
      if (mode == 6) {
        step_homing(cw);
        v_cmd_mm_s_ = home_v_mm_s_;
        plant_.step_velocity(v_cmd_mm_s_);
      } else if (mode == 8) {
        // CSP: the drive closes its own position loop; the plant command is the position error.
        plant_.step(static_cast<double>(rx_target_ + pos_zero_counts_) / s_.counts_per_mm - plant_.measured_mm());
        v_cmd_mm_s_ = plant_.velocity_mm_s();
      } else {
        v_cmd_mm_s_ = static_cast<double>(rx_target_) / s_.counts_per_mm;
        plant_.step_velocity(v_cmd_mm_s_);
      }
      break;
    case co::Cia402State::kQuickStopActive:
    case co::Cia402State::kFaultReactionActive: {
      if (before != co::Cia402State::kQuickStopActive && before != co::Cia402State::kFaultReactionActive)
        v_cmd_mm_s_ = plant_.velocity_mm_s();
      const double dv = decel_mm_s2 * T;
      v_cmd_mm_s_ = std::abs(v_cmd_mm_s_) <= dv ? 0.0 : v_cmd_mm_s_ - std::copysign(dv, v_cmd_mm_s_);
      plant_.step_velocity(v_cmd_mm_s_);
      break;
    }
    default:
      v_cmd_mm_s_ = 0.0;
      plant_.step(0.0);  // velocity loop holds zero speed (brake)
      break;
  }
  touch_probe_watch(x_before_mm, plant_.position_mm());
  if (state_ != co::Cia402State::kOperationEnabled || mode != 6) {
    // Homing only runs in operation enabled, mode 6: anything else interrupts it.
    if (home_stage_ != HomeStage::kNotStarted && home_stage_ != HomeStage::kAttained &&
        home_stage_ != HomeStage::kError)
      home_stage_ = HomeStage::kInterrupted;
    home_v_mm_s_ = 0.0;
  }
}

void SimDrive::touch_probe_apply() {
  const auto fn = static_cast<std::uint16_t>(read_int_or(0x60B8, 0, 0) & 0xFFFF);
  const std::uint16_t prev = tp_fn_;
  tp_fn_ = fn;
  if (find(0x60B9, 0) == nullptr) return;
  if ((fn & co::kTouchProbe1Enable) == 0) {
    set_int(0x60B9, 0, 0);  // touch probe 1 off: its status is cleared
    tp_watch_ = false;
    return;
  }
  auto st = static_cast<std::uint16_t>((read_int(0x60B9, 0) & 0xFFFF) | co::kTouchProbe1Enabled);
  const bool positive = (fn & co::kTouchProbe1PositiveEdge) != 0;
  const bool edge = positive && ((prev & co::kTouchProbe1Enable) == 0 ||
                                 (prev & co::kTouchProbe1PositiveEdge) == 0);
  if (!positive || edge) st = static_cast<std::uint16_t>(st & ~co::kTouchProbe1PositiveStored);
  if (!positive) tp_watch_ = false;
  if (edge) tp_watch_ = (fn & co::kTouchProbe1TriggerMask) == co::kTouchProbe1TriggerIndex;
  set_int(0x60B9, 0, st);
}

void SimDrive::touch_probe_watch(double x0, double x1) {
  const double pitch = s_.index_pitch_mm;
  if (!tp_watch_ || !(pitch > 0.0) || s_.spindle || x0 == x1) return;
  const double phase = s_.index_phase_mm;
  // The first pulse past x0 in the direction of motion; crossed if the step reaches it.
  const bool up = x1 > x0;
  const double k = up ? std::floor((x0 - phase) / pitch) + 1.0 : std::ceil((x0 - phase) / pitch) - 1.0;
  const double at = phase + k * pitch;
  if (up ? at > x1 : at < x1) return;
  const std::int64_t counts = std::llround(at * s_.counts_per_mm) - pos_zero_counts_;
  set_int(0x60BA, 0, static_cast<std::int32_t>(static_cast<std::uint32_t>(counts & 0xFFFFFFFF)));
  set_int(0x60B9, 0, (read_int(0x60B9, 0) & 0xFFFF) | co::kTouchProbe1PositiveStored);
  ++tp_latches_;
  tp_last_index_mm_ = at;
  if ((tp_fn_ & co::kTouchProbe1Continuous) == 0) tp_watch_ = false;  // first event only
}

std::uint32_t SimDrive::inputs_at(double x) const {
  std::uint32_t di = 0;
  for (const auto& w : s_.switches)
    if (w.bit >= 0 && w.bit < 32 && (w.on_above ? x > w.threshold_mm : x < w.threshold_mm))
      di |= 1u << w.bit;
  return di;
}

void SimDrive::home_here(double x_mm) {
  // 0x6064 reads the home offset (0x607C) here from now on.
  pos_zero_counts_ = std::llround(x_mm * s_.counts_per_mm) - static_cast<std::int32_t>(read_int(0x607C, 0));
}

// One period of homing mode 6 on the drive's own profile (0x609A), speeds 0x6099:01 (to the
// switch) and :02 (off it / on to it slowly). Home is where the switch opens as the axis leaves it
// (17, 18, 19, 21) or where it closes on the slow approach after backing off (20, 22); 35/37:
// here. A limit switch ahead that is not the target is a homing error (the drive stops).
void SimDrive::step_homing(std::uint16_t cw) {
  const bool start = (cw & 0x10u) != 0 && (prev_cw_ & 0x10u) == 0;
  const bool halt = (cw & 0x10u) == 0;
  const double cpm = s_.counts_per_mm;
  const double search = static_cast<double>(u32(0x6099, 1)) / cpm;
  const double latch = static_cast<double>(u32(0x6099, 2)) / cpm;
  const double acc = std::max(1.0, static_cast<double>(u32(0x609A, 0))) / cpm;
  const int method = static_cast<int>(static_cast<std::int8_t>(read_int(0x6098, 0)));
  const double x = plant_.position_mm();
  if (start) {
    home_v_mm_s_ = 0.0;
    if (method == 35 || method == 37) {
      home_here(x);
      home_stage_ = HomeStage::kBrake;
      home_after_brake_ = HomeStage::kAttained;
    } else if (method >= 17 && method <= 22 && search > 0.0 && latch > 0.0) {
      home_stage_ = HomeStage::kSearch;
    } else {
      home_stage_ = HomeStage::kError;  // a method this drive does not have, or no speeds
    }
  } else if (halt && home_stage_ != HomeStage::kNotStarted && home_stage_ != HomeStage::kAttained &&
             home_stage_ != HomeStage::kError) {
    home_stage_ = HomeStage::kInterrupted;
  }
  int bit = 2;
  double side = -1.0;
  bool leave = true;
  switch (method) {
    case 17: bit = 0; break;
    case 18: bit = 1; side = 1.0; break;
    case 19: side = 1.0; break;
    case 20: side = 1.0; leave = false; break;
    case 22: leave = false; break;
    default: break;
  }
  const std::uint32_t di = inputs_at(x);
  const bool sw = (di >> bit & 1u) != 0;
  double v_target = 0.0;
  switch (home_stage_) {
    case HomeStage::kSearch:
      if (sw) {
        home_stage_ = HomeStage::kBrake;
        home_after_brake_ = HomeStage::kAway;
      } else {
        v_target = side * search;
      }
      break;
    case HomeStage::kAway:
      if (!sw) {
        if (leave) home_here(x);
        home_stage_ = HomeStage::kBrake;
        home_after_brake_ = leave ? HomeStage::kAttained : HomeStage::kApproach;
      } else {
        v_target = -side * latch;
      }
      break;
    case HomeStage::kApproach:
      if (sw) {
        home_here(x);
        home_stage_ = HomeStage::kBrake;
        home_after_brake_ = HomeStage::kAttained;
      } else {
        v_target = side * latch;
      }
      break;
    case HomeStage::kBrake:
      if (home_v_mm_s_ == 0.0 && std::abs(plant_.velocity_mm_s()) < 0.05) home_stage_ = home_after_brake_;
      break;
    default: break;
  }
  const bool moving = home_stage_ == HomeStage::kSearch || home_stage_ == HomeStage::kAway ||
                      home_stage_ == HomeStage::kApproach;
  if (moving && ((v_target < 0.0 && (di & 1u) != 0 && bit != 0) || (v_target > 0.0 && (di & 2u) != 0 && bit != 1))) {
    home_stage_ = HomeStage::kError;
  }
  const double dv = acc * s_.period_s;
  home_v_mm_s_ = v_target > home_v_mm_s_ ? std::min(v_target, home_v_mm_s_ + dv)
                                         : std::max(v_target, home_v_mm_s_ - dv);
}

// ------------------------------------------------------------------ SDO server
void SimDrive::send_sdo(std::uint8_t cs, std::uint16_t index, std::uint8_t sub,
                        const std::uint8_t* d, std::size_t n) {
  CanFrame f;
  f.id = co::kCobSdoTx + s_.node_id;
  f.dlc = 8;
  f.data[0] = cs;
  co::put_u16(&f.data[1], index);
  f.data[3] = sub;
  for (std::size_t i = 0; i < n && i < 4; ++i) f.data[4 + i] = d[i];
  send_(f);
}

void SimDrive::abort(std::uint16_t index, std::uint8_t sub, std::uint32_t code) {
  seg_upload_ = seg_download_ = false;
  send_(co::sdo_abort_frame(s_.node_id, true, index, sub, code));
}

bool SimDrive::pdo_mapping_ok(bool rx, std::uint8_t count, std::uint16_t map_index,
                              std::uint32_t& code) const {
  int bits = 0;
  for (std::uint8_t k = 1; k <= count; ++k) {
    const auto e = co::PdoEntry::from_word(u32(map_index, k));
    if (!(rx ? rx_mappable(e.index, e.sub) : tx_mappable(e.index, e.sub))) {
      code = od_.count(key(e.index, e.sub)) != 0 ? 0x06040041 : 0x06020000;
      return false;
    }
    const auto it = od_.find(key(e.index, e.sub));
    if (it == od_.end()) {
      code = 0x06020000;
      return false;
    }
    if (static_cast<std::size_t>(e.bits) != 8 * it->second.value.size()) {
      code = 0x06040043;
      return false;
    }
    bits += e.bits;
  }
  if (bits > 64) {
    code = 0x06040042;
    return false;
  }
  return true;
}

std::optional<std::uint32_t> SimDrive::write_object(std::uint16_t index, std::uint8_t sub,
                                                    const std::vector<std::uint8_t>& data) {
  Entry* e = find(index, sub);
  if (e == nullptr) {
    bool any = false;
    for (const auto& [k, v] : od_)
      if ((k >> 8) == index) any = true;
    return any ? 0x06090011u : 0x06020000u;
  }
  if (!e->writable) return 0x06010002u;
  if (data.size() != e->value.size()) return data.size() > e->value.size() ? 0x06070012u : 0x06070013u;
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < data.size() && i < 4; ++i) v |= static_cast<std::uint32_t>(data[i]) << (8 * i);
  const bool is_comm = (index >= 0x1400 && index <= 0x1403) || (index >= 0x1800 && index <= 0x1803);
  const bool is_map = (index >= 0x1600 && index <= 0x1603) || (index >= 0x1A00 && index <= 0x1A03);
  if (is_comm && sub == 1) {
    const std::uint32_t cur = u32(index, 1);
    const bool cur_valid = (cur & 0x80000000u) == 0, new_valid = (v & 0x80000000u) == 0;
    // CiA 301: the COB-ID may only change while the PDO is invalid.
    if (cur_valid && new_valid && (cur & 0x7FF) != (v & 0x7FF)) return 0x06090030u;
    if ((v & 0x7FF) == 0 || (v & 0x20000000u) != 0) return 0x06090030u;
  }
  if (is_comm && sub == 2 && !(v <= 240 || v >= 254)) return 0x06090030u;
  if (is_map) {
    const std::uint16_t comm = static_cast<std::uint16_t>(index - 0x200);
    if ((u32(comm, 1) & 0x80000000u) == 0) return 0x08000022u;  // PDO still valid
    if (sub == 0) {
      if (v > 8) return 0x06090031u;
      std::uint32_t code = 0;
      if (v > 0 && !pdo_mapping_ok(index < 0x1A00, static_cast<std::uint8_t>(v), index, code)) return code;
    } else if ((read_int(index, 0) & 0xFF) != 0) {
      return 0x08000022u;  // entries change only while sub 0 is 0
    }
  }
  if (index == 0x6060) {
    const auto m = static_cast<std::int8_t>(v & 0xFF);
    const bool homing = !s_.spindle && m == 6 && find(0x6098, 0) != nullptr;
    const bool ok = s_.spindle ? (m == 3 || m == 9) : (m == 8 || m == 9 || homing);
    if (!ok) return 0x06090030u;
    // Into and out of homing in operation enabled (as CiA 402 drives allow); other changes only
    // with the power stage off.
    const auto cur = static_cast<std::int8_t>(read_int(0x6061, 0));
    if (state_ == co::Cia402State::kOperationEnabled && m != 6 && cur != 6) return 0x08000022u;
  }
  if (index == 0x605A && static_cast<std::int16_t>(v & 0xFFFF) > 8) return 0x06090030u;
  if (index == 0x6098) {
    const int m = static_cast<int>(static_cast<std::int8_t>(v & 0xFF));
    if (!((m >= 17 && m <= 22) || m == 35 || m == 37)) return 0x06090030u;  // value range
  }
  e->value = data;
  if (index == 0x6060) {
    set_int(0x6061, 0, static_cast<std::int8_t>(v & 0xFF));
    if (static_cast<std::int8_t>(v & 0xFF) == 6) home_stage_ = HomeStage::kNotStarted;
  }
  return std::nullopt;
}

void SimDrive::on_sdo(const CanFrame& f) {
  if (f.dlc != 8) return;  // not an SDO request; ignored (the client times out)
  const std::uint8_t cs = f.data[0];
  const std::uint8_t ccs = cs >> 5;
  const std::uint16_t index = co::get_u16(&f.data[1]);
  const std::uint8_t sub = f.data[3];
  if (cs == 0x80) {  // abort from the client
    seg_upload_ = seg_download_ = false;
    return;
  }
  // Fault injection: a lost request (or response) - the client's timeout and retry must cope.
  // Only initiate requests (upload ccs 2, download ccs 1) are dropped, never segments.
  if ((ccs == 1 || ccs == 2) && sdo_dropped_ < s_.faults.drop_sdo_requests) {
    ++sdo_dropped_;
    return;
  }
  // Segment traffic first (no multiplexer in these frames).
  if (ccs == 3 && seg_upload_) {
    if (((cs & 0x10) != 0) != seg_toggle_) return abort(seg_index_, seg_sub_, 0x05030000);
    const std::size_t n = std::min<std::size_t>(7, seg_buf_.size() - seg_pos_);
    const bool last = seg_pos_ + n >= seg_buf_.size();
    CanFrame r;
    r.id = co::kCobSdoTx + s_.node_id;
    r.dlc = 8;
    r.data[0] = static_cast<std::uint8_t>((seg_toggle_ ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0));
    for (std::size_t i = 0; i < n; ++i) r.data[1 + i] = seg_buf_[seg_pos_ + i];
    seg_pos_ += n;
    seg_toggle_ = !seg_toggle_;
    if (last) seg_upload_ = false;
    send_(r);
    return;
  }
  if (ccs == 0 && seg_download_) {
    if (((cs & 0x10) != 0) != seg_toggle_) return abort(seg_index_, seg_sub_, 0x05030000);
    const std::size_t n = 7u - ((cs >> 1) & 7u);
    seg_buf_.insert(seg_buf_.end(), f.data.begin() + 1, f.data.begin() + 1 + static_cast<std::ptrdiff_t>(n));
    CanFrame r;
    r.id = co::kCobSdoTx + s_.node_id;
    r.dlc = 8;
    r.data[0] = static_cast<std::uint8_t>(0x20 | (seg_toggle_ ? 0x10 : 0));
    seg_toggle_ = !seg_toggle_;
    if ((cs & 1) != 0) {
      seg_download_ = false;
      if (seg_buf_.size() != seg_size_) return abort(seg_index_, seg_sub_, 0x06070010);
      if (auto err = write_object(seg_index_, seg_sub_, seg_buf_)) return abort(seg_index_, seg_sub_, *err);
    }
    send_(r);
    return;
  }
  if (s_.faults.sdo_abort_object && *s_.faults.sdo_abort_object == key(index, sub) &&
      (ccs == 1 || ccs == 2))
    return abort(index, sub, s_.faults.sdo_abort_code);
  if (ccs == 2) {  // initiate upload
    Entry* e = find(index, sub);
    if (e == nullptr) {
      bool any = false;
      for (const auto& [k, v] : od_)
        if ((k >> 8) == index) any = true;
      return abort(index, sub, any ? 0x06090011 : 0x06020000);
    }
    if (!e->readable) return abort(index, sub, 0x06010001);
    if (s_.quirks.expedited_only && (e->value.size() > 4 || e->value.empty()))
      return abort(index, sub, 0x05040001);  // no segmented upload on this drive
    if (e->value.size() <= 4 && !e->value.empty()) {
      const auto n = e->value.size();
      send_sdo(static_cast<std::uint8_t>(0x43 | ((4 - n) << 2)), index, sub, e->value.data(), n);
    } else {
      seg_buf_ = e->value;
      seg_pos_ = 0;
      seg_toggle_ = false;
      seg_upload_ = true;
      seg_index_ = index;
      seg_sub_ = sub;
      std::uint8_t sz[4];
      co::put_u32(sz, static_cast<std::uint32_t>(seg_buf_.size()));
      send_sdo(0x41, index, sub, sz, 4);
    }
    return;
  }
  if (ccs == 1) {  // initiate download
    const bool expedited = (cs & 0x02) != 0, size_ind = (cs & 0x01) != 0;
    if (expedited) {
      const std::size_t n = size_ind ? 4u - ((cs >> 2) & 3u) : 4u;
      std::vector<std::uint8_t> d(f.data.begin() + 4, f.data.begin() + 4 + static_cast<std::ptrdiff_t>(n));
      if (auto err = write_object(index, sub, d)) return abort(index, sub, *err);
      send_sdo(0x60, index, sub, nullptr, 0);
      return;
    }
    if (s_.quirks.expedited_only) return abort(index, sub, 0x05040001);
    Entry* e = find(index, sub);
    if (e == nullptr) return abort(index, sub, 0x06020000);
    if (!e->writable) return abort(index, sub, 0x06010002);
    seg_buf_.clear();
    seg_size_ = size_ind ? co::get_u32(&f.data[4]) : 0;
    seg_download_ = true;
    seg_toggle_ = false;
    seg_index_ = index;
    seg_sub_ = sub;
    send_sdo(0x60, index, sub, nullptr, 0);
    return;
  }
  abort(index, sub, 0x05040001);
}

}  // namespace contour::sim
