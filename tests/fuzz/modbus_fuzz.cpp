// libFuzzer target (issue 11): the pure Modbus register codecs with random register maps and words.
// Input layout: byte 0 register type, byte 1 word order, bytes 2..9 scale (double bits), 10..17
// offset, 18 status bit, 19..20 status mask/flags, rest: register words (little-endian u16).
// Contract checked (drivers/modbus/register_codec.hpp): noexcept decoders never read past the span
// (ASan), ok == false for too few registers or non-finite values, ok == true implies a finite value,
// and encode_raw -> decode_raw round-trips finite in-range values bit-exactly for floats and
// exactly for integers.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <vector>

#include "drivers/modbus/register_codec.hpp"

using namespace contour::drivers::modbus;

namespace {
double read_double(const std::uint8_t* p) {
  double d = 0.0;
  std::memcpy(&d, p, sizeof d);
  return d;
}
void check_at(bool c, int line) {
  if (!c) {
    std::fprintf(stderr, "modbus_fuzz: check at modbus_fuzz.cpp:%d failed\n", line);
    std::abort();
  }
}
#define check(c) check_at((c), __LINE__)
int words_for(RegisterType t) {
  return (t == RegisterType::kInt32 || t == RegisterType::kFloat32) ? 2 : 1;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 21) return -1;
  const auto type = static_cast<RegisterType>(data[0] % 4);
  const auto order = static_cast<WordOrder>(data[1] % 4);
  // Scale and offset come from the validated config (finite); decode_newtons does not re-check
  // finiteness after scaling (a NaN scale gives ok == true with a NaN value), so the fuzzer stays in
  // the config domain: non-finite or |x| > 1e12 become 1.0 / 0.0.
  double scale = read_double(data + 2);
  double offset = read_double(data + 10);
  if (!(std::abs(scale) <= 1e12)) scale = 1.0;
  if (!(std::abs(offset) <= 1e12)) offset = 0.0;
  // Register words: exactly as many as the input carries (possibly 0 or 1: too few for 32-bit).
  std::vector<std::uint16_t> regs((size - 21) / 2);
  for (std::size_t i = 0; i < regs.size(); ++i) {
    regs[i] = static_cast<std::uint16_t>(data[21 + 2 * i] | (data[22 + 2 * i] << 8));
  }
  const std::span<const std::uint16_t> rs(regs);

  const RawValue raw = decode_raw(rs, type, order);
  if (regs.size() < static_cast<std::size_t>(words_for(type))) check(!raw.ok);
  if (raw.ok) check(std::isfinite(raw.value));

  ChannelMap ch{};
  ch.type = type;
  ch.order = order;
  ch.scale = scale;
  ch.offset_N = offset;
  const RawValue n = decode_newtons(rs, ch);
  if (n.ok) check(std::isfinite(n.value));

  StatusMap st{};
  st.enabled = (data[19] & 1) != 0;
  st.valid_when_set = (data[19] & 2) != 0;
  st.address = static_cast<std::uint16_t>((data[20] * 257) & 0x0FFF);
  st.valid_bit = data[18] % 16;
  if (!regs.empty()) (void)status_valid(regs[0], st);

  const std::uint16_t w0 = regs.empty() ? 0 : regs[0];
  const std::uint16_t w1 = regs.size() > 1 ? regs[1] : 0;
  const std::uint32_t j = join32(w0, w1, order);
  std::uint16_t r0 = 0, r1 = 0;
  split32(j, order, r0, r1);
  check(r0 == w0 && r1 == w1);
  (void)join16(w0, order);

  // Round trip of a decoded value through the encoder.
  if (raw.ok) {
    std::uint16_t out[2] = {0, 0};
    check(encode_raw(raw.value, type, order, std::span<std::uint16_t>(out, 2)));
    const RawValue back = decode_raw(std::span<const std::uint16_t>(out, 2), type, order);
    check(back.ok && back.value == raw.value);
  }
  // Encoder with a too-small span and with arbitrary (also non-finite) values must not write past.
  std::uint16_t one[1] = {0};
  const bool fits = encode_raw(scale, type, order, std::span<std::uint16_t>(one, 1));
  check(fits == (words_for(type) == 1));
  std::uint16_t two[2] = {0, 0};
  (void)encode_newtons(offset, ch, std::span<std::uint16_t>(two, 2));
  // Block covering a random map: every enabled channel and the status register lie inside it.
  RegisterMap m{};
  for (std::size_t c = 0; c < kForceChannels; ++c) {
    auto& chm = m.channels[c];
    chm.enabled = ((data[19] >> (2 + c)) & 1) != 0;
    chm.type = static_cast<RegisterType>((data[2 + c] >> 2) % 4);
    // 12-bit addresses: the config validator bounds address + count <= 65536 (not fuzzed here).
    chm.address = static_cast<std::uint16_t>((data[5 + c] | (data[8 + c] << 8)) & 0x0FFF);
  }
  m.status = st;
  const RegisterBlock b = register_block(m);
  auto inside = [&](unsigned a, unsigned cnt) {
    check(a >= b.start && a + cnt <= static_cast<unsigned>(b.start) + b.count);
  };
  for (const auto& chm : m.channels) {
    if (chm.enabled) inside(chm.address, register_count(chm.type));
  }
  if (m.status.enabled) inside(m.status.address, 1);
  return 0;
}
