// Regression test for a g++ 12.2 (Debian 12) miscompilation of PositionUnwrapper::update (issue
// 17). tests/CMakeLists.txt compiles this file at -O3 in every build type, so the ci, dev and
// release-o3 builds all exercise the optimiser that broke it.
//
// What happened: with the last reading kept as int32_t and the step computed as
// int32_t(uint32_t(raw) - uint32_t(last)) (valid C++20, UBSan-clean), g++ 12.2 -O3 inlines update()
// into a loop whose readings are a 64-bit counter truncated to int32, models the truncated
// readings as an int32 sequence that does not wrap, and value range propagation then folds the
// stored last reading to its first value: every step after the first is measured from the start
// (8999 of the 9000 steps of the wrap test wrong; correct at -O2 and with clang 14 -O3; -fwrapv or
// -fno-tree-vrp hide it). A stand-alone 25-line copy of the old class reproduces it:
//   g++ -std=c++20 -O3 repro.cpp && ./a.out   -> 8999 wrong steps (g++ 12.2.0-14)
// The loops below are the shapes that failed (a, b, d) plus the ones that did not (c, e), all
// on the real class, here inlined into the caller exactly as in that reproducer. With the old
// update() restored, a, b and d fail in this file (measured: 8999, 2998 and 3002 wrong steps).
//
// Each loop counts wrong steps and reports the first, instead of one EXPECT per step: a
// regression is 1000s of identical failures.
#include <gtest/gtest.h>

#include <cstdint>
#include <sstream>
#include <string>

#include "drivers/canopen/codec.hpp"

namespace co = contour::drivers::canopen;

namespace {

// What a drive's 32-bit position register shows for a true 64-bit count.
std::int32_t register_bits(std::int64_t counts) {
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(counts & 0xFFFFFFFF));
}

struct Mismatches {
  int count = 0;
  std::string first;
  void check(bool ok, int step, std::int64_t got, std::int64_t want) {
    if (ok) return;
    if (count++ == 0) {
      std::ostringstream o;
      o << "step " << step << ": got " << got << ", want " << want;
      first = o.str();
    }
  }
};

}  // namespace

// a: the unit test's shape (Scaling.UnwrapperFollowsAcross32BitWrapBothWays): forward over +2^31
// in 1000-count steps, then back past the start.
TEST(PositionUnwrapperO3, ForwardOverPlusTwoPow31AndBack) {
  co::PositionUnwrapper u;
  u.reset(2147483000);
  std::int64_t counts = 2147483000;
  Mismatches m;
  int step = 0;
  for (int k = 0; k < 3000; ++k, ++step) {
    counts += 1000;
    const std::int64_t got = u.update(register_bits(counts));
    m.check(got == counts, step, got, counts);
  }
  for (int k = 0; k < 6000; ++k, ++step) {
    counts -= 1000;
    const std::int64_t got = u.update(register_bits(counts));
    m.check(got == counts, step, got, counts);
  }
  EXPECT_EQ(m.count, 0) << "wrong steps of 9000; first " << m.first;
  EXPECT_EQ(u.value(), 2147483000 - 3000 * 1000);
}

// b: a 64-bit counter truncated with a plain cast (no reset: the first update primes).
TEST(PositionUnwrapperO3, TruncatedCounterForward) {
  co::PositionUnwrapper u;
  Mismatches m;
  int step = 0;
  for (std::int64_t counts = 2147483000; counts < 2147483000LL + 3000000; counts += 1000, ++step) {
    const std::int64_t got = u.update(static_cast<std::int32_t>(counts));
    m.check(got == counts, step, got, counts);
  }
  EXPECT_EQ(m.count, 0) << "wrong steps of 3000; first " << m.first;
}

// c: the register itself as an unsigned counter crossing 0 (0xFFFFFFFF -> 0) and 2^31.
TEST(PositionUnwrapperO3, UnsignedRegisterAcrossZeroAndTwoPow31) {
  co::PositionUnwrapper u;
  Mismatches m;
  std::uint32_t bits = 0xFFFFF000u;
  std::int64_t want = -4096;
  for (int k = 0; k < 2200000; ++k, bits += 977u, want += 977) {
    const std::int64_t got = u.update(static_cast<std::int32_t>(bits));
    m.check(got == want, k, got, want);
  }
  EXPECT_EQ(m.count, 0) << "wrong steps of 2200000; first " << m.first;
  EXPECT_GT(want, std::int64_t{1} << 31);  // the loop did cross 2^31
}

// d: backward through -2^31 (0x80000000 -> 0x7FFFFFFF).
TEST(PositionUnwrapperO3, TruncatedCounterBackwardOverMinusTwoPow31) {
  co::PositionUnwrapper u;
  Mismatches m;
  int step = 0;
  for (std::int64_t counts = -2147483000; counts > -2147483000LL - 3000000;
       counts -= 999, ++step) {
    const std::int64_t got = u.update(static_cast<std::int32_t>(counts));
    m.check(got == counts, step, got, counts);
  }
  EXPECT_EQ(m.count, 0) << "wrong steps of 3004; first " << m.first;
}

// e: the largest steps either way (2^31 - 1 forward, -2^31 backward: the fold's two edges).
TEST(PositionUnwrapperO3, LargestStepsBothWays) {
  co::PositionUnwrapper u;
  std::int64_t counts = 12345;
  u.reset(register_bits(counts));
  Mismatches m;
  for (int k = 0; k < 64; ++k) {
    counts += (k % 3 == 2) ? -(std::int64_t{1} << 31) : (std::int64_t{1} << 31) - 1;
    const std::int64_t got = u.update(register_bits(counts));
    m.check(got == counts, k, got, counts);
  }
  EXPECT_EQ(m.count, 0) << "wrong steps of 64; first " << m.first;
  // One count more than half the range is the shorter way round backwards.
  co::PositionUnwrapper v;
  v.reset(0);
  EXPECT_EQ(v.update(register_bits((std::int64_t{1} << 31) + 1)), -((std::int64_t{1} << 31) - 1));
}
