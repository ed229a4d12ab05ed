#include "daemon/rt_timing.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace contour::daemon {

std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

namespace {
void prefault_stack(std::size_t bytes) {
  // Touch the stack pages now so the first cycles take no page faults. The volatile buffer keeps
  // the compiler from dropping the writes.
  constexpr std::size_t kChunk = 4096;
  volatile unsigned char probe[kChunk];
  probe[0] = 1;
  if (bytes > kChunk) prefault_stack(bytes - kChunk);
  probe[kChunk - 1] = probe[0];
}
}  // namespace

RtThread::~RtThread() {
  if (started_) join();
}

void* RtThread::trampoline(void* self) {
  auto* t = static_cast<RtThread*>(self);
  prefault_stack(t->prefault_);
  t->body_();
  return nullptr;
}

RtSetupReport RtThread::start(const RtSetupRequest& req, std::function<void()> body) {
  if (started_) throw std::logic_error("RtThread already started");
  RtSetupReport rep;
  body_ = std::move(body);
  prefault_ = req.prefault_stack_bytes;

  if (req.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      rep.memory_locked = true;
    } else {
      rep.warnings.push_back(std::string("mlockall failed: ") + std::strerror(errno) +
                             " (needs CAP_IPC_LOCK or LimitMEMLOCK=infinity)");
      if (req.require_realtime) {
        throw std::runtime_error("loop.require_realtime is true but " + rep.warnings.back());
      }
    }
  }

  pthread_attr_t attr;
  pthread_attr_init(&attr);
  pthread_attr_setstacksize(&attr, req.prefault_stack_bytes + 256 * 1024);
  bool want_rt = req.priority > 0;
  if (want_rt) {
    sched_param sp{};
    sp.sched_priority = req.priority;
    pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
    pthread_attr_setschedpolicy(&attr, SCHED_FIFO);
    pthread_attr_setschedparam(&attr, &sp);
  }
  if (req.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<unsigned>(req.cpu), &set);
    if (pthread_attr_setaffinity_np(&attr, sizeof(set), &set) == 0) {
      rep.affinity_set = true;
    } else {
      rep.warnings.push_back("cannot pin the RT thread to CPU " + std::to_string(req.cpu));
    }
  }
  int rc = pthread_create(&thread_, &attr, &RtThread::trampoline, this);
  if (rc == EPERM && want_rt && req.require_realtime) {
    pthread_attr_destroy(&attr);
    throw std::runtime_error(
        "loop.require_realtime is true but SCHED_FIFO is not permitted (needs CAP_SYS_NICE or "
        "LimitRTPRIO)");
  }
  if (rc == EPERM && want_rt) {
    rep.warnings.push_back(
        "SCHED_FIFO not permitted (needs CAP_SYS_NICE or LimitRTPRIO); running SCHED_OTHER");
    pthread_attr_setinheritsched(&attr, PTHREAD_INHERIT_SCHED);
    rc = pthread_create(&thread_, &attr, &RtThread::trampoline, this);
    want_rt = false;
  }
  if (rc == EINVAL && rep.affinity_set) {
    rep.warnings.push_back("CPU " + std::to_string(req.cpu) + " not available; no affinity");
    rep.affinity_set = false;
    cpu_set_t all;
    CPU_ZERO(&all);
    for (int c = 0; c < CPU_SETSIZE; ++c) CPU_SET(static_cast<unsigned>(c), &all);
    pthread_attr_setaffinity_np(&attr, sizeof(all), &all);
    rc = pthread_create(&thread_, &attr, &RtThread::trampoline, this);
  }
  pthread_attr_destroy(&attr);
  if (rc != 0) throw std::runtime_error(std::string("cannot start the RT thread: ") + std::strerror(rc));
  started_ = true;
  rep.realtime = want_rt;
  return rep;
}

void RtThread::join() {
  if (!started_) return;
  pthread_join(thread_, nullptr);
  started_ = false;
}

int LatencyHistogram::bin_of(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  const std::int64_t us = ns / 1000;
  if (us < kFineBins) return static_cast<int>(us);
  const std::int64_t coarse = (us - kFineBins) / 100;
  if (coarse < kCoarseBins) return kFineBins + static_cast<int>(coarse);
  return kBins - 1;
}

double LatencyHistogram::bin_low_us(int i) noexcept {
  if (i < kFineBins) return i;
  return kFineBins + (i - kFineBins) * 100.0;
}

void LatencyHistogram::record(std::int64_t ns) noexcept {
  bins_[static_cast<std::size_t>(bin_of(ns))].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  sum_ns_.fetch_add(ns, std::memory_order_relaxed);
  if (ns < min_ns_.load(std::memory_order_relaxed)) min_ns_.store(ns, std::memory_order_relaxed);
  if (ns > max_ns_.load(std::memory_order_relaxed)) max_ns_.store(ns, std::memory_order_relaxed);
}

void LatencyHistogram::reset() noexcept {
  for (auto& b : bins_) b.store(0, std::memory_order_relaxed);
  count_.store(0);
  sum_ns_.store(0);
  min_ns_.store(INT64_MAX);
  max_ns_.store(0);
}

std::uint64_t LatencyHistogram::count() const noexcept { return count_.load(std::memory_order_relaxed); }

double LatencyHistogram::mean_us() const noexcept {
  const auto n = count();
  return n == 0 ? 0.0
                : static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) /
                      static_cast<double>(n) / 1000.0;
}

double LatencyHistogram::quantile_us(double q) const noexcept {
  const auto n = count();
  if (n == 0) return 0.0;
  const auto target = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(n)));
  std::uint64_t acc = 0;
  for (int i = 0; i < kBins; ++i) {
    acc += bin_count(i);
    if (acc >= target && acc > 0) {
      if (i == kBins - 1) return static_cast<double>(max_ns()) / 1000.0;
      return i + 1 < kBins ? bin_low_us(i + 1) : bin_low_us(i);
    }
  }
  return static_cast<double>(max_ns()) / 1000.0;
}

void CycleClock::start() noexcept { deadline_ns_ = monotonic_ns() + period_ns_; }

std::int64_t CycleClock::wait_next(CycleStats& stats) noexcept {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline_ns_ / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(deadline_ns_ % 1'000'000'000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
  const std::int64_t now = monotonic_ns();
  stats.wake_lateness.record(now - deadline_ns_);
  stats.cycles.fetch_add(1, std::memory_order_relaxed);
  return now;
}

void CycleClock::end_cycle(CycleStats& stats, std::int64_t wake_ns) noexcept {
  const std::int64_t now = monotonic_ns();
  const std::int64_t compute = now - wake_ns;
  stats.compute_last_ns.store(compute, std::memory_order_relaxed);
  if (compute > stats.compute_max_ns.load(std::memory_order_relaxed)) {
    stats.compute_max_ns.store(compute, std::memory_order_relaxed);
  }
  deadline_ns_ += period_ns_;
  if (now > deadline_ns_) {
    // Overrun: skip whole missed periods (counted) instead of running a catch-up burst.
    stats.overruns.fetch_add(1, std::memory_order_relaxed);
    const std::int64_t missed = (now - deadline_ns_) / period_ns_ + 1;
    stats.skipped_periods.fetch_add(static_cast<std::uint64_t>(missed), std::memory_order_relaxed);
    deadline_ns_ += missed * period_ns_;
  }
}

}  // namespace contour::daemon
