#include "tools/contour-machine-sim/storm.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace contour::sim {

namespace {

constexpr std::array<const char*, kStormKindCount> kNames = {
    "tpdo_gap",       "tpdo_burst",       "drive_fault",      "heartbeat_gap",
    "modbus_timeout", "modbus_exception", "modbus_disconnect"};

// Real CiA 402 / CiA 301 emergency codes a servo drive raises.
constexpr std::array<std::uint16_t, 5> kDriveFaultCodes = {
    0x2310,  // continuous over-current
    0x3210,  // DC link over-voltage
    0x4310,  // excess temperature drive
    0x7121,  // motor blocked
    0x8611,  // following error
};

std::size_t idx(StormKind k) { return static_cast<std::size_t>(k); }

}  // namespace

const char* storm_kind_name(StormKind k) noexcept { return kNames[idx(k)]; }

std::optional<StormKind> storm_kind_from(std::string_view name) noexcept {
  for (std::size_t i = 0; i < kNames.size(); ++i)
    if (name == kNames[i]) return static_cast<StormKind>(i);
  return std::nullopt;
}

bool storm_fault_level(StormKind k) noexcept {
  return k == StormKind::kTpdoBurst || k == StormKind::kDriveFault || k == StormKind::kHeartbeatGap;
}

bool storm_needs_modbus(StormKind k) noexcept {
  return k == StormKind::kModbusTimeout || k == StormKind::kModbusException ||
         k == StormKind::kModbusDisconnect;
}

std::vector<StormKind> all_storm_kinds() {
  std::vector<StormKind> v;
  for (std::size_t i = 0; i < kStormKindCount; ++i) v.push_back(static_cast<StormKind>(i));
  return v;
}

std::vector<StormKind> parse_storm_kinds(const std::string& list) {
  std::vector<StormKind> out;
  std::size_t pos = 0;
  while (pos <= list.size()) {
    const std::size_t c = list.find(',', pos);
    const std::string name = list.substr(pos, c == std::string::npos ? std::string::npos : c - pos);
    if (!name.empty()) {
      const auto k = storm_kind_from(name);
      if (!k) {
        std::string known;
        for (const char* n : kNames) known += std::string(known.empty() ? "" : ", ") + n;
        throw std::invalid_argument("unknown storm kind '" + name + "' (known: " + known + ")");
      }
      bool seen = false;
      for (auto o : out) seen = seen || o == *k;
      if (!seen) out.push_back(*k);
    }
    if (c == std::string::npos) break;
    pos = c + 1;
  }
  if (out.empty()) throw std::invalid_argument("empty storm kind list");
  return out;
}

Storm::Storm(StormSetup setup, std::vector<StormNode> nodes, DynamometerServer* dyno, Emit emit)
    : s_(std::move(setup)),
      nodes_(std::move(nodes)),
      dyno_(dyno),
      emit_(std::move(emit)),
      rng_(s_.seed) {
  if (s_.interval_syncs < 1) throw std::invalid_argument("storm interval must be >= 1 SYNC");
  if (s_.kinds.empty()) throw std::invalid_argument("no storm kinds enabled");
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (nodes_[i].axis) axes_.push_back(i);
    if (nodes_[i].heartbeat_timeout_ms > 0) hb_nodes_.push_back(i);
  }
  enabled_since_.assign(nodes_.size(), -1);
  for (auto k : s_.kinds) {
    const std::string who = std::string("storm kind ") + storm_kind_name(k);
    if ((k == StormKind::kTpdoGap || k == StormKind::kTpdoBurst || k == StormKind::kDriveFault) &&
        axes_.empty())
      throw std::invalid_argument(who + ": no axis node");
    if (k == StormKind::kTpdoGap && s_.missed_tpdo_streak < 2)
      throw std::invalid_argument(who + ": missed_tpdo_streak " +
                                  std::to_string(s_.missed_tpdo_streak) +
                                  " leaves no gap below the fault threshold");
    if (k == StormKind::kHeartbeatGap && hb_nodes_.empty())
      throw std::invalid_argument(who + ": no node with a heartbeat timeout");
    if (storm_needs_modbus(k) && dyno_ == nullptr)
      throw std::invalid_argument(who + ": the dynamometer server is not running");
  }
}

std::uint64_t Storm::below(std::uint64_t n) {
  // Modulo bias < n / 2^64: irrelevant here, and unlike std::uniform_int_distribution the
  // mapping is the same in every standard library.
  return n == 0 ? 0 : rng_() % n;
}

double Storm::unit() { return static_cast<double>(rng_() >> 11) * 0x1.0p-53; }

