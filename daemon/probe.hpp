#pragma once
// `contourd --config FILE --probe modbus|can|gpio [--count N] [--scan]`: commissioning probe.
// Talks to the configured devices without starting the loop (no RT set-up, no drive enable) and
// prints one JSON object per line: one per sample (modbus), per node (can), per line (gpio), then
// one summary line {"probe": kind, "summary": true, "total": n, "answered": n, "ok": n, ...,
// "exit": status}.
//
// Lines (contract, relied on by tests/sim/probe_test.cpp and tests/hil/probe_can_test.cpp):
//   modbus: {"probe":"modbus","index":i,"ok":true,"valid":b,"seq":n,"t_ns":mono,"age_ms":x,
//            "latency_ms":x,"fx_n":N,"fy_n":N,"fz_n":N (configured channels only),
//            "raw_start":a,"raw":[u16...],"status":{"address":a,"value":u16,"valid":b}}
//           {"probe":"modbus","index":i,"ok":false,"error":"timeout|exception|connection|protocol|
//            config","error_text":"127.0.0.1:1502: connect: Connection refused","latency_ms":x}
//   can:    {"probe":"can","node_id":n,"name":"X","configured":b,"found":b,"nmt":"pre-operational",
//            "nmt_source":"heartbeat","device_type":"0x00020192","vendor_id":"0x00000C7D",
//            "product_code":"0x00000192","revision":"0x00010000","serial":"0x00001001",
//            "statusword":"0x0250","cia402_state":"switch-on-disabled","mode_display":9,
//            "errors":[...]}  (absent objects are omitted)
//   gpio:   {"probe":"gpio","round":r,"role":"estop","line":"estop (line 'ESTOP')","ok":b,
//            "direction":"input|output","active":b,"error":"..."}
//
// Exit status: 0 every sample/node/line answered and was good (valid sample; node with identity
// and no failed object; line requested); 1 some did not (a configured node missing, a read error,
// an invalid sample, a line that could not be requested); 69 (EX_UNAVAILABLE) nothing answered at
// all (no Modbus reply, no CAN node, interface missing); 78 (EX_CONFIG) the config has no such
// device (dynamometer/gpio section absent, bus.type not socketcan).
#include <cstdio>
#include <memory>
#include <optional>
#include <string_view>

#include "config/config.hpp"
#include "drivers/gpio/gpio.hpp"

namespace contour::daemon {

enum class ProbeKind { kModbus, kCan, kGpio };

[[nodiscard]] std::optional<ProbeKind> parse_probe_kind(std::string_view s) noexcept;
[[nodiscard]] const char* to_string(ProbeKind k) noexcept;

struct ProbeOptions {
  ProbeKind kind = ProbeKind::kModbus;
  int count = 0;      // samples (modbus) / rounds (can, gpio); 0 = default (10 / 1 / 1)
  bool scan = false;  // can: also scan node-ids 1..127 beyond the configured ones
  // gpio: use this backend instead of the configured one (tests drive a SimGpio's inputs).
  std::shared_ptr<drivers::gpio::GpioBackend> gpio_backend;
};

inline constexpr int kProbeDefaultModbusCount = 10;

// Prints to `out`; errors about the invocation itself (config without the device) go to `out` too,
// as {"probe":..., "error": "..."} lines, so the output is always JSON lines.
int run_probe(const config::Config& cfg, const ProbeOptions& opt, std::FILE* out);

}  // namespace contour::daemon
