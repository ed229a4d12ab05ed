#include "tools/contour-machine-sim/plant_io.hpp"

#include <arpa/inet.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iostream>
#include <stdexcept>
#include <vector>

namespace contour::sim {

namespace cp = contour::control::plc;

CouplerServer::CouplerServer(int unit_id, std::chrono::milliseconds watchdog)
    : unit_id_(unit_id), watchdog_(watchdog) {}

CouplerServer::~CouplerServer() { stop(); }

void CouplerServer::set_discrete(int address, bool v) {
  std::lock_guard lk(mu_);
  discrete_.at(static_cast<std::size_t>(address)) = v ? 1 : 0;
}
void CouplerServer::set_input_register(int address, std::uint16_t v) {
  std::lock_guard lk(mu_);
  input_regs_.at(static_cast<std::size_t>(address)) = v;
}
void CouplerServer::set_coil(int address, bool v) {
  std::lock_guard lk(mu_);
  coils_.at(static_cast<std::size_t>(address)) = v ? 1 : 0;
}
void CouplerServer::set_holding(int address, std::uint16_t v) {
  std::lock_guard lk(mu_);
  holding_.at(static_cast<std::size_t>(address)) = v;
}
bool CouplerServer::coil(int address) const {
  std::lock_guard lk(mu_);
  return coils_.at(static_cast<std::size_t>(address)) != 0;
}
std::uint16_t CouplerServer::holding(int address) const {
  std::lock_guard lk(mu_);
  return holding_.at(static_cast<std::size_t>(address));
}
void CouplerServer::set_fault(FaultMode mode, std::chrono::milliseconds delay, int exception_code) {
  std::lock_guard lk(mu_);
  fault_ = mode;
  delay_ = delay;
  exception_code_ = exception_code;
}
void CouplerServer::inject_disconnect() {
  std::lock_guard lk(mu_);
  disconnect_pending_ = true;
}

void CouplerServer::start(const std::string& host, int port) {
  if (thread_.joinable()) return;
  const int want = port != 0 ? port : port_.load();
  modbus_t* probe = modbus_new_tcp(host.c_str(), want);
  if (probe == nullptr) throw std::runtime_error("coupler server: bad endpoint " + host);
  const int fd = modbus_tcp_listen(probe, 4);
  const int err = errno;
  modbus_free(probe);
  if (fd < 0)
    throw std::runtime_error("coupler server: listen " + host + ":" + std::to_string(want) + ": " +
                             std::strerror(err));
  sockaddr_in addr{};
  socklen_t len = sizeof addr;
  if (getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) port_.store(ntohs(addr.sin_port));
  stop_.store(false);
  thread_ = std::thread([this, fd] { run(fd); });
}

void CouplerServer::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

void CouplerServer::run(int listen_fd) {
  modbus_t* ctx = modbus_new_tcp("127.0.0.1", port_.load());
  modbus_set_slave(ctx, unit_id_);
  modbus_mapping_t* mb = modbus_mapping_new(kTableSize, kTableSize, kTableSize, kTableSize);
  std::vector<int> clients;
  std::vector<std::uint8_t> query(MODBUS_TCP_MAX_ADU_LENGTH);
  auto drop = [&](int fd) {
    ::close(fd);
    std::erase(clients, fd);
  };
  auto last_request = std::chrono::steady_clock::now();
  bool tripped = false;
  while (!stop_.load()) {
    // Communication watchdog: outputs off when the master has gone quiet.
    if (!tripped && std::chrono::steady_clock::now() - last_request > watchdog_) {
      std::lock_guard lk(mu_);
      coils_.fill(0);
      tripped = true;
      watchdog_trips_.fetch_add(1);
    }
    fd_set rd;
    FD_ZERO(&rd);
    FD_SET(listen_fd, &rd);
    int maxfd = listen_fd;
    for (int c : clients) {
      FD_SET(c, &rd);
      maxfd = std::max(maxfd, c);
    }
    timeval tv{0, 10000};
    if (select(maxfd + 1, &rd, nullptr, nullptr, &tv) <= 0) continue;
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
      if (rc == 0) continue;
      requests_.fetch_add(1);
      FaultMode fault;
      std::chrono::milliseconds delay;
      int exc;
      {
        std::lock_guard lk(mu_);
        fault = fault_;
        delay = delay_;
        exc = exception_code_;
        if (disconnect_pending_) {
          disconnect_pending_ = false;
          fault = FaultMode::kDropConnection;
        }
      }
      if (fault == FaultMode::kNoReply) continue;  // the master times out; the watchdog runs on
      if (fault == FaultMode::kDropConnection) {
        drop(c);
        continue;
      }
      if (fault == FaultMode::kException) {
        modbus_reply_exception(ctx, query.data(), static_cast<unsigned>(exc));
        continue;
      }
      if (fault == FaultMode::kDelay) std::this_thread::sleep_for(delay);
      last_request = std::chrono::steady_clock::now();
      tripped = false;
      {
        std::lock_guard lk(mu_);
        for (int i = 0; i < kTableSize; ++i) {
          const auto k = static_cast<std::size_t>(i);
          mb->tab_bits[i] = coils_[k];
          mb->tab_input_bits[i] = discrete_[k];
          mb->tab_input_registers[i] = input_regs_[k];
          mb->tab_registers[i] = holding_[k];
        }
      }
      if (modbus_reply(ctx, query.data(), rc, mb) < 0) {
        drop(c);
        continue;
      }
      std::lock_guard lk(mu_);  // writes by the master land in the mapping
      for (int i = 0; i < kTableSize; ++i) {
        const auto k = static_cast<std::size_t>(i);
        coils_[k] = mb->tab_bits[i];
        holding_[k] = mb->tab_registers[i];
      }
    }
  }
  for (int c : clients) ::close(c);
  ::close(listen_fd);
  modbus_set_socket(ctx, -1);
  modbus_mapping_free(mb);
  modbus_free(ctx);
}

