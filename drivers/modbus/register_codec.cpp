#include "drivers/modbus/register_codec.hpp"

#include <bit>
#include <cmath>
#include <limits>

namespace contour::drivers::modbus {

namespace {
constexpr std::uint16_t swap_bytes(std::uint16_t v) noexcept {
  return static_cast<std::uint16_t>(((v & 0x00FFu) << 8) | ((v & 0xFF00u) >> 8));
}
template <typename T>
T saturate_round(double v) noexcept {
  if (std::isnan(v)) return T{0};
  const double r = std::nearbyint(v);
  if (r <= static_cast<double>(std::numeric_limits<T>::min())) return std::numeric_limits<T>::min();
  if (r >= static_cast<double>(std::numeric_limits<T>::max())) return std::numeric_limits<T>::max();
  return static_cast<T>(r);
}
}  // namespace

std::uint32_t join32(std::uint16_t r0, std::uint16_t r1, WordOrder order) noexcept {
  std::uint16_t hi = r0;
  std::uint16_t lo = r1;
  switch (order) {
    case WordOrder::kAbcd:
      break;
    case WordOrder::kBadc:
      hi = swap_bytes(r0);
      lo = swap_bytes(r1);
      break;
    case WordOrder::kCdab:
      hi = r1;
      lo = r0;
      break;
    case WordOrder::kDcba:
      hi = swap_bytes(r1);
      lo = swap_bytes(r0);
      break;
  }
  return (static_cast<std::uint32_t>(hi) << 16) | lo;
}

void split32(std::uint32_t abcd, WordOrder order, std::uint16_t& r0, std::uint16_t& r1) noexcept {
  const auto hi = static_cast<std::uint16_t>(abcd >> 16);
  const auto lo = static_cast<std::uint16_t>(abcd & 0xFFFFu);
  switch (order) {
    case WordOrder::kAbcd:
      r0 = hi;
      r1 = lo;
      break;
    case WordOrder::kBadc:
      r0 = swap_bytes(hi);
      r1 = swap_bytes(lo);
      break;
    case WordOrder::kCdab:
      r0 = lo;
      r1 = hi;
      break;
    case WordOrder::kDcba:
      r0 = swap_bytes(lo);
      r1 = swap_bytes(hi);
      break;
  }
}

std::uint16_t join16(std::uint16_t r0, WordOrder order) noexcept {
  return (order == WordOrder::kBadc || order == WordOrder::kDcba) ? swap_bytes(r0) : r0;
}

RawValue decode_raw(std::span<const std::uint16_t> regs, RegisterType type,
                    WordOrder order) noexcept {
  if (regs.size() < register_count(type)) return {};
  switch (type) {
    case RegisterType::kInt16:
      return {static_cast<double>(std::bit_cast<std::int16_t>(join16(regs[0], order))), true};
    case RegisterType::kUint16:
      return {static_cast<double>(join16(regs[0], order)), true};
    case RegisterType::kInt32:
      return {static_cast<double>(std::bit_cast<std::int32_t>(join32(regs[0], regs[1], order))),
              true};
    case RegisterType::kFloat32: {
      const float f = std::bit_cast<float>(join32(regs[0], regs[1], order));
      return {static_cast<double>(f), std::isfinite(f)};
    }
  }
  return {};
}

RawValue decode_newtons(std::span<const std::uint16_t> regs, const ChannelMap& ch) noexcept {
  RawValue r = decode_raw(regs, ch.type, ch.order);
  r.value = r.value * ch.scale + ch.offset_N;
  return r;
}

bool encode_raw(double raw, RegisterType type, WordOrder order,
                std::span<std::uint16_t> regs) noexcept {
  if (regs.size() < register_count(type)) return false;
  switch (type) {
    case RegisterType::kInt16: {
      const auto v = std::bit_cast<std::uint16_t>(saturate_round<std::int16_t>(raw));
      regs[0] = join16(v, order);  // the byte swap is its own inverse
      return true;
    }
    case RegisterType::kUint16:
      regs[0] = join16(saturate_round<std::uint16_t>(raw), order);
      return true;
    case RegisterType::kInt32:
      split32(std::bit_cast<std::uint32_t>(saturate_round<std::int32_t>(raw)), order, regs[0],
              regs[1]);
      return true;
    case RegisterType::kFloat32:
      split32(std::bit_cast<std::uint32_t>(static_cast<float>(raw)), order, regs[0], regs[1]);
      return true;
  }
  return false;
}

bool encode_newtons(double force_N, const ChannelMap& ch, std::span<std::uint16_t> regs) noexcept {
  const double raw = ch.scale != 0.0 ? (force_N - ch.offset_N) / ch.scale : 0.0;
  return encode_raw(raw, ch.type, ch.order, regs);
}

bool status_valid(std::uint16_t status_reg, const StatusMap& st) noexcept {
  if (!st.enabled) return true;
  const bool set = ((status_reg >> st.valid_bit) & 1u) != 0;
  return set == st.valid_when_set;
}

}  // namespace contour::drivers::modbus
