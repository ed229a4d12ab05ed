#pragma once
// Dynamometer register map: plain data, C++ standard library only, so that config/ (which parses
// it from YAML), drivers/ (which decodes it) and the simulated dynamometer (which encodes it) share
// one definition. Addresses are 0-based PDU addresses (mbpoll -0 convention).
#include <array>
#include <cstdint>
#include <string>

namespace contour::drivers::modbus {

enum class RegisterFunction { kInput, kHolding };  // FC 04 / FC 03
enum class RegisterType { kInt16, kUint16, kInt32, kFloat32 };
// Byte order of a value's bytes A (most significant) .. D across registers r0, r1:
// abcd: r0=AB r1=CD (Modbus big-endian); badc: r0=BA r1=DC (bytes swapped in each word);
// cdab: r0=CD r1=AB (words swapped); dcba: r0=DC r1=BA (little-endian).
// 16-bit types use one register: abcd/cdab -> AB, badc/dcba -> BA.
enum class WordOrder { kAbcd, kBadc, kCdab, kDcba };

enum class Axis { kFx = 0, kFy = 1, kFz = 2 };
inline constexpr std::size_t kForceChannels = 3;
// The poll reads the map as one contiguous block; a dynamometer's force block is a few registers.
inline constexpr std::size_t kMaxBlockRegisters = 32;

struct ChannelMap {
  bool enabled = false;
  std::uint16_t address = 0;  // 0-based
  RegisterType type = RegisterType::kInt16;
  WordOrder order = WordOrder::kAbcd;
  double scale = 1.0;  // N per raw count: force_N = raw * scale + offset_N
  double offset_N = 0.0;
};

struct StatusMap {
  bool enabled = false;
  std::uint16_t address = 0;
  unsigned valid_bit = 0;      // 0..15
  bool valid_when_set = true;  // false: the bit is an "invalid/overload" flag
};

struct RegisterMap {
  RegisterFunction function = RegisterFunction::kInput;
  std::array<ChannelMap, kForceChannels> channels{};  // index = Axis
  StatusMap status{};
};

[[nodiscard]] constexpr unsigned register_count(RegisterType t) {
  return (t == RegisterType::kInt32 || t == RegisterType::kFloat32) ? 2u : 1u;
}

// Contiguous block [start, start + count) covering every enabled channel and the status register.
struct RegisterBlock {
  std::uint16_t start = 0;
  std::uint16_t count = 0;  // 0: nothing enabled
};

[[nodiscard]] inline RegisterBlock register_block(const RegisterMap& m) {
  unsigned lo = 0x10000u;
  unsigned hi = 0;
  auto cover = [&](unsigned a, unsigned n) {
    if (a < lo) lo = a;
    if (a + n > hi) hi = a + n;
  };
  for (const auto& c : m.channels)
    if (c.enabled) cover(c.address, register_count(c.type));
  if (m.status.enabled) cover(m.status.address, 1);
  if (hi == 0) return {};
  return {static_cast<std::uint16_t>(lo), static_cast<std::uint16_t>(hi - lo)};
}

[[nodiscard]] inline const char* to_string(RegisterType t) {
  switch (t) {
    case RegisterType::kInt16:
      return "int16";
    case RegisterType::kUint16:
      return "uint16";
    case RegisterType::kInt32:
      return "int32";
    case RegisterType::kFloat32:
      return "float32";
  }
  return "?";
}
[[nodiscard]] inline const char* to_string(WordOrder o) {
  switch (o) {
    case WordOrder::kAbcd:
      return "abcd";
    case WordOrder::kBadc:
      return "badc";
    case WordOrder::kCdab:
      return "cdab";
    case WordOrder::kDcba:
      return "dcba";
  }
  return "?";
}

}  // namespace contour::drivers::modbus
