// libFuzzer target (issue 11): the pure CANopen codecs on arbitrary frames.
// Input: a sequence of 12-byte records {id lo, id hi, dlc, flags, data[8]}. Each frame goes through
// every decoder the master runs on received traffic (heartbeat, EMCY, PDO unpack with a mapping
// taken from the input's first bytes, statusword, position unwrap), and through one SDO client
// transfer (upload or download, chosen by the first byte) as a server response.
// Contract checked (drivers/canopen/codec.hpp): decoders are noexcept and never read beyond dlc /
// the 8 data bytes (ASan); unpack_pdo fails iff dlc < mapping bytes; decode_emcy needs dlc 8;
// pack -> unpack round-trips; SdoTransfer::on_frame never throws, answers only its own COB-ID,
// ends in kDone or kAborted (a received abort or one it raises), never holds more data than the
// server indicated, and every frame it returns is a well-formed 8-byte SDO request on 0x600+node.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <span>

#include "drivers/canopen/codec.hpp"

using namespace contour::drivers;
using namespace contour::drivers::canopen;

namespace {
void check(bool c, const char* what) {
  if (!c) {
    std::fprintf(stderr, "canopen_fuzz: violated: %s\n", what);
    std::abort();
  }
}

CanFrame frame_at(const std::uint8_t* p) {
  CanFrame f;
  f.id = static_cast<std::uint32_t>(p[0] | (p[1] << 8)) & 0x7FF;
  f.dlc = static_cast<std::uint8_t>(p[2] % 16);  // dlc > 8 is possible on a raw socket
  f.rtr = (p[3] & 1) != 0;
  f.error = (p[3] & 2) != 0;
  for (std::size_t i = 0; i < 8; ++i) f.data[i] = p[4 + i];
  return f;
}

void check_request(const CanFrame& f, std::uint8_t node) {
  check(f.id == kCobSdoRx + node, "SDO request on 0x600+node");
  check(f.dlc == 8, "SDO request dlc 8");
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 8 || size > 12 * 256 + 8) return -1;
  // Header: mapping (4 entries of {bits selector}), node id, SDO mode, download length.
  PdoMapping m;
  static constexpr std::uint8_t kBits[3] = {8, 16, 32};
  std::size_t bits = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const std::uint8_t b = kBits[data[i] % 3];
    if (bits + b > 64) break;
    m.entries[m.count++] = PdoEntry{static_cast<std::uint16_t>(0x6000 + i), 0, b};
    bits += b;
  }
  check(m.validate().empty(), "generated mapping valid");
  const std::uint8_t node = static_cast<std::uint8_t>(1 + data[4] % 127);
  const bool upload = (data[5] & 1) != 0;
  const std::size_t dl_len = data[6] % 64;
  std::uint8_t payload[64];
  for (std::size_t i = 0; i < dl_len; ++i) payload[i] = static_cast<std::uint8_t>(i * 7);

  SdoTransfer sdo;
  const CanFrame first = upload ? sdo.start_upload(node, 0x1018, 1)
                                : sdo.start_download(node, 0x6060, 0,
                                                     std::span<const std::uint8_t>(payload, dl_len));
  check_request(first, node);
  PositionUnwrapper unwrap;

  for (std::size_t off = 8; off + 12 <= size; off += 12) {
    CanFrame f = frame_at(data + off);
    const std::uint8_t dlc = f.dlc;

    if (const auto hb = decode_heartbeat(f)) (void)nmt_state_name(*hb);
    if (const auto e = decode_emcy(f)) {
      check(dlc >= 8, "EMCY decoded from a short frame");
      (void)emcy_code_text(e->code);
      const CanFrame back = emcy_frame(node, *e);
      check(decode_emcy(back).has_value(), "EMCY round trip");
    }
    PdoValues v{};
    const bool ok = unpack_pdo(m, f, v);
    check(ok == (dlc >= m.bytes()), "unpack_pdo accepts iff dlc >= mapping bytes");
    if (ok) {
      CanFrame g;
      pack_pdo(m, v, g);
      check(g.dlc == m.bytes(), "pack dlc");
      PdoValues w{};
      check(unpack_pdo(m, g, w) && w == v, "PDO round trip");
      const Cia402State st = decode_statusword(static_cast<std::uint16_t>(v[0] & 0xFFFF));
      (void)cia402_state_name(st);
      (void)unwrap.update(as_i32(v[m.count - 1]));
    }
    (void)sdo_abort_reason(get_u32(&f.data[4]));

    // Steer some frames onto this transfer's response COB so the state machine gets exercised.
    if ((data[off + 3] & 4) != 0) f.id = kCobSdoTx + node;
    const auto before = sdo.status();
    const std::optional<CanFrame> reply = sdo.on_frame(f);
    if (f.id != kCobSdoTx + node) {
      check(!reply.has_value() && sdo.status() == before, "foreign COB-ID ignored");
    }
    if (reply) check_request(*reply, node);
    if (before == SdoTransfer::Status::kDone || before == SdoTransfer::Status::kAborted) {
      check(sdo.status() == before, "finished transfer stays finished");
    }
    if (upload) check(sdo.data().size() <= 0xFFFFFF, "bounded upload");
  }
  if (sdo.status() == SdoTransfer::Status::kWaiting) {
    const CanFrame t = sdo.timeout_abort();
    check_request(t, node);
    check(sdo.status() == SdoTransfer::Status::kAborted, "timeout aborts");
  }
  return 0;
}
