#pragma once
// Remote I/O coupler over Modbus TCP or RTU (libmodbus), for the soft PLC's I/O image (issue 20):
// discrete inputs (FC02), input registers (FC04) and holding registers (FC03) read as inputs;
// coils (FC15) and holding registers (FC16) written as outputs. A non-RT poll thread does every
// transfer; the RT side exchanges whole records with it through two lock-free triple buffers
// (drivers/modbus/triple_buffer.hpp), like the dynamometer reader:
//
//   poll thread:  read the three input spans -> one CouplerInputs record (t_ns, seq) -> RT
//                 RT's latest CouplerOutputs -> write the coil and holding-register runs
//   RT:           read(now) -> the latest inputs, their age and state (kNoData, kOk, kStale);
//                 write(outputs) -> published for the next poll
//
// Inputs are read as one span per table (lowest to highest address used: the coupler must
// answer for every address between). Outputs are written as contiguous runs of the addresses
// the PLC drives only, so an address between two outputs is never overwritten. Every poll writes
// every output (a coupler that restarted gets its outputs back at once; its own watchdog drops
// them if this thread stops). Before the thread ends (stop()), the safe outputs given at
// construction are written once, best effort.
//
// Failure handling as DynamometerReader: response timeout -> count, flush; 3 in a row or a
// connection error -> close, reconnect with exponential backoff (reconnect_min .. reconnect_max);
// exception reply -> count (the record is not published); bad reply -> wait one response
// timeout, flush. Inputs older than stale_after are kStale: the PLC engine faults the machine.
// RT calls are noexcept, wait-free, allocation-free and make no system call.
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drivers/modbus/modbus_client.hpp"
#include "drivers/modbus/triple_buffer.hpp"

namespace contour::drivers::modbus {

inline constexpr std::size_t kCouplerMaxBits = 256;       // span of coils / discrete inputs
inline constexpr std::size_t kCouplerMaxRegisters = 64;   // span of registers per table

struct CouplerSpan {
  std::uint16_t start = 0;
  std::uint16_t count = 0;  // 0: the table is not used
};

struct IoCouplerSettings {
  std::string name = "coupler";  // for messages
  TransportSettings transport{};
  double poll_hz = 100.0;
  std::chrono::microseconds stale_after{200000};
  std::chrono::milliseconds reconnect_min{50};
  std::chrono::milliseconds reconnect_max{2000};
  int timeouts_before_reconnect = 3;
  // Inputs: one span each.
  CouplerSpan discrete_inputs, input_registers, holding_inputs;
  // Outputs: the addresses driven (each written every poll, in contiguous runs).
  std::vector<std::uint16_t> coils;
  std::vector<std::uint16_t> holding_outputs;
};

struct CouplerInputs {
  std::int64_t t_ns = 0;  // steady clock at the end of the last read
  std::uint64_t seq = 0;  // 1, 2, ... per complete read; 0 = none yet
  std::array<std::uint8_t, kCouplerMaxBits> discrete{};            // [addr - span.start]
  std::array<std::uint16_t, kCouplerMaxRegisters> input_registers{};
  std::array<std::uint16_t, kCouplerMaxRegisters> holding{};
};

// Indexed by address - the lowest coil / holding output address (see output_base()).
struct CouplerOutputs {
  std::array<std::uint8_t, kCouplerMaxBits> coils{};
  std::array<std::uint16_t, kCouplerMaxRegisters> holding{};
};

enum class CouplerState : std::uint8_t { kNoData, kOk, kStale };
[[nodiscard]] const char* to_string(CouplerState s) noexcept;

struct CouplerReading {
  CouplerState state = CouplerState::kNoData;
  std::int64_t age_ns = 0;
  bool fresh = false;  // a new record since the previous read()
};

struct CouplerStatus {
  bool connected = false;
  std::uint64_t polls = 0;    // poll cycles started
  std::uint64_t reads = 0;    // complete input records published
  std::uint64_t writes = 0;   // complete output writes
  std::uint64_t timeouts = 0;
  std::uint64_t exceptions = 0;
  std::uint64_t protocol_errors = 0;
  std::uint64_t connection_errors = 0;
  std::uint64_t reconnects = 0;
  std::string last_error;
};

class IoCoupler {
 public:
  // Validates the spans (throws std::invalid_argument naming the coupler and the table); does
  // not connect. `safe` are the outputs written until the RT side writes, and at stop().
  IoCoupler(IoCouplerSettings s, const CouplerOutputs& safe);
  ~IoCoupler();
  IoCoupler(const IoCoupler&) = delete;
  IoCoupler& operator=(const IoCoupler&) = delete;

  void start();  // spawns the poll thread (idempotent)
  void stop();   // writes the safe outputs once, joins (returns within ~2 response timeouts)

  // RT side (single consumer / single producer). `in` receives the latest record.
  CouplerReading read(std::int64_t now_ns, CouplerInputs& in) noexcept;
  void write(const CouplerOutputs& out) noexcept { outbox_.write(out); }

  [[nodiscard]] std::uint16_t coil_base() const noexcept { return coil_base_; }
  [[nodiscard]] std::uint16_t holding_output_base() const noexcept { return hold_base_; }
  [[nodiscard]] const IoCouplerSettings& settings() const noexcept { return s_; }
  // Non-RT: counters and the last error (takes a mutex for the string).
  [[nodiscard]] CouplerStatus status() const;

 private:
  struct Run {
    std::uint16_t start;
    std::uint16_t count;
  };
  void run();
  bool wait_until(std::chrono::steady_clock::time_point t);
  void set_error(const std::string& text);

  IoCouplerSettings s_;
  CouplerOutputs safe_{};
  std::uint16_t coil_base_ = 0, hold_base_ = 0;
  std::vector<Run> coil_runs_, hold_runs_;
  TripleBuffer<CouplerInputs> inbox_;
  TripleBuffer<CouplerOutputs> outbox_;
  bool out_written_ = false;  // poll thread: the RT side has written at least once
  std::thread thread_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::string last_error_;
  std::atomic<bool> connected_{false};
  std::atomic<std::uint64_t> polls_{0}, reads_{0}, writes_{0}, timeouts_{0}, exceptions_{0},
      protocol_errors_{0}, connection_errors_{0}, reconnects_{0};
};

}  // namespace contour::drivers::modbus
