// Google Benchmark of the per-cycle CANopen work (issue 11): for 3 CiA 402 axes in cyclic
// synchronous position mode, pack the RPDO (controlword 0x6040 u16 + target position 0x607A i32)
// with mm -> counts scaling, and unpack the TPDO (statusword 0x6041 u16 + position actual 0x6064
// i32) with 32-bit unwrap and counts -> mm. Single-frame pack/unpack and the other decoders the
// master runs on received frames (heartbeat, EMCY, statusword) are measured separately.
#include <benchmark/benchmark.h>

#include <array>
#include <cstdint>

#include "drivers/canopen/codec.hpp"

using namespace contour::drivers;
using namespace contour::drivers::canopen;

namespace {

PdoMapping rpdo_map() {
  PdoMapping m;
  m.entries[0] = PdoEntry{0x6040, 0, 16};
  m.entries[1] = PdoEntry{0x607A, 0, 32};
  m.count = 2;
  return m;
}
PdoMapping tpdo_map() {
  PdoMapping m;
  m.entries[0] = PdoEntry{0x6041, 0, 16};
  m.entries[1] = PdoEntry{0x6064, 0, 32};
  m.count = 2;
  return m;
}

constexpr double kCountsPerMm = 10000.0;

void BM_PdoPack(benchmark::State& state) {
  const PdoMapping m = rpdo_map();
  PdoValues v{};
  CanFrame f;
  std::int64_t k = 0;
  for (auto _ : state) {
    v[0] = 0x000F;
    v[1] = k++;
    pack_pdo(m, v, f);
    benchmark::DoNotOptimize(f.data.data());
  }
}
BENCHMARK(BM_PdoPack);

void BM_PdoUnpack(benchmark::State& state) {
  const PdoMapping m = tpdo_map();
  PdoValues v{};
  CanFrame f;
  pack_pdo(m, PdoValues{0x1237, 123456, 0, 0, 0, 0, 0, 0}, f);
  for (auto _ : state) {
    benchmark::DoNotOptimize(f.data.data());
    const bool ok = unpack_pdo(m, f, v);
    benchmark::DoNotOptimize(ok);
    benchmark::DoNotOptimize(v.data());
  }
}
BENCHMARK(BM_PdoUnpack);

// Everything the master does with PDOs in one 3-axis cycle.
void BM_PdoCycle3Axis(benchmark::State& state) {
  const PdoMapping rm = rpdo_map(), tm = tpdo_map();
  std::array<CanFrame, 3> rx{}, tx{};
  std::array<PositionUnwrapper, 3> unwrap{};
  std::array<Cia402Sequencer, 3> seq{};
  std::array<double, 3> cmd_mm{0.0, 0.0, 0.0}, pos_mm{};
  for (std::size_t a = 0; a < 3; ++a) {
    pack_pdo(tm, PdoValues{statusword_for(Cia402State::kOperationEnabled), 0, 0, 0, 0, 0, 0, 0},
             rx[a]);
    rx[a].id = kCobTpdo[0] + static_cast<std::uint32_t>(a + 1);
  }
  std::int32_t drive_counts = 0x7FFFFF00;  // crosses the 32-bit wrap during the run
  for (auto _ : state) {
    drive_counts = static_cast<std::int32_t>(static_cast<std::uint32_t>(drive_counts) + 17u);
    for (std::size_t a = 0; a < 3; ++a) {
      put_u32(&rx[a].data[2], static_cast<std::uint32_t>(drive_counts));
      benchmark::DoNotOptimize(rx[a].data.data());
      PdoValues in{};
      if (!unpack_pdo(tm, rx[a], in)) state.SkipWithError("short TPDO");
      const Cia402State st = decode_statusword(static_cast<std::uint16_t>(in[0]));
      pos_mm[a] = counts_to_mm(unwrap[a].update(as_i32(in[1])), kCountsPerMm);
      cmd_mm[a] += 0.0667;
      PdoValues out{};
      out[0] = seq[a].next(st, DriveRequest::kEnabled, false);
      out[1] = mm_to_counts_wrapped(cmd_mm[a], kCountsPerMm);
      pack_pdo(rm, out, tx[a]);
      tx[a].id = kCobRpdo[0] + static_cast<std::uint32_t>(a + 1);
    }
    benchmark::DoNotOptimize(tx.data());
    benchmark::DoNotOptimize(pos_mm.data());
  }
}
BENCHMARK(BM_PdoCycle3Axis);

void BM_DecodeHeartbeatEmcy(benchmark::State& state) {
  const CanFrame hb = heartbeat_frame(3, NmtState::kOperational);
  Emcy e;
  e.code = 0x2310;
  e.error_register = 0x03;
  const CanFrame em = emcy_frame(3, e);
  for (auto _ : state) {
    benchmark::DoNotOptimize(decode_heartbeat(hb));
    benchmark::DoNotOptimize(decode_emcy(em));
  }
}
BENCHMARK(BM_DecodeHeartbeatEmcy);

}  // namespace

BENCHMARK_MAIN();
