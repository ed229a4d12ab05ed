#pragma once
// Fault storm for contour-machine-sim (--storm SEED): a seeded random fault injector, scheduled
// in SYNC counts so that the same seed against the same (lockstep) master gives the same events.
//
// Time base: `sync` is the number of SYNC frames the simulator has received since it started
// (Storm::on_sync() is called once per SYNC, before the drives process it). In lockstep this is
// the master's cycle count.
//
// Schedule: one event is pending at a time. It is drawn when the previous one fires (the first
// at start-up): due = fire sync + gap, gap uniform in [0.5, 1.5] x interval_syncs (at least 1),
// kind uniform over the enabled kinds, then its node and parameters. Uniform, not exponential:
// the gap is bounded below, so events never pile up and each fault stays a separate fault.
// Randomness: std::mt19937_64 (fully specified by the standard) and only our own integer and
// [0, 1) mappings of its output (no std::*_distribution, whose algorithms are not specified),
// so a seed gives the same events with any standard library.
//
// Kinds (fault-level: the controller must fault; the others must only be counted):
//   tpdo_gap          one random axis node withholds 1..(missed_tpdo_streak - 1) consecutive TPDOs
//   tpdo_burst        (fault) one random axis node withholds missed_tpdo_streak + 2 TPDOs
//   drive_fault       (fault) one random axis node raises a drive fault (Fault + EMCY), code one
//                     of 0x2310, 0x3210, 0x4310, 0x7121, 0x8611; cleared by the operator's reset
//   heartbeat_gap     (fault) one random node (axis or spindle, heartbeat_timeout_ms > 0) sends no
//                     heartbeat for 2 x its master-side heartbeat timeout (in SYNCs), then resumes
//   modbus_timeout    the dynamometer server does not reply for 5 x the reader's response
//                     timeout of wall time
//   modbus_exception  the next 3 requests get exception replies (code 4, server device failure)
//   modbus_disconnect the server closes the connection that carries the next request
// Gating: a fault-level event fires only once every axis node has been in CiA 402 operation
// enabled for >= settle_syncs SYNCs without a break (the machine is enabled and settled after
// the previous reset); until then it stays pending with its kind, node and parameters. Events
// never overlap: each waits for the end of the previous one's effect (TPDO drops, heartbeat gap,
// modbus no-reply window converted to SYNCs), plus guard_syncs when either of the two is
// fault-level, plus one TPDO period after a TPDO gap (two gaps never join into a streak).
//
// Output: each fired event is one JSON line through `emit` at once, e.g.
//   {"storm":"drive_fault","node":2,"sync":123456,"code":8976}
//   {"storm":"tpdo_gap","node":1,"sync":4711,"count":2}
//   {"storm":"tpdo_burst","node":3,"sync":9000,"count":5}
//   {"storm":"heartbeat_gap","node":4,"sync":12000,"syncs":400,"ms":400}
//   {"storm":"modbus_timeout","sync":15000,"ms":100}
//   {"storm":"modbus_exception","sync":17000,"count":3,"code":4}
//   {"storm":"modbus_disconnect","sync":19000}
// summary(): {"seed", "events": {kind: fired count, all seven kinds}, "tpdo_dropped": TPDO
// frames withheld by the simulated drives (storm and --drop-tpdo; each is one missed TPDO for the
// master), "emcy_sent": EMCY frames caused by drive_fault events (the fault EMCY, and the
// error-reset EMCY 0x0000 once the operator's reset clears that fault)}.
//
// Not real-time code: it runs in the simulator's single thread, allocates when it fires.
#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "tools/contour-machine-sim/dynamometer_server.hpp"
#include "tools/contour-machine-sim/sim_drive.hpp"

