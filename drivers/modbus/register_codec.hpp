#pragma once
// Pure Modbus register codecs (no libmodbus): decode a channel's registers to its raw value and to
// newtons, and the exact inverse (used by the simulated dynamometer: Debian's libmodbus 3.1.6
// modbus_set_float_* writes swapped words, so the simulator never uses it).
// RT-safe: noexcept, no allocation, O(1).
#include <cstdint>
#include <span>

#include "drivers/modbus/register_map.hpp"

namespace contour::drivers::modbus {

// Joins two registers into the 32-bit pattern ABCD according to `order`.
[[nodiscard]] std::uint32_t join32(std::uint16_t r0, std::uint16_t r1, WordOrder order) noexcept;
// Splits ABCD into registers r0, r1 according to `order` (inverse of join32).
void split32(std::uint32_t abcd, WordOrder order, std::uint16_t& r0, std::uint16_t& r1) noexcept;
// One register's 16-bit value AB (byte swapped for badc/dcba).
[[nodiscard]] std::uint16_t join16(std::uint16_t r0, WordOrder order) noexcept;

// Raw numeric value of `type` from regs[0..register_count(type)). regs.size() must be large
// enough; if not, returns false. Float NaN/inf decode but report `finite == false`.
struct RawValue {
  double value = 0.0;
  bool ok = false;  // enough registers and finite
};
[[nodiscard]] RawValue decode_raw(std::span<const std::uint16_t> regs, RegisterType type,
                                  WordOrder order) noexcept;
// Channel value in newtons: raw * scale + offset_N.
[[nodiscard]] RawValue decode_newtons(std::span<const std::uint16_t> regs,
                                      const ChannelMap& ch) noexcept;

// Encodes `raw` (rounded and saturated for integer types) into regs[0..register_count(type)).
// Returns false if regs is too small.
bool encode_raw(double raw, RegisterType type, WordOrder order,
                std::span<std::uint16_t> regs) noexcept;
// Encodes a force in newtons through the channel's scale and offset (inverse of decode_newtons up
// to integer rounding: |error| <= scale / 2 for integer types).
bool encode_newtons(double force_N, const ChannelMap& ch, std::span<std::uint16_t> regs) noexcept;

// Status register valid bit (true when the map has no status register).
[[nodiscard]] bool status_valid(std::uint16_t status_reg, const StatusMap& st) noexcept;

}  // namespace contour::drivers::modbus
