#pragma once
// Shared pieces of the CANopen HIL tests (tests/hil/canopen_*_test.cpp): the simulated machine
// as a child process, the master over SocketCAN on vcan0 from config/hil.yaml, a lockstep
// cycle driver, and an independent raw-socket observer (plain linux/can.h, no project code).
#include <gtest/gtest.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <signal.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <nlohmann/json.hpp>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "config/config.hpp"
#include "drivers/can/socket_can.hpp"
#include "drivers/canopen/master.hpp"
#include "daemon/canopen_master_config.hpp"

namespace contour::test {

// `node`'s entry in contour-machine-sim's JSON summary (the last line it prints at exit:
// nodes[]); an empty object if there is none.
inline nlohmann::json sim_summary_node(const std::string& out, int node) {
  const auto end = out.find_last_not_of('\n');
  if (end == std::string::npos) return nlohmann::json::object();
  const auto begin = out.find_last_of('\n', end);
  const auto j = nlohmann::json::parse(out.substr(begin == std::string::npos ? 0 : begin + 1, end - begin),
                                       nullptr, false);
  if (j.is_object() && j.contains("nodes"))
    for (const auto& n : j["nodes"])
      if (n["node_id"] == node) return n;
  return nlohmann::json::object();
}

// The plant position of `node` in that summary (nodes[].position_mm); NaN if there is none.
inline double sim_summary_position_mm(const std::string& out, int node) {
  const auto n = sim_summary_node(out, node);
  return n.contains("position_mm") ? n["position_mm"].get<double>() : std::nan("");
}

inline const char* kIface = "vcan0";

// contour-machine-sim as a child process; waits for its "ready:" line.
class MachineSim {
 public:
  explicit MachineSim(std::vector<std::string> extra = {},
                      const std::string& config = CONTOUR_SOURCE_DIR "/config/hil.yaml") {
    const std::string bin = CONTOUR_BINARY_DIR "/tools/contour-machine-sim";
    std::vector<std::string> args = {bin, "--config", config, "--can", kIface};
    args.insert(args.end(), extra.begin(), extra.end());
    int out[2];
    if (::pipe(out) != 0) throw std::runtime_error("pipe");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(out[1], 1);
      ::close(out[0]);
      ::close(out[1]);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(bin.c_str(), argv.data());
      _exit(127);
    }
    ::close(out[1]);
    fd_ = out[0];
    // Wait up to 20 s (the VM can be slow) for the ready line.
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < until && output_.find("ready:") == std::string::npos) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 200) == 1) {
        char buf[512];
        const ssize_t n = ::read(fd_, buf, sizeof buf);
        if (n <= 0) break;
        output_.append(buf, static_cast<std::size_t>(n));
      }
    }
    ready_ = output_.find("ready:") != std::string::npos;
  }
  ~MachineSim() { stop(); }
  [[nodiscard]] bool ready() const { return ready_; }
  // Reads what the child printed so far without blocking (long runs: keeps its stdout pipe from
  // filling up and stalling it) and returns everything printed up to now.
  const std::string& poll_output() {
    if (pid_ <= 0) return output_;
    for (;;) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 0) != 1) break;
      char buf[4096];
      const ssize_t n = ::read(fd_, buf, sizeof buf);
      if (n <= 0) break;
      output_.append(buf, static_cast<std::size_t>(n));
    }
    return output_;
  }
  [[nodiscard]] pid_t pid() const { return pid_; }
  // Stops the child (SIGTERM) and returns everything it printed (the JSON summary last).
  std::string stop() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      char buf[4096];
      ssize_t n;
      while ((n = ::read(fd_, buf, sizeof buf)) > 0) output_.append(buf, static_cast<std::size_t>(n));
      int st = 0;
      ::waitpid(pid_, &st, 0);
      ::close(fd_);
      pid_ = -1;
    }
    return output_;
  }

 private:
  pid_t pid_ = -1;
  int fd_ = -1;
  std::string output_;
  bool ready_ = false;
};

