#pragma once
// Commissioning probe for the dynamometer (used by `contourd --probe modbus`): connects with the
// configured transport, reads the register block `count` times at the poll rate, and returns one
// record per request (decoded sample, or the translated error). Synchronous, non-RT; never throws
// for device errors (they are in the records), throws std::invalid_argument for bad settings.
#include <functional>
#include <string>
#include <vector>

#include "drivers/modbus/dynamometer_reader.hpp"

namespace contour::drivers::modbus {

struct ProbeRecord {
  int index = 0;
  bool ok = false;          // reply received and decoded
  ForceSample sample{};     // valid when ok (sample.valid: status bit + finite values)
  double latency_ms = 0.0;  // request -> reply
  ErrorKind error = ErrorKind::kNone;
  std::string error_text;  // "127.0.0.1:1502: connect: Connection refused"
};

std::vector<ProbeRecord> probe_dynamometer(const DynamometerSettings& s, int count);

// Streaming form: `on_record` is called as each reply (or error) arrives, before the wait for the
// next period, so a caller can print it with a meaningful age.
void probe_dynamometer(const DynamometerSettings& s, int count,
                       const std::function<void(const ProbeRecord&)>& on_record);

// "timeout", "exception", "connection", "protocol", "config" ("none" for kNone).
[[nodiscard]] const char* error_kind_name(ErrorKind k) noexcept;

}  // namespace contour::drivers::modbus