void PlantIo::step(double dt_s, const std::array<double, 3>& axis_mm) {
  for (std::size_t k = 0; k < kCoilMap.size(); ++k)
    plant_.set(kCoilMap[k], server_.coil(static_cast<int>(k)) ? 1 : 0);
  plant_.step(dt_s, axis_mm);
  for (std::size_t k = 0; k < kDiscreteMap.size(); ++k)
    server_.set_discrete(static_cast<int>(k), plant_.get(kDiscreteMap[k]) != 0);
  server_.set_input_register(0, static_cast<std::uint16_t>(plant_.get(cp::PlantPoint::kCarouselPocket)));
}

PlantEvent parse_plant_event(const std::string& text) {
  static const char* const kKinds[] = {"door_open",     "door_close",    "air_loss",
                                       "air_ok",        "carousel_jam",  "carousel_free",
                                       "drawbar_stuck", "drawbar_free",  "sensor_dead",
                                       "sensor_ok",     "coupler_no_reply", "coupler_ok",
                                       "coupler_drop"};
  const auto at = text.find('@');
  if (at == std::string::npos) throw std::invalid_argument("expected KIND@SYNC, got '" + text + "'");
  PlantEvent e;
  e.kind = text.substr(0, at);
  if (std::find_if(std::begin(kKinds), std::end(kKinds), [&](const char* k) { return e.kind == k; }) ==
      std::end(kKinds)) {
    std::string list;
    for (const char* k : kKinds) list += std::string(list.empty() ? "" : ", ") + k;
    throw std::invalid_argument("unknown plant event '" + e.kind + "' (" + list + ")");
  }
  char* end = nullptr;
  const std::string n = text.substr(at + 1);
  e.sync = std::strtol(n.c_str(), &end, 10);
  if (n.empty() || *end != '\0' || e.sync < 0)
    throw std::invalid_argument("bad SYNC count '" + n + "' in '" + text + "'");
  return e;
}

void apply_plant_event(const PlantEvent& e, cp::MachinePlant& plant, cp::PlantFaults& f,
                       CouplerServer& server) {
  const std::string& k = e.kind;
  if (k == "door_open") plant.set_door_open(true);
  else if (k == "door_close") plant.set_door_open(false);
  else if (k == "air_loss") plant.set_air_supply(false);
  else if (k == "air_ok") plant.set_air_supply(true);
  else if (k == "carousel_jam") f.carousel_jam = true;
  else if (k == "carousel_free") f.carousel_jam = false;
  else if (k == "drawbar_stuck") f.drawbar_stuck = true;
  else if (k == "drawbar_free") f.drawbar_stuck = false;
  else if (k == "sensor_dead") f.pocket_sensor_dead = true;
  else if (k == "sensor_ok") f.pocket_sensor_dead = false;
  else if (k == "coupler_no_reply") server.set_fault(FaultMode::kNoReply);
  else if (k == "coupler_ok") server.set_fault(FaultMode::kNone);
  else if (k == "coupler_drop") server.inject_disconnect();
  plant.set_faults(f);
}

