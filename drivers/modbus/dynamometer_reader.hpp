#pragma once
// Dynamometer reader: a non-RT poll thread reads the register block at a fixed rate over Modbus
// TCP or RTU (libmodbus) and publishes ForceSample records through a lock-free triple buffer.
// The RT loop calls read() only: wait-free, noexcept, no allocation, no libmodbus, no lock
// (budget < 1 us; it copies one ~120-byte record).
//
// Failure handling (poll thread): response timeout (default 20 ms) -> count, flush; 3 timeouts in
// a row or a connection error -> close and reconnect with exponential backoff (50 ms .. 2 s);
// exception reply -> count, text in status; bad/late reply (TCP transaction id mismatch, CRC) ->
// wait one response timeout, flush, reconnect after 3 in a row; a sample older than `stale_after`
// is reported stale by read(). The thread never spins: it sleeps until the next period or backoff
// deadline, and the socket waits are bounded by the response timeout.
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "drivers/modbus/force_filter.hpp"
#include "drivers/modbus/modbus_client.hpp"
#include "drivers/modbus/register_map.hpp"
#include "drivers/modbus/triple_buffer.hpp"

namespace contour::drivers::modbus {

struct DynamometerSettings {
  TransportSettings transport{};
  RegisterMap map{};
  double poll_rate_hz = 200.0;
  std::chrono::microseconds stale_after{50000};
  std::chrono::milliseconds reconnect_min{50};
  std::chrono::milliseconds reconnect_max{2000};
  int timeouts_before_reconnect = 3;
  // Signal conditioning, run on the poll thread so that every sample is filtered exactly once
  // whatever the consumer's timing (a consumer that misses samples would break the tooth-period
  // average). filter.sample_rate_hz is taken from poll_rate_hz. The filter restarts after a gap
  // longer than stale_after.
  bool filter_enabled = false;
  ForceFilterSettings filter{};
};

struct ForceSample {
  std::int64_t t_ns = 0;  // CLOCK_MONOTONIC (std::chrono::steady_clock) at reply
  std::uint64_t seq = 0;  // 1, 2, ... per successful read; 0 = no sample yet
  bool valid = false;     // read ok, status valid bit set, every channel finite
  std::array<double, kForceChannels> force_N{};     // raw, 0 for channels not mapped
  std::array<double, kForceChannels> filtered_N{};  // conditioned (== force_N if no filter)
  std::array<bool, kForceChannels> present{};
  std::uint16_t raw_start = 0;
  std::uint16_t raw_count = 0;
  std::array<std::uint16_t, kMaxBlockRegisters> raw{};
};

enum class ForceState { kOk, kNoData, kStale, kInvalid };
[[nodiscard]] const char* to_string(ForceState s) noexcept;

struct ForceReading {
  ForceState state = ForceState::kNoData;
  ForceSample sample{};
  std::int64_t age_ns = 0;
  bool fresh = false;  // a new sample since the previous read()
};

struct DynamometerStatus {
  bool connected = false;
  std::uint64_t polls = 0;    // requests sent
  std::uint64_t samples = 0;  // successful reads
  std::uint64_t timeouts = 0;
  std::uint64_t exceptions = 0;
  std::uint64_t protocol_errors = 0;
  std::uint64_t connection_errors = 0;
  std::uint64_t reconnects = 0;  // successful connects after the first
  std::uint64_t invalid = 0;     // reads with status bit invalid or non-finite values
  std::string last_error;        // text of the last failure ("" if none)
};

// Decodes one block read at `block.start` into a sample (pure; used by the reader and the probe).
void decode_block(const RegisterMap& map, std::uint16_t start, std::span<const std::uint16_t> regs,
                  ForceSample& out) noexcept;

class DynamometerReader {
 public:
  // Validates the settings (throws std::invalid_argument with the reason); does not connect.
  explicit DynamometerReader(DynamometerSettings s);
  ~DynamometerReader();
  DynamometerReader(const DynamometerReader&) = delete;
  DynamometerReader& operator=(const DynamometerReader&) = delete;

  void start();  // spawns the poll thread (idempotent)
  void stop();   // joins it; returns within ~response timeout

  // RT side (single consumer). now_ns: steady_clock time of the RT cycle.
  ForceReading read(std::int64_t now_ns) noexcept;
  // Any thread: spindle speed for the tooth-period moving average (wait-free atomic store).
  void set_spindle_rpm(double rpm) noexcept { spindle_rpm_.store(rpm, std::memory_order_relaxed); }

  // Non-RT: counters and last error (takes a mutex for the string).
  [[nodiscard]] DynamometerStatus status() const;
  [[nodiscard]] const DynamometerSettings& settings() const noexcept { return s_; }

 private:
  void run();
  bool wait_until(std::chrono::steady_clock::time_point t);  // false if stopping
  void set_error(const std::string& text);

  DynamometerSettings s_;
  RegisterBlock block_{};
  TripleBuffer<ForceSample> mailbox_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::string last_error_;
  std::atomic<bool> connected_{false};
  std::atomic<double> spindle_rpm_{0.0};
  std::atomic<std::uint64_t> polls_{0}, samples_{0}, timeouts_{0}, exceptions_{0},
      protocol_errors_{0}, connection_errors_{0}, reconnects_{0}, invalid_{0};
};

[[nodiscard]] inline std::int64_t steady_now_ns() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace contour::drivers::modbus
