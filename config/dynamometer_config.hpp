#pragma once
// `dynamometer:` section (issue 8). Absent section -> enabled = false. The parsed values are the
// drivers' own plain settings structs (header-only data, no I/O), so the daemon hands them to
// DynamometerReader / ForceFilter / probe_dynamometer unchanged.
//
// dynamometer:
//   transport: tcp            # tcp | rtu
//   host: 127.0.0.1           # tcp
//   port: 1502                # tcp
//   device: /dev/ttyUSB0      # rtu
//   baud: 115200              # rtu
//   parity: none              # rtu: none | even | odd
//   unit_id: 1
//   function: input           # input (FC04) | holding (FC03)
//   channels:                 # any subset of fx, fy, fz
//     fx: {address: 0, type: float32, word_order: abcd, scale: 1.0, offset_n: 0.0}
//   status: {address: 6, valid_bit: 0, valid_when: set}   # optional; valid_when: set | clear
//   poll_rate_hz: 200
//   timeout_ms: 20
//   stale_ms: 50
//   reconnect_min_ms: 50
//   reconnect_max_ms: 2000
//   filter: {enabled: true, moving_average: true, teeth: 4, min_spindle_rpm: 100,
//            butterworth_order: 2, cutoff_hz: 10}      # runs on the poll thread
// (what the force loop does on a stale sample is `force.fallback`)
#include <string>

#include "config/yaml_reader.hpp"
#include "drivers/modbus/dynamometer_reader.hpp"
#include "drivers/modbus/force_filter.hpp"

namespace contour::config {

struct DynamometerConfig {
  bool enabled = false;
  drivers::modbus::DynamometerSettings reader{};  // incl. filter (sample_rate_hz = poll_rate_hz)
};

DynamometerConfig parse_dynamometer(Section& s);

}  // namespace contour::config
