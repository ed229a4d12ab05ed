#pragma once
// Real-time thread set-up and the periodic cycle clock.
//
// RtThread starts a thread with EXPLICIT scheduling attributes (PTHREAD_EXPLICIT_SCHED, SCHED_FIFO
// at the configured priority, CPU affinity), after mlockall(MCL_CURRENT|MCL_FUTURE) and with its
// stack prefaulted. Where RT scheduling or memory locking is not permitted it falls back to a normal
// thread and reports why (RtSetupReport), unless require_realtime is set: then start() throws.
// Threads created by the RT thread would inherit SCHED_FIFO; helper threads are created from the
// main thread, which stays SCHED_OTHER.
//
// CycleClock sleeps with clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) to the next absolute
// deadline and records the wake-up lateness into a fixed histogram (lock-free: relaxed atomics,
// written by the RT thread only, read by anyone). Overrun policy: when a wake-up is later than one
// full period, the missed periods are skipped and counted (deadline advances to the next period in
// the future), so the loop never runs a burst of catch-up cycles.
#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace contour::daemon {

struct RtSetupRequest {
  int priority = 80;           // SCHED_FIFO priority 1..99
  int cpu = -1;                // CPU to pin the RT thread to; -1 = no affinity
  bool lock_memory = true;     // mlockall
  bool require_realtime = false;
  std::size_t prefault_stack_bytes = 256 * 1024;
};

struct RtSetupReport {
  bool realtime = false;       // running SCHED_FIFO
  bool memory_locked = false;
  bool affinity_set = false;
  std::vector<std::string> warnings;  // why something was not applied
};

class RtThread {
 public:
  RtThread() = default;
  ~RtThread();
  RtThread(const RtThread&) = delete;
  RtThread& operator=(const RtThread&) = delete;

  // Starts body() on the RT thread. Throws std::runtime_error when require_realtime is set and RT
  // scheduling or memory locking is not permitted; otherwise falls back and reports.
  RtSetupReport start(const RtSetupRequest& req, std::function<void()> body);
  void join();
  [[nodiscard]] bool joinable() const { return started_; }

 private:
  pthread_t thread_{};
  bool started_ = false;
  std::function<void()> body_;
  std::size_t prefault_ = 0;
  static void* trampoline(void* self);
};

// Lateness histogram: 1 µs bins up to 20 ms (cyclictest's `-h 20000` resolution, so
// tools/latency-compare.sh compares like with like even on a VM whose lateness is milliseconds),
// then 100 µs bins up to 100 ms, plus overflow. Quantiles report the bin's upper edge (a bound).
class LatencyHistogram {
 public:
  static constexpr int kFineBins = 20000;    // 0..19999 µs, 1 µs wide
  static constexpr int kCoarseBins = 800;    // 20..100 ms, 100 µs wide
  static constexpr int kBins = kFineBins + kCoarseBins + 1;

  void record(std::int64_t lateness_ns) noexcept;
  void reset() noexcept;
  [[nodiscard]] std::uint64_t count() const noexcept;
  [[nodiscard]] std::int64_t min_ns() const noexcept { return min_ns_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::int64_t max_ns() const noexcept { return max_ns_.load(std::memory_order_relaxed); }
  [[nodiscard]] double mean_us() const noexcept;
  // Upper edge of the bin holding quantile q (0..1), in µs; 0 when empty.
  [[nodiscard]] double quantile_us(double q) const noexcept;
  // Lower edge of bin i in µs (for plotting); bin_count(i).
  [[nodiscard]] static double bin_low_us(int i) noexcept;
  [[nodiscard]] std::uint64_t bin_count(int i) const noexcept {
    return bins_[static_cast<std::size_t>(i)].load(std::memory_order_relaxed);
  }

 private:
  static int bin_of(std::int64_t ns) noexcept;
  std::array<std::atomic<std::uint64_t>, kBins> bins_{};
  std::atomic<std::uint64_t> count_{0};
  std::atomic<std::int64_t> sum_ns_{0};
  std::atomic<std::int64_t> min_ns_{INT64_MAX};
  std::atomic<std::int64_t> max_ns_{0};
};

struct CycleStats {
  LatencyHistogram wake_lateness;
  std::atomic<std::uint64_t> cycles{0};
  std::atomic<std::uint64_t> overruns{0};        // cycles whose work ended past the next deadline
  std::atomic<std::uint64_t> skipped_periods{0}; // periods skipped by the overrun policy
  std::atomic<std::int64_t> compute_max_ns{0};
  std::atomic<std::int64_t> compute_last_ns{0};
};

class CycleClock {
 public:
  explicit CycleClock(std::int64_t period_ns) : period_ns_(period_ns) {}
  // Sets the first deadline one period from now.
  void start() noexcept;
  // Sleeps to the next deadline; records lateness into stats. Returns the wake time (ns, MONOTONIC).
  std::int64_t wait_next(CycleStats& stats) noexcept;
  // Call at the end of the cycle's work: records compute time and overruns.
  void end_cycle(CycleStats& stats, std::int64_t wake_ns) noexcept;
  [[nodiscard]] std::int64_t period_ns() const noexcept { return period_ns_; }
  // The deadline the last wait_next() slept to (ns, MONOTONIC).
  [[nodiscard]] std::int64_t deadline_ns() const noexcept { return deadline_ns_; }

 private:
  std::int64_t period_ns_;
  std::int64_t deadline_ns_ = 0;
};

std::int64_t monotonic_ns() noexcept;

}  // namespace contour::daemon