void add_plant_options(CLI::App& app, PlantOptions& o) {
  app.add_option("--plant-io", o.endpoint,
                 "HOST:PORT serve the simulated machine's I/O coupler (Modbus TCP; door, air, "
                 "lube, carousel, drawbar, overtravel switches: plant_io.hpp has the map)");
  app.add_option("--plant-event", o.events,
                 "KIND@SYNC plant event (door_open, door_close, air_loss, air_ok, carousel_jam, "
                 "carousel_free, drawbar_stuck, drawbar_free, sensor_dead, sensor_ok, "
                 "coupler_no_reply, coupler_ok, coupler_drop)");
  app.add_flag("--plant-stdin", o.from_stdin,
               "also read plant events from stdin, one KIND per line, applied at once");
  app.add_option("--coupler-watchdog-ms", o.watchdog_ms,
                 "MS the coupler drops its coils after MS without a request (default 500)")
      ->check(CLI::Range(10, 600000));
}

PlantRunner::PlantRunner(const PlantOptions& o, const config::Config& cfg)
    : server_(1, std::chrono::milliseconds(o.watchdog_ms)), io_(server_), period_s_(cfg.machine.period_s) {
  const auto colon = o.endpoint.rfind(':');
  char* end = nullptr;
  const long p = colon == std::string::npos ? -1 : std::strtol(o.endpoint.c_str() + colon + 1, &end, 10);
  if (colon == std::string::npos || p < 0 || p > 65535 || *end != '\0')
    throw std::invalid_argument("--plant-io expects HOST:PORT, got '" + o.endpoint + "'");
  host_ = o.endpoint.substr(0, colon);
  for (const auto& e : o.events) events_.push_back(parse_plant_event(e));
  std::stable_sort(events_.begin(), events_.end(),
                   [](const PlantEvent& a, const PlantEvent& b) { return a.sync < b.sync; });
  std::array<double, 3> neg{-1e300, -1e300, -1e300}, pos{1e300, 1e300, 1e300};
  for (std::size_t a = 0; a < cfg.machine.axes.size() && a < 3; ++a) {
    neg[a] = cfg.machine.axes[a].min_mm - 2.0;
    pos[a] = cfg.machine.axes[a].max_mm + 2.0;
  }
  io_.plant().set_limits(neg, pos);
  server_.start(host_, static_cast<int>(p));
  io_.step(0.0, {0.0, 0.0, 0.0});  // inputs valid before the first SYNC
}

void PlantRunner::step(long syncs, const std::array<double, 3>& axis_mm) {
  while (next_event_ < events_.size() && events_[next_event_].sync <= syncs) {
    apply_plant_event(events_[next_event_], io_.plant(), faults_, server_);
    std::cout << nlohmann::json{{"plant", events_[next_event_].kind}, {"sync", syncs}}.dump()
              << std::endl;
    ++next_event_;
    ++events_applied_;
  }
  if (syncs <= last_sync_) return;
  io_.step(static_cast<double>(syncs - last_sync_) * period_s_, axis_mm);
  last_sync_ = syncs;
}

void PlantRunner::apply_now(const std::string& kind, long syncs) {
  PlantEvent e = parse_plant_event(kind + "@0");
  e.sync = syncs;
  apply_plant_event(e, io_.plant(), faults_, server_);
  std::cout << nlohmann::json{{"plant", e.kind}, {"sync", syncs}}.dump() << std::endl;
  ++events_applied_;
}

nlohmann::json PlantRunner::summary() const {
  const auto& plant = io_.plant();
  return {{"requests", server_.requests()},
          {"watchdog_trips", server_.watchdog_trips()},
          {"events", events_applied_},
          {"carousel_pocket", plant.get(control::plc::PlantPoint::kCarouselPocket)},
          {"carousel_moves", plant.carousel_moves()}};
}

}  // namespace contour::sim
