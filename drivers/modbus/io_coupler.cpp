#include "drivers/modbus/io_coupler.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <cerrno>
#include <stdexcept>
#include <utility>

namespace contour::drivers::modbus {

const char* to_string(CouplerState s) noexcept {
  switch (s) {
    case CouplerState::kNoData:
      return "no_data";
    case CouplerState::kOk:
      return "ok";
    case CouplerState::kStale:
      return "stale";
  }
  return "?";
}

namespace {

std::int64_t now_ns() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// One libmodbus context with the bit and multi-register functions the coupler needs (the
// shared ModbusClient has registers only). Errors are translated once, as in modbus_client.cpp.
class Link {
 public:
  explicit Link(const TransportSettings& s) {
    if (s.transport == Transport::kTcp) {
      endpoint_ = s.host + ":" + std::to_string(s.port);
      ctx_ = modbus_new_tcp(s.host.c_str(), s.port);
    } else {
      endpoint_ = s.device;
      ctx_ = modbus_new_rtu(s.device.c_str(), s.baud, s.parity, s.data_bits, s.stop_bits);
    }
    if (ctx_ == nullptr)
      throw std::runtime_error("modbus " + endpoint_ + ": cannot create context: " +
                               modbus_strerror(errno));
    modbus_set_slave(ctx_, s.unit_id);
    const auto us = s.response_timeout.count();
    modbus_set_response_timeout(ctx_, static_cast<std::uint32_t>(us / 1000000),
                                static_cast<std::uint32_t>(us % 1000000));
  }
  ~Link() {
    close();
    modbus_free(ctx_);
  }
  Link(const Link&) = delete;
  Link& operator=(const Link&) = delete;

  ModbusError connect() {
    if (connected_) return {};
    if (modbus_connect(ctx_) != 0) {
      ModbusError e = fail("connect", errno);
      e.kind = ErrorKind::kConnection;
      return e;
    }
    connected_ = true;
    return {};
  }
  void close() noexcept {
    if (connected_) modbus_close(ctx_);
    connected_ = false;
  }
  [[nodiscard]] bool connected() const noexcept { return connected_; }
  void flush() noexcept {
    if (connected_) modbus_flush(ctx_);
  }

  ModbusError read_discrete(std::uint16_t start, std::uint16_t n, std::uint8_t* out) {
    return check(modbus_read_input_bits(ctx_, start, n, out), n, "read discrete inputs", start);
  }
  ModbusError read_input_registers(std::uint16_t start, std::uint16_t n, std::uint16_t* out) {
    return check(modbus_read_input_registers(ctx_, start, n, out), n, "read input registers", start);
  }
  ModbusError read_holding(std::uint16_t start, std::uint16_t n, std::uint16_t* out) {
    return check(modbus_read_registers(ctx_, start, n, out), n, "read holding registers", start);
  }
  ModbusError write_coils(std::uint16_t start, std::uint16_t n, const std::uint8_t* v) {
    return check(modbus_write_bits(ctx_, start, n, v), n, "write coils", start);
  }
  ModbusError write_holding(std::uint16_t start, std::uint16_t n, const std::uint16_t* v) {
    return check(modbus_write_registers(ctx_, start, n, v), n, "write holding registers", start);
  }

 private:
  ModbusError check(int rc, int n, const char* op, std::uint16_t start) {
    if (!connected_) return {ErrorKind::kConnection, ENOTCONN, endpoint_ + ": not connected"};
    if (rc == n) return {};
    return fail((std::string(op) + " " + std::to_string(start) + "+" + std::to_string(n)).c_str(),
                rc < 0 ? errno : EMBMDATA);
  }
  ModbusError fail(const char* op, int err) {
    ModbusError e;
    e.kind = classify_errno(err);
    e.code = e.kind == ErrorKind::kException ? err - MODBUS_ENOBASE : err;
    const std::string what =
        e.kind == ErrorKind::kException
            ? "exception " + std::to_string(e.code) + " (" + exception_text(e.code) + ")"
            : std::string(modbus_strerror(err));
    e.text = endpoint_ + ": " + op + ": " + what;
    return e;
  }