// Independent observer: a second raw socket recording every frame in a thread.
struct Observed {
  canid_t id;
  std::uint8_t dlc;
  std::uint8_t data[8];
};
class Observer {
 public:
  Observer() {
    fd_ = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
    ifreq ifr{};
    std::strncpy(ifr.ifr_name, kIface, IFNAMSIZ - 1);
    ::ioctl(fd_, SIOCGIFINDEX, &ifr);
    int rcvbuf = 4 << 20;
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    sockaddr_can addr{};
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    ok_ = ::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
    th_ = std::thread([this] {
      while (!stop_) {
        pollfd p{fd_, POLLIN, 0};
        if (::poll(&p, 1, 20) != 1) continue;
        can_frame k{};
        if (::read(fd_, &k, sizeof k) != static_cast<ssize_t>(sizeof k)) continue;
        Observed o{k.can_id, k.can_dlc, {}};
        std::memcpy(o.data, k.data, 8);
        std::lock_guard<std::mutex> g(m_);
        frames_.push_back(o);
      }
    });
  }
  ~Observer() {
    stop_ = true;
    th_.join();
    ::close(fd_);
  }
  [[nodiscard]] bool ok() const { return ok_; }
  std::vector<Observed> take() {
    // let the thread catch up with what is already queued
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    std::lock_guard<std::mutex> g(m_);
    return frames_;
  }

 private:
  int fd_ = -1;
  bool ok_ = false;
  std::atomic<bool> stop_{false};
  std::thread th_;
  std::mutex m_;
  std::vector<Observed> frames_;
};

inline config::Config hil_config() {
  return config::load_config_file(CONTOUR_SOURCE_DIR "/config/hil.yaml");
}

// The master for hil.yaml; the TPDO deadline is widened to 200 ms because the VM has heavy steal
// time (collect() returns as soon as every TPDO is in, so this does not slow the loop).
inline drivers::canopen::MasterConfig hil_master_config(const config::Config& c) {
  auto m = daemon::master_config_from(c);
  m.tpdo_deadline_us = 200000;
  return m;
}

struct Rig {
  std::vector<std::string> log;
  std::unique_ptr<drivers::SocketCan> bus;
  std::unique_ptr<drivers::canopen::Master> master;
  std::int64_t cycle = 0;
  std::int64_t period_ns = 1000000;

  explicit Rig(const drivers::canopen::MasterConfig& mc, bool filters = false) {
    bus = std::make_unique<drivers::SocketCan>(
        kIface, filters ? drivers::canopen::master_rx_filters(mc) : std::vector<drivers::CanFilter>{});
    master = std::make_unique<drivers::canopen::Master>(
        *bus, mc, [this](const std::string& s) { log.push_back(s); });
    period_ns = static_cast<std::int64_t>(mc.period_us) * 1000;
  }
  // One lockstep cycle; `now` is the cycle time (not the wall clock).
  drivers::canopen::CycleStatus step() {
    using drivers::canopen::CycleStatus;
    auto a = master->begin_cycle(cycle * period_ns);
    auto b = master->collect();
    auto c = master->send_rpdos();
    ++cycle;
    return (a == CycleStatus::kFault || b == CycleStatus::kFault || c == CycleStatus::kFault)
               ? CycleStatus::kFault
               : CycleStatus::kOk;
  }
  std::vector<std::string> events() {
    std::vector<std::string> out;
    drivers::canopen::MasterEvent e;
    while (master->pop_event(e)) out.push_back(master->describe(e));
    return out;
  }
  // Enables every drive; returns the cycles it took, or -1.
  int enable_all(int max_cycles = 2000) {
    master->set_request_all(drivers::canopen::DriveRequest::kEnabled);
    for (int k = 0; k < max_cycles; ++k) {
      step();
      if (master->all_enabled()) return k + 1;
    }
    return -1;
  }
};

}  // namespace contour::test
