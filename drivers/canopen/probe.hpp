#pragma once
// Commissioning probe for the CANopen bus (used by `contourd --probe can`): which nodes answer,
// their NMT state, identity (0x1000, 0x1018:1..4) and, for CiA 402 drives, statusword (0x6041)
// and mode display (0x6061). Non-RT, synchronous (a few hundred ms per node at most).
//
// Read-only by design: it sends no NMT command, no SYNC, no PDO and never writes 0x6040 or
// 0x6060; the drives stay in whatever NMT and CiA 402 state they were in. The one write it may
// make: a node whose heartbeat was not heard and whose producer time 0x1017 reads 0 has no other
// way (CiA 301 without node guarding) to tell its NMT state, so, when `temporary_heartbeat` is
// set, the probe writes 0x1017 = temporary_heartbeat_ms, waits for one heartbeat and writes the
// old value back (reported in `nmt_source`, and as an error if the restore fails).
//
// SDO upload failures are per object: recorded in `errors` ("0x1018:04: aborted by the drive:
// 0x06020000 object does not exist ..."), the rest of the node is still read.
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "drivers/can/can_bus.hpp"
#include "drivers/canopen/codec.hpp"

namespace contour::drivers::canopen {

struct CanProbeNode {
  std::uint8_t node_id = 0;
  std::string name;  // from the config ("X", "spindle"), empty for a node found by scan only
};

struct CanProbeSettings {
  std::vector<CanProbeNode> nodes;        // configured nodes, probed whether they answer or not
  bool scan = false;                      // also look for answering node-ids 1..127 not configured
  std::chrono::milliseconds listen{250};  // passive wait for heartbeats / boot-ups first
  std::chrono::milliseconds sdo_timeout{300};  // per SDO request/response pair
  std::chrono::milliseconds scan_timeout{60};  // per batch of scan requests
  bool temporary_heartbeat = true;
  std::uint16_t temporary_heartbeat_ms = 100;
};

struct CanProbeResult {
  std::uint8_t node_id = 0;
  std::string name;
  bool configured = false;
  bool found = false;  // answered an SDO, or a heartbeat/boot-up was seen
  std::optional<NmtState> nmt;
  std::string nmt_source;  // "heartbeat", "boot-up", "heartbeat (0x1017 temporarily ...)", ""
  std::optional<std::uint32_t> device_type;   // 0x1000
  std::optional<std::uint32_t> vendor_id;     // 0x1018:01
  std::optional<std::uint32_t> product_code;  // 0x1018:02
  std::optional<std::uint32_t> revision;      // 0x1018:03
  std::optional<std::uint32_t> serial;        // 0x1018:04
  std::optional<std::uint16_t> statusword;    // 0x6041 (CiA 402 devices only)
  std::optional<std::int8_t> mode_display;    // 0x6061
  std::vector<std::string> errors;
};

// Results: the configured nodes in config order, then the nodes found by scan in node-id order.
std::vector<CanProbeResult> probe_canopen(CanBus& bus, const CanProbeSettings& s);

}  // namespace contour::drivers::canopen
