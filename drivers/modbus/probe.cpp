#include "drivers/modbus/probe.hpp"

#include <array>
#include <chrono>
#include <stdexcept>
#include <thread>

namespace contour::drivers::modbus {

const char* error_kind_name(ErrorKind k) noexcept {
  switch (k) {
    case ErrorKind::kNone: return "none";
    case ErrorKind::kTimeout: return "timeout";
    case ErrorKind::kException: return "exception";
    case ErrorKind::kConnection: return "connection";
    case ErrorKind::kProtocol: return "protocol";
    case ErrorKind::kConfig: return "config";
  }
  return "?";
}

std::vector<ProbeRecord> probe_dynamometer(const DynamometerSettings& s, int count) {
  std::vector<ProbeRecord> out;
  out.reserve(static_cast<std::size_t>(count > 0 ? count : 0));
  probe_dynamometer(s, count, [&](const ProbeRecord& r) { out.push_back(r); });
  return out;
}

void probe_dynamometer(const DynamometerSettings& s, int count,
                       const std::function<void(const ProbeRecord&)>& on_record) {
  const RegisterBlock block = register_block(s.map);
  if (block.count == 0 || block.count > kMaxBlockRegisters)
    throw std::invalid_argument("probe: register map must cover 1.." +
                                std::to_string(kMaxBlockRegisters) + " registers");
  if (count < 1) throw std::invalid_argument("probe: count must be >= 1");
  using Clock = std::chrono::steady_clock;
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / (s.poll_rate_hz > 0 ? s.poll_rate_hz : 200.0)));
  ModbusClient client(s.transport);
  std::array<std::uint16_t, kMaxBlockRegisters> regs{};
  const std::span<std::uint16_t> span(regs.data(), block.count);
  std::uint64_t seq = 0;
  auto next = Clock::now();
  for (int i = 0; i < count; ++i) {
    ProbeRecord r;
    r.index = i;
    ModbusError e = client.connect();
    const auto t0 = Clock::now();
    if (!e) e = client.read_registers(s.map.function, block.start, span);
    r.latency_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (!e) {
      r.ok = true;
      decode_block(s.map, block.start, span, r.sample);
      r.sample.t_ns = steady_now_ns();
      r.sample.seq = ++seq;
    } else {
      r.error = e.kind;
      r.error_text = e.text;
      if (e.kind == ErrorKind::kTimeout || e.kind == ErrorKind::kProtocol) client.flush();
      if (e.kind == ErrorKind::kConnection) client.close();
    }
    on_record(r);
    if (i + 1 == count) break;  // no wait after the last sample
    next += period;
    std::this_thread::sleep_until(next);
  }
}

}  // namespace contour::drivers::modbus
