#include "drivers/modbus/dynamometer_reader.hpp"

#include <stdexcept>
#include <utility>

#include "drivers/modbus/register_codec.hpp"

namespace contour::drivers::modbus {

const char* to_string(ForceState s) noexcept {
  switch (s) {
    case ForceState::kOk:
      return "ok";
    case ForceState::kNoData:
      return "no_data";
    case ForceState::kStale:
      return "stale";
    case ForceState::kInvalid:
      return "invalid";
  }
  return "?";
}

void decode_block(const RegisterMap& map, std::uint16_t start, std::span<const std::uint16_t> regs,
                  ForceSample& out) noexcept {
  out.raw_start = start;
  out.raw_count = static_cast<std::uint16_t>(std::min(regs.size(), out.raw.size()));
  for (std::size_t i = 0; i < out.raw_count; ++i) out.raw[i] = regs[i];
  bool valid = true;
  for (std::size_t c = 0; c < kForceChannels; ++c) {
    const ChannelMap& ch = map.channels[c];
    out.present[c] = ch.enabled;
    out.force_N[c] = 0.0;
    if (!ch.enabled) continue;
    const std::size_t off = static_cast<std::size_t>(ch.address - start);
    if (ch.address < start || off >= regs.size()) {
      valid = false;
      continue;
    }
    const RawValue v = decode_newtons(regs.subspan(off), ch);
    out.force_N[c] = v.ok ? v.value : 0.0;
    valid = valid && v.ok;
  }
  if (map.status.enabled) {
    const std::size_t off = static_cast<std::size_t>(map.status.address - start);
    valid = valid && map.status.address >= start && off < regs.size() &&
            status_valid(regs[off], map.status);
  }
  out.valid = valid;
}

DynamometerReader::DynamometerReader(DynamometerSettings s) : s_(std::move(s)) {
  block_ = register_block(s_.map);
  if (block_.count == 0) throw std::invalid_argument("dynamometer: no channel mapped");
  if (block_.count > kMaxBlockRegisters)
    throw std::invalid_argument("dynamometer: mapped registers span " +
                                std::to_string(block_.count) + " registers (max " +
                                std::to_string(kMaxBlockRegisters) + ")");
  if (!(s_.poll_rate_hz > 0.0 && s_.poll_rate_hz <= 2000.0))
    throw std::invalid_argument("dynamometer: poll_rate_hz must be in (0, 2000]");
  if (s_.timeouts_before_reconnect < 1) s_.timeouts_before_reconnect = 1;
  s_.filter.sample_rate_hz = s_.poll_rate_hz;
  if (s_.filter_enabled) ForceFilter{s_.filter};  // validates (throws std::invalid_argument)
}

DynamometerReader::~DynamometerReader() { stop(); }

void DynamometerReader::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void DynamometerReader::stop() {
  {
    std::lock_guard lk(mu_);
    stop_.store(true);
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool DynamometerReader::wait_until(std::chrono::steady_clock::time_point t) {
  std::unique_lock lk(mu_);
  return !cv_.wait_until(lk, t, [this] { return stop_.load(); });
}

void DynamometerReader::set_error(const std::string& text) {
  std::lock_guard lk(mu_);
  last_error_ = text;
}

ForceReading DynamometerReader::read(std::int64_t now_ns) noexcept {
  ForceReading r;
  r.fresh = mailbox_.read(r.sample);
  if (r.sample.seq == 0) {
    r.state = ForceState::kNoData;
    return r;
  }
  r.age_ns = now_ns - r.sample.t_ns;
  const auto stale_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(s_.stale_after).count();
  if (r.age_ns > stale_ns)
    r.state = ForceState::kStale;
  else
    r.state = r.sample.valid ? ForceState::kOk : ForceState::kInvalid;
  return r;
}

DynamometerStatus DynamometerReader::status() const {
  DynamometerStatus st;
  st.connected = connected_.load();
  st.polls = polls_.load();
  st.samples = samples_.load();
  st.timeouts = timeouts_.load();
  st.exceptions = exceptions_.load();
  st.protocol_errors = protocol_errors_.load();
  st.connection_errors = connection_errors_.load();
  st.reconnects = reconnects_.load();
  st.invalid = invalid_.load();
  std::lock_guard lk(mu_);
  st.last_error = last_error_;
  return st;
}

void DynamometerReader::run() {
  using Clock = std::chrono::steady_clock;
  ModbusClient client(s_.transport);
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / s_.poll_rate_hz));
  std::array<std::uint16_t, kMaxBlockRegisters> regs{};
  const std::span<std::uint16_t> block(regs.data(), block_.count);
  auto backoff = s_.reconnect_min;
  bool ever_connected = false;
  int timeouts_in_row = 0;
  int protocol_in_row = 0;
  std::uint64_t seq = 0;
  ForceSample sample;
  ForceFilter filter;
  if (s_.filter_enabled) filter.configure(s_.filter);
  double filter_rpm = -1.0;
  std::int64_t last_sample_ns = 0;
  const auto stale_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(s_.stale_after).count();
  auto next = Clock::now();

  while (!stop_.load()) {
    if (!client.connected()) {
      if (ModbusError e = client.connect()) {
        connection_errors_.fetch_add(1);
        set_error(e.text);
        if (!wait_until(Clock::now() + backoff)) break;
        backoff = std::min(backoff * 2, s_.reconnect_max);
        continue;
      }
      if (ever_connected) reconnects_.fetch_add(1);
      ever_connected = true;
      connected_.store(true);
      backoff = s_.reconnect_min;
      timeouts_in_row = 0;
      protocol_in_row = 0;
      next = Clock::now();
    }

    polls_.fetch_add(1);
    const ModbusError e = client.read_registers(s_.map.function, block_.start, block);
    if (!e) {
      timeouts_in_row = 0;
      protocol_in_row = 0;
      decode_block(s_.map, block_.start, block, sample);
      sample.t_ns = steady_now_ns();
      sample.seq = ++seq;
      if (s_.filter_enabled) {
        const double rpm = spindle_rpm_.load(std::memory_order_relaxed);
        if (rpm != filter_rpm) {
          filter.set_spindle_rpm(rpm);
          filter_rpm = rpm;
        }
        if (!sample.valid || sample.t_ns - last_sample_ns > stale_ns) filter.reset();
        sample.filtered_N = sample.valid ? filter.step(sample.force_N) : sample.force_N;
        last_sample_ns = sample.valid ? sample.t_ns : 0;
      } else {
        sample.filtered_N = sample.force_N;
      }
      if (!sample.valid) invalid_.fetch_add(1);
      samples_.fetch_add(1);
      mailbox_.write(sample);
    } else {
      set_error(e.text);
      bool reconnect = false;
      switch (e.kind) {
        case ErrorKind::kTimeout:
          timeouts_.fetch_add(1);
          client.flush();
          reconnect = ++timeouts_in_row >= s_.timeouts_before_reconnect;
          break;
        case ErrorKind::kException:
          exceptions_.fetch_add(1);
          timeouts_in_row = 0;
          break;
        case ErrorKind::kProtocol:
          // A reply that arrived after its timeout is read as the answer to the next request
          // (TCP: transaction id mismatch -> "Invalid data"); flushing at once leaves the stream
          // one reply behind for ever (measured: 598 errors in 3 s). Let the pending reply land,
          // then flush; reconnect if it persists.
          protocol_errors_.fetch_add(1);
          if (wait_until(Clock::now() + s_.transport.response_timeout)) client.flush();
          reconnect = ++protocol_in_row >= 3;
          break;
        default:
          connection_errors_.fetch_add(1);
          reconnect = true;
          break;
      }
      if (reconnect) {
        client.close();
        connected_.store(false);
        if (!wait_until(Clock::now() + backoff)) break;
        continue;
      }
    }

    next += period;
    const auto now = Clock::now();
    // Late by more than a period (timeout, slow device): restart the grid instead of bursting.
    if (next < now) next = now;
    if (!wait_until(next)) break;
  }
  client.close();
  connected_.store(false);
}

}  // namespace contour::drivers::modbus