  std::string endpoint_;
  modbus_t* ctx_ = nullptr;
  bool connected_ = false;
};

}  // namespace

IoCoupler::IoCoupler(IoCouplerSettings s, const CouplerOutputs& safe)
    : s_(std::move(s)), safe_(safe) {
  const std::string who = "modbus coupler '" + s_.name + "': ";
  auto check_span = [&](const CouplerSpan& sp, std::size_t max, const char* what) {
    if (sp.count > max)
      throw std::invalid_argument(who + what + " span " + std::to_string(sp.count) +
                                  " addresses (max " + std::to_string(max) + ")");
    if (sp.count > 0 && sp.start + sp.count > 65536)
      throw std::invalid_argument(who + what + " beyond address 65535");
  };
  check_span(s_.discrete_inputs, kCouplerMaxBits, "discrete inputs");
  check_span(s_.input_registers, kCouplerMaxRegisters, "input registers");
  check_span(s_.holding_inputs, kCouplerMaxRegisters, "holding registers (inputs)");
  auto runs = [&](std::vector<std::uint16_t> addr, std::size_t max, const char* what,
                  std::uint16_t& base, std::vector<Run>& out) {
    std::sort(addr.begin(), addr.end());
    addr.erase(std::unique(addr.begin(), addr.end()), addr.end());
    if (addr.empty()) return;
    base = addr.front();
    if (static_cast<std::size_t>(addr.back() - addr.front()) >= max)
      throw std::invalid_argument(who + what + " span " +
                                  std::to_string(addr.back() - addr.front() + 1) +
                                  " addresses (max " + std::to_string(max) + ")");
    for (std::uint16_t a : addr) {
      if (!out.empty() && out.back().start + out.back().count == a) {
        ++out.back().count;
      } else {
        out.push_back({a, 1});
      }
    }
  };
  runs(s_.coils, kCouplerMaxBits, "coils", coil_base_, coil_runs_);
  runs(s_.holding_outputs, kCouplerMaxRegisters, "holding registers (outputs)", hold_base_,
       hold_runs_);
  if (!(s_.poll_hz > 0.0 && s_.poll_hz <= 2000.0))
    throw std::invalid_argument(who + "poll_hz must be in (0, 2000]");
  if (s_.timeouts_before_reconnect < 1) s_.timeouts_before_reconnect = 1;
}

IoCoupler::~IoCoupler() { stop(); }

void IoCoupler::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void IoCoupler::stop() {
  {
    std::lock_guard lk(mu_);
    stop_.store(true);
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

bool IoCoupler::wait_until(std::chrono::steady_clock::time_point t) {
  std::unique_lock lk(mu_);
  return !cv_.wait_until(lk, t, [this] { return stop_.load(); });
}

void IoCoupler::set_error(const std::string& text) {
  std::lock_guard lk(mu_);
  last_error_ = text;
}

CouplerReading IoCoupler::read(std::int64_t now, CouplerInputs& in) noexcept {
  CouplerReading r;
  r.fresh = inbox_.read(in);
  if (in.seq == 0) return r;
  r.age_ns = now - in.t_ns;
  const auto stale_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(s_.stale_after).count();
  r.state = r.age_ns > stale_ns ? CouplerState::kStale : CouplerState::kOk;
  return r;
}

CouplerStatus IoCoupler::status() const {
  CouplerStatus st;
  st.connected = connected_.load();
  st.polls = polls_.load();
  st.reads = reads_.load();
  st.writes = writes_.load();
  st.timeouts = timeouts_.load();
  st.exceptions = exceptions_.load();
  st.protocol_errors = protocol_errors_.load();
  st.connection_errors = connection_errors_.load();
  st.reconnects = reconnects_.load();
  std::lock_guard lk(mu_);
  st.last_error = last_error_;
  return st;
}

void IoCoupler::run() {
  using Clock = std::chrono::steady_clock;
  Link link(s_.transport);
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / s_.poll_hz));
  auto backoff = s_.reconnect_min;
  bool ever_connected = false;
  int timeouts_in_row = 0, protocol_in_row = 0;
  std::uint64_t seq = 0;
  CouplerInputs rec;
  CouplerOutputs out = safe_;
  auto next = Clock::now();

  // Writes every output run from `o`; the first error, if any.
  auto write_all = [&](const CouplerOutputs& o) -> ModbusError {
    for (const Run& r : coil_runs_)
      if (ModbusError e = link.write_coils(r.start, r.count, &o.coils[static_cast<std::size_t>(r.start - coil_base_)]))
        return e;
    for (const Run& r : hold_runs_)
      if (ModbusError e = link.write_holding(r.start, r.count, &o.holding[static_cast<std::size_t>(r.start - hold_base_)]))
        return e;
    return {};
  };

  while (!stop_.load()) {
    if (!link.connected()) {
      if (ModbusError e = link.connect()) {
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
    ModbusError e;
    if (!e && s_.discrete_inputs.count > 0)
      e = link.read_discrete(s_.discrete_inputs.start, s_.discrete_inputs.count, rec.discrete.data());
    if (!e && s_.input_registers.count > 0)
      e = link.read_input_registers(s_.input_registers.start, s_.input_registers.count,
                                    rec.input_registers.data());
    if (!e && s_.holding_inputs.count > 0)
      e = link.read_holding(s_.holding_inputs.start, s_.holding_inputs.count, rec.holding.data());
    if (!e) {
      rec.t_ns = now_ns();
      rec.seq = ++seq;
      inbox_.write(rec);
      reads_.fetch_add(1);
      CouplerOutputs latest;
      if (outbox_.read(latest)) out_written_ = true;
      if (out_written_) out = latest;
      e = write_all(out);
      if (!e) writes_.fetch_add(1);
    }
    if (!e) {
      timeouts_in_row = 0;
      protocol_in_row = 0;
    } else {
      set_error(e.text);
      bool reconnect = false;
      switch (e.kind) {
        case ErrorKind::kTimeout:
          timeouts_.fetch_add(1);
          link.flush();
          reconnect = ++timeouts_in_row >= s_.timeouts_before_reconnect;
          break;
        case ErrorKind::kException:
          exceptions_.fetch_add(1);
          timeouts_in_row = 0;
          break;
        case ErrorKind::kProtocol:
          // A late reply would be read as the next answer: let it land, then flush.
          protocol_errors_.fetch_add(1);
          if (wait_until(Clock::now() + s_.transport.response_timeout)) link.flush();
          reconnect = ++protocol_in_row >= 3;
          break;
        default:
          connection_errors_.fetch_add(1);
          reconnect = true;
          break;
      }
      if (reconnect) {
        link.close();
        connected_.store(false);
        if (!wait_until(Clock::now() + backoff)) break;
        continue;
      }
    }
    next += period;
    const auto now = Clock::now();
    if (next < now) next = now;  // late (timeouts): restart the grid instead of bursting
    if (!wait_until(next)) break;
  }
  // Safe outputs once on the way out (best effort: the coupler's own watchdog is the backstop).
  if (link.connected() || !link.connect()) (void)write_all(safe_);
  link.close();
  connected_.store(false);
}

}  // namespace contour::drivers::modbus
