#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "daemon/rt_timing.hpp"
#include "daemon/spsc_ring.hpp"
#include "tests/support/alloc_counter.hpp"

using contour::daemon::LatencyHistogram;
using contour::daemon::SpscRing;

struct Rec {
  std::uint64_t seq;
  double value;
};

TEST(SpscRing, RejectsBadCapacity) {
  EXPECT_THROW(SpscRing<Rec>(3), std::invalid_argument);
  EXPECT_THROW(SpscRing<Rec>(0), std::invalid_argument);
}

TEST(SpscRing, FullRingDropsAndCountsNeverBlocks) {
  SpscRing<Rec> r(4);
  for (std::uint64_t i = 0; i < 4; ++i) EXPECT_TRUE(r.push({i, 0.0}));
  EXPECT_FALSE(r.push({99, 0.0}));
  EXPECT_EQ(r.dropped(), 1u);
  Rec out{};
  ASSERT_TRUE(r.pop(out));
  EXPECT_EQ(out.seq, 0u);
  EXPECT_TRUE(r.push({4, 0.0}));
  for (std::uint64_t i = 1; i <= 4; ++i) {
    ASSERT_TRUE(r.pop(out));
    EXPECT_EQ(out.seq, i);
  }
  EXPECT_FALSE(r.pop(out));
}

TEST(SpscRing, TwoThreadsKeepOrderAndAccountForEveryRecord) {
  SpscRing<Rec> r(64);
  constexpr std::uint64_t kN = 200000;
  std::uint64_t received = 0;
  std::uint64_t last = 0;
  bool ordered = true;
  std::atomic<bool> producer_done{false};
  std::thread consumer([&] {
    Rec v{};
    // Runs until the producer is done and the ring is drained (no idle-count heuristic: under
    // CPU contention a yield can take milliseconds, and the last record may have been dropped).
    for (;;) {
      const bool done = producer_done.load(std::memory_order_acquire);
      if (r.pop(v)) {
        if (received > 0 && v.seq <= last) ordered = false;
        last = v.seq;
        ++received;
        continue;
      }
      if (done) break;  // done was seen before this empty pop: nothing more will come
      std::this_thread::yield();
    }
  });
  for (std::uint64_t i = 0; i < kN; ++i) r.push({i, static_cast<double>(i)});
  producer_done.store(true, std::memory_order_release);
  consumer.join();
  Rec v{};
  while (r.pop(v)) ++received;
  EXPECT_TRUE(ordered);
  EXPECT_EQ(received + r.dropped(), kN);
}

TEST(SpscRing, PushPopDoNotAllocate) {
  SpscRing<Rec> r(1024);
  contour::test::AllocGuard g;
  Rec out{};
  for (std::uint64_t i = 0; i < 10000; ++i) {
    r.push({i, 1.0});
    r.pop(out);
  }
  EXPECT_EQ(g.counts().total(), 0u);
}

TEST(LatencyHistogram, QuantilesAndBins) {
  LatencyHistogram h;
  for (int i = 0; i < 990; ++i) h.record(10'500);     // 10.5 us
  for (int i = 0; i < 10; ++i) h.record(2'500'000);   // 2.5 ms
  EXPECT_EQ(h.count(), 1000u);
  EXPECT_DOUBLE_EQ(h.quantile_us(0.5), 11.0);          // upper edge of the 10 us bin
  EXPECT_DOUBLE_EQ(h.quantile_us(0.99), 11.0);
  EXPECT_DOUBLE_EQ(h.quantile_us(0.999), 2501.0);    // 1 us bins up to 20 ms
  EXPECT_EQ(h.max_ns(), 2'500'000);
  EXPECT_EQ(h.min_ns(), 10'500);
  EXPECT_NEAR(h.mean_us(), (990 * 10.5 + 10 * 2500.0) / 1000.0, 1e-9);
  h.record(30'050'000);                                // 30.05 ms: a 100 us bin
  EXPECT_DOUBLE_EQ(h.quantile_us(1.0), 30100.0);
  h.record(-5);  // clock anomalies land in bin 0, never out of range
  h.record(10'000'000'000);
  EXPECT_EQ(h.bin_count(LatencyHistogram::kBins - 1), 1u);
}

TEST(LatencyHistogram, RecordDoesNotAllocate) {
  LatencyHistogram h;
  contour::test::AllocGuard g;
  for (int i = 0; i < 10000; ++i) h.record(i * 1000);
  EXPECT_EQ(g.counts().total(), 0u);
}