namespace contour::sim {

enum class StormKind : std::uint8_t {
  kTpdoGap,
  kTpdoBurst,
  kDriveFault,
  kHeartbeatGap,
  kModbusTimeout,
  kModbusException,
  kModbusDisconnect,
};
inline constexpr std::size_t kStormKindCount = 7;

[[nodiscard]] const char* storm_kind_name(StormKind k) noexcept;
[[nodiscard]] std::optional<StormKind> storm_kind_from(std::string_view name) noexcept;
[[nodiscard]] bool storm_fault_level(StormKind k) noexcept;
[[nodiscard]] bool storm_needs_modbus(StormKind k) noexcept;
[[nodiscard]] std::vector<StormKind> all_storm_kinds();
// "tpdo_gap,drive_fault" -> kinds in the given order, duplicates removed. Throws
// std::invalid_argument naming the unknown kind, or for an empty list.
[[nodiscard]] std::vector<StormKind> parse_storm_kinds(const std::string& list);

struct StormSetup {
  std::uint64_t seed = 0;
  long interval_syncs = 5000;    // mean gap between events, SYNCs (>= 1)
  std::vector<StormKind> kinds;  // enabled kinds (non-empty); modbus_* need `dyno`
  int missed_tpdo_streak = 3;    // safety.missed_tpdo_streak
  double period_s = 0.001;       // machine.period_s: converts ms to SYNCs
  std::chrono::milliseconds modbus_no_reply{100};  // 5 x the reader's response timeout
  int modbus_exception_count = 3;
  int modbus_exception_code = 4;
  long settle_syncs = 500;  // all axes operation enabled this long before a fault-level event
  long guard_syncs = 50;    // no event this close to a fault-level one
};

struct StormNode {
  SimDrive* drive = nullptr;
  bool axis = true;              // false: the spindle
  int heartbeat_timeout_ms = 0;  // master's consumer timeout for this node (0: not monitored)
  int sync_every = 1;            // TPDO transmission type
};

class Storm {
 public:
  using Emit = std::function<void(const std::string&)>;

  // Throws std::invalid_argument when a kind has no possible target (no axis node, no monitored
  // heartbeat, tpdo_gap with missed_tpdo_streak < 2, modbus_* without `dyno`), or for an
  // interval < 1 / empty kinds. `dyno` may be null; nodes and dyno must outlive the Storm.
  Storm(StormSetup setup, std::vector<StormNode> nodes, DynamometerServer* dyno, Emit emit);

  // Once per SYNC received, before the drives see it: may fire the pending event.
  void on_sync();

  [[nodiscard]] long syncs() const noexcept { return sync_; }
  [[nodiscard]] nlohmann::json summary() const;

 private:
  struct Event {
    StormKind kind = StormKind::kTpdoGap;
    long due = 0;
    std::size_t node = 0;  // index into nodes_
    long count = 0;        // TPDOs (tpdo_*), SYNCs (heartbeat_gap), requests (modbus_exception)
    std::uint16_t code = 0;
  };
  void schedule();
  [[nodiscard]] bool settled() const noexcept;
  [[nodiscard]] bool may_fire(const Event& e) const noexcept;
  void fire(const Event& e);
  std::uint64_t below(std::uint64_t n);  // uniform integer in [0, n)
  double unit();                         // uniform in [0, 1), 53 bits

  StormSetup s_;
  std::vector<StormNode> nodes_;
  DynamometerServer* dyno_;
  Emit emit_;
  std::mt19937_64 rng_;
  std::vector<std::size_t> axes_, hb_nodes_;  // candidates per kind (indices into nodes_)
  std::vector<long> enabled_since_;           // per node: sync since which it is enabled, or -1
  std::optional<Event> pending_;
  long sync_ = 0;
  bool any_fired_ = false;
  long last_end_ = 0;  // first SYNC after the previous event's effect
  bool last_fault_ = false;
  long last_extra_ = 0;  // extra spacing the previous event asks for (TPDO period of a gap)
  std::array<std::uint64_t, kStormKindCount> fired_{};
};

}  // namespace contour::sim