void Storm::schedule() {
  Event e;
  const double gap = static_cast<double>(s_.interval_syncs) * (0.5 + unit());
  e.due = sync_ + std::max<long>(1, std::lround(gap));
  e.kind = s_.kinds[below(s_.kinds.size())];
  switch (e.kind) {
    case StormKind::kTpdoGap:
      e.node = axes_[below(axes_.size())];
      e.count = 1 + static_cast<long>(below(static_cast<std::uint64_t>(s_.missed_tpdo_streak - 1)));
      break;
    case StormKind::kTpdoBurst:
      e.node = axes_[below(axes_.size())];
      e.count = s_.missed_tpdo_streak + 2;
      break;
    case StormKind::kDriveFault:
      e.node = axes_[below(axes_.size())];
      e.code = kDriveFaultCodes[below(kDriveFaultCodes.size())];
      break;
    case StormKind::kHeartbeatGap: {
      e.node = hb_nodes_[below(hb_nodes_.size())];
      const double ms = 2.0 * nodes_[e.node].heartbeat_timeout_ms;
      e.count = std::max<long>(1, std::lround(ms * 1e-3 / s_.period_s));
      break;
    }
    case StormKind::kModbusTimeout:
      e.count = static_cast<long>(s_.modbus_no_reply.count());
      break;
    case StormKind::kModbusException:
      e.count = s_.modbus_exception_count;
      e.code = static_cast<std::uint16_t>(s_.modbus_exception_code);
      break;
    case StormKind::kModbusDisconnect:
      break;
  }
  pending_ = e;
}

bool Storm::settled() const noexcept {
  for (std::size_t i : axes_)
    if (enabled_since_[i] < 0 || sync_ - enabled_since_[i] < s_.settle_syncs) return false;
  return true;
}

bool Storm::may_fire(const Event& e) const noexcept {
  if (sync_ < e.due) return false;
  if (any_fired_) {
    const bool fault_near = last_fault_ || storm_fault_level(e.kind);
    if (sync_ < last_end_ + (fault_near ? s_.guard_syncs : 0) + last_extra_) return false;
  }
  return !storm_fault_level(e.kind) || settled();
}

void Storm::on_sync() {
  ++sync_;
  // States as the drives left them at the previous SYNC.
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (nodes_[i].drive->state() == drivers::canopen::Cia402State::kOperationEnabled) {
      if (enabled_since_[i] < 0) enabled_since_[i] = sync_;
    } else {
      enabled_since_[i] = -1;
    }
  }
  if (!pending_) schedule();
  if (!may_fire(*pending_)) return;
  const Event e = *pending_;
  pending_.reset();
  fire(e);
  schedule();
}

void Storm::fire(const Event& e) {
  nlohmann::ordered_json j;
  j["storm"] = storm_kind_name(e.kind);
  const StormNode* n = storm_needs_modbus(e.kind) ? nullptr : &nodes_[e.node];
  if (n != nullptr) j["node"] = n->drive->node_id();
  j["sync"] = sync_;
  long end = sync_ + 1;
  last_extra_ = 0;
  switch (e.kind) {
    case StormKind::kTpdoGap:
    case StormKind::kTpdoBurst:
      n->drive->drop_tpdos(e.count);
      j["count"] = e.count;
      end = sync_ + e.count * std::max(1, n->sync_every);
      if (e.kind == StormKind::kTpdoGap) last_extra_ = std::max(1, n->sync_every);
      break;
    case StormKind::kDriveFault:
      n->drive->inject_fault(e.code);
      j["code"] = e.code;
      break;
    case StormKind::kHeartbeatGap:
      n->drive->suppress_heartbeat(e.count);
      j["syncs"] = e.count;
      j["ms"] = std::lround(static_cast<double>(e.count) * s_.period_s * 1e3);
      end = sync_ + e.count;
      break;
    case StormKind::kModbusTimeout:
      dyno_->inject_no_reply(std::chrono::milliseconds(e.count));
      j["ms"] = e.count;
      end =
          sync_ + std::max<long>(
                      1, std::lround(std::ceil(static_cast<double>(e.count) * 1e-3 / s_.period_s)));
      break;
    case StormKind::kModbusException:
      dyno_->inject_exceptions(static_cast<int>(e.count), e.code);
      j["count"] = e.count;
      j["code"] = e.code;
      break;
    case StormKind::kModbusDisconnect:
      dyno_->inject_disconnect();
      break;
  }
  ++fired_[idx(e.kind)];
  any_fired_ = true;
  last_end_ = end;
  last_fault_ = storm_fault_level(e.kind);
  emit_(j.dump());
}

nlohmann::json Storm::summary() const {
  nlohmann::json j;
  j["seed"] = s_.seed;
  nlohmann::json ev = nlohmann::json::object();
  for (std::size_t i = 0; i < kStormKindCount; ++i) ev[kNames[i]] = fired_[i];
  j["events"] = ev;
  std::uint64_t dropped = 0, emcy = 0;
  for (const auto& n : nodes_) {
    dropped += n.drive->tpdo_dropped();
    emcy += n.drive->injected_emcy_sent();
  }
  j["tpdo_dropped"] = dropped;
  j["emcy_sent"] = emcy;
  return j;
}

}  // namespace contour::sim
