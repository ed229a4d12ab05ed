#pragma once
// Single-producer single-consumer triple buffer: the latest value wins, neither side ever blocks or
// allocates, no data race (each slot is owned by exactly one side between index exchanges).
// Producer: the Modbus poll thread. Consumer: the RT loop (read() is wait-free, O(sizeof(T))).
#include <array>
#include <atomic>
#include <cstdint>
#include <type_traits>

namespace contour::drivers {

template <typename T>
class TripleBuffer {
  static_assert(std::is_trivially_copyable_v<T>);

 public:
  // Producer only.
  void write(const T& v) noexcept {
    slots_[back_] = v;
    const std::uint8_t prev =
        middle_.exchange(static_cast<std::uint8_t>(back_ | kDirty), std::memory_order_acq_rel);
    back_ = prev & kIndex;
  }
  // Consumer only. Returns true if a value newer than the previous read was taken; `out` always
  // receives the latest value published (default-constructed T before the first write).
  bool read(T& out) noexcept {
    bool fresh = false;
    if (middle_.load(std::memory_order_relaxed) & kDirty) {
      const std::uint8_t prev = middle_.exchange(front_, std::memory_order_acq_rel);
      front_ = prev & kIndex;
      fresh = true;
    }
    out = slots_[front_];
    return fresh;
  }

 private:
  static constexpr std::uint8_t kDirty = 0x4;
  static constexpr std::uint8_t kIndex = 0x3;
  std::array<T, 3> slots_{};
  alignas(64) std::atomic<std::uint8_t> middle_{1};
  alignas(64) std::uint8_t back_ = 2;   // producer's
  alignas(64) std::uint8_t front_ = 0;  // consumer's
};

}  // namespace contour::drivers
