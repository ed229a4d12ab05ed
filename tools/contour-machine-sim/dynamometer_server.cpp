#include "tools/contour-machine-sim/dynamometer_server.hpp"

#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <utility>

#include "drivers/modbus/register_codec.hpp"

namespace contour::sim {

namespace dm = contour::drivers::modbus;

namespace {
constexpr int kTableSize = 512;  // registers per table; the reader's map must fit

double step_response(double x, double target, double tau_s, double dt_s) {
  if (tau_s <= 0.0) return target;
  return target + (x - target) * std::exp(-dt_s / tau_s);
}
}  // namespace

DynamometerServer::DynamometerServer(dm::RegisterMap map, ForceModelParams model, int unit_id)
    : map_(map),
      p_(std::move(model)),
      unit_id_(unit_id),
      feed_mm_min_(p_.feed0_mm_min),
      spindle_rpm_(p_.spindle0_rpm),
      rng_(p_.seed),
      regs_(kTableSize, 0) {
  const dm::RegisterBlock b = dm::register_block(map_);
  if (b.start + b.count > kTableSize)
    throw std::invalid_argument("dynamometer server: register map beyond address " +
                                std::to_string(kTableSize - 1));
}

DynamometerServer::~DynamometerServer() { stop(); }

void DynamometerServer::set_feed(double feed_mm_min) {
  std::lock_guard lk(mu_);
  feed_mm_min_ = feed_mm_min;
}
void DynamometerServer::set_spindle(double spindle_rpm) {
  std::lock_guard lk(mu_);
  spindle_rpm_ = spindle_rpm;
}
void DynamometerServer::set_path_position(double path_mm) {
  std::lock_guard lk(mu_);
  path_mm_ = path_mm;
}
void DynamometerServer::set_fixed_forces(std::optional<std::array<double, dm::kForceChannels>> f) {
  std::lock_guard lk(mu_);
  fixed_ = f;
}
void DynamometerServer::set_status_valid(bool valid) {
  std::lock_guard lk(mu_);
  status_valid_ = valid;
}
void DynamometerServer::set_fault(FaultMode mode, std::chrono::milliseconds delay,
                                  int exception_code) {
  std::lock_guard lk(mu_);
  fault_ = mode;
  delay_ = delay;
  exception_code_ = exception_code;
}
void DynamometerServer::inject_no_reply(std::chrono::milliseconds d) {
  std::lock_guard lk(mu_);
  no_reply_until_ = std::chrono::steady_clock::now() + d;
}
void DynamometerServer::inject_exceptions(int count, int code) {
  std::lock_guard lk(mu_);
  exceptions_left_ = std::max(0, count);
  injected_exception_code_ = code;
}
void DynamometerServer::inject_disconnect() {
  std::lock_guard lk(mu_);
  disconnect_pending_ = true;
}
std::array<double, dm::kForceChannels> DynamometerServer::last_forces() const {
  std::lock_guard lk(mu_);
  return last_;
}
double DynamometerServer::mean_force_N() const {
  std::lock_guard lk(mu_);
  const double f = p_.force0_N + x_feed_N_ + x_spindle_N_;
  return path_mm_ >= p_.step_at_mm ? f * p_.step_factor : f;
}

void DynamometerServer::update_registers() {
  std::lock_guard lk(mu_);
  const auto now = std::chrono::steady_clock::now();
  const double dt_s = evaluated_ ? std::chrono::duration<double>(now - last_eval_).count() : 0.0;
  last_eval_ = now;
  evaluated_ = true;
  std::array<double, dm::kForceChannels> f{};
  if (fixed_) {
    f = *fixed_;
  } else {
    x_feed_N_ = step_response(x_feed_N_, p_.k_feed_N_per_mm_min * (feed_mm_min_ - p_.feed0_mm_min),
                              p_.tau_feed_s, dt_s);
    x_spindle_N_ =
        step_response(x_spindle_N_, p_.k_spindle_N_per_rpm * (spindle_rpm_ - p_.spindle0_rpm),
                      p_.tau_spindle_s, dt_s);
    double mean = p_.force0_N + x_feed_N_ + x_spindle_N_;
    if (path_mm_ >= p_.step_at_mm) mean *= p_.step_factor;
    if (feed_mm_min_ <= 0.0 || spindle_rpm_ <= 0.0) mean = 0.0;  // not cutting
    const double tooth_hz = p_.teeth * spindle_rpm_ / 60.0;
    phase_rad_ =
        std::fmod(phase_rad_ + 2.0 * std::numbers::pi * tooth_hz * dt_s, 2.0 * std::numbers::pi);
    double ripple = 0.0;
    for (std::size_t k = 0; k < p_.harmonics.size(); ++k)
      ripple += p_.harmonics[k] * std::sin(static_cast<double>(k + 1) * phase_rad_);
    std::normal_distribution<double> noise(0.0, p_.noise_std_N);
    for (std::size_t c = 0; c < dm::kForceChannels; ++c)
      f[c] =
          p_.channel_ratio[c] * mean * (1.0 + ripple) + (p_.noise_std_N > 0.0 ? noise(rng_) : 0.0);
  }
  last_ = f;
  for (std::size_t c = 0; c < dm::kForceChannels; ++c) {
    const dm::ChannelMap& ch = map_.channels[c];
    if (!ch.enabled) continue;
    dm::encode_newtons(f[c], ch, std::span<std::uint16_t>(regs_).subspan(ch.address));
  }
  if (map_.status.enabled) {
    const bool bit = status_valid_ == map_.status.valid_when_set;
    auto& r = regs_[map_.status.address];
    const auto mask = static_cast<std::uint16_t>(1u << map_.status.valid_bit);
    r = static_cast<std::uint16_t>(bit ? (r | mask) : (r & ~mask));
  }
}

void DynamometerServer::start(const std::string& host, int port) {
  if (thread_.joinable()) return;
  const int want = port != 0 ? port : port_.load();
  modbus_t* probe = modbus_new_tcp(host.c_str(), want);
  if (probe == nullptr) throw std::runtime_error("dynamometer server: bad endpoint " + host);
  const int fd = modbus_tcp_listen(probe, 8);
  const int err = errno;
  modbus_free(probe);
  if (fd < 0)
    throw std::runtime_error("dynamometer server: listen " + host + ":" + std::to_string(want) +
                             ": " + std::strerror(err));
  sockaddr_in addr{};
  socklen_t len = sizeof addr;
  if (getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0)
    port_.store(ntohs(addr.sin_port));
  stop_.store(false);
  thread_ = std::thread([this, fd] { run(fd); });
}

void DynamometerServer::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void DynamometerServer::run(int listen_fd) {
  modbus_t* ctx = modbus_new_tcp("127.0.0.1", port_.load());
  modbus_set_slave(ctx, unit_id_);
  modbus_mapping_t* mb = modbus_mapping_new(0, 0, kTableSize, kTableSize);
  std::vector<int> clients;
  std::vector<std::uint8_t> query(MODBUS_TCP_MAX_ADU_LENGTH);
  auto drop = [&](int fd) {
    ::close(fd);
    std::erase(clients, fd);
  };

  while (!stop_.load()) {
    fd_set rd;
    FD_ZERO(&rd);
    FD_SET(listen_fd, &rd);
    int maxfd = listen_fd;
    for (int c : clients) {
      FD_SET(c, &rd);
      maxfd = std::max(maxfd, c);
    }
    timeval tv{0, 20000};  // 20 ms: bounds stop() latency, no spinning
    const int n = select(maxfd + 1, &rd, nullptr, nullptr, &tv);
    if (n <= 0) continue;
    if (FD_ISSET(listen_fd, &rd)) {
      const int c = accept(listen_fd, nullptr, nullptr);
      if (c >= 0) clients.push_back(c);
    }
    const std::vector<int> ready = clients;
    for (int c : ready) {
      if (!FD_ISSET(c, &rd)) continue;
      modbus_set_socket(ctx, c);
      const int rc = modbus_receive(ctx, query.data());
      if (rc < 0) {
        drop(c);
        continue;
      }
      if (rc == 0) continue;  // not for this unit
      requests_.fetch_add(1);
      FaultMode fault;
      std::chrono::milliseconds delay;
      int exc;
      {
        std::lock_guard lk(mu_);
        fault = fault_;
        delay = delay_;
        exc = exception_code_;
        if (std::chrono::steady_clock::now() < no_reply_until_) {
          fault = FaultMode::kNoReply;
        } else if (disconnect_pending_) {
          disconnect_pending_ = false;
          fault = FaultMode::kDropConnection;
        } else if (exceptions_left_ > 0) {
          --exceptions_left_;
          fault = FaultMode::kException;
          exc = injected_exception_code_;
        }
      }
      if (fault == FaultMode::kNoReply) continue;
      if (fault == FaultMode::kDropConnection) {
        drop(c);
        continue;
      }
      if (fault == FaultMode::kException) {
        modbus_reply_exception(ctx, query.data(), static_cast<unsigned>(exc));
        continue;
      }
      if (fault == FaultMode::kDelay) std::this_thread::sleep_for(delay);
      update_registers();
      {
        std::lock_guard lk(mu_);
        for (int i = 0; i < kTableSize; ++i) {
          const auto idx = static_cast<std::size_t>(i);
          if (map_.function == dm::RegisterFunction::kInput)
            mb->tab_input_registers[i] = regs_[idx];
          else
            mb->tab_registers[i] = regs_[idx];
        }
      }
      if (modbus_reply(ctx, query.data(), rc, mb) < 0) drop(c);
    }
  }
  for (int c : clients) ::close(c);
  ::close(listen_fd);
  modbus_set_socket(ctx, -1);
  modbus_mapping_free(mb);
  modbus_free(ctx);
}

}  // namespace contour::sim
