#pragma once
// Minimal simulated VFD for tests: a libmodbus TCP server on loopback (any free port).
// Holding 0 = setpoint counts, 1 = run (0 stop, 1 fwd, 2 rev), 2 = actual counts, which follows
// the setpoint at once while running. `stall` keeps the actual speed at 0 (a jammed spindle).
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace contour::test {

// Minimal VFD: holding 0 = setpoint counts, 1 = run (0 stop, 1 fwd, 2 rev), 2 = actual counts.
class SimVfd {
 public:
  SimVfd() {
    modbus_t* p = modbus_new_tcp("127.0.0.1", 0);
    fd_ = modbus_tcp_listen(p, 2);
    modbus_free(p);
    sockaddr_in a{};
    socklen_t len = sizeof a;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    th_ = std::thread([this] { run(); });
  }
  ~SimVfd() {
    stop_ = true;
    th_.join();
  }
  int port() const { return port_; }
  std::atomic<std::uint16_t> setpoint{0}, run_cmd{0};
  std::atomic<bool> stall{false};

 private:
  void run() {
    modbus_t* ctx = modbus_new_tcp("127.0.0.1", port_);
    modbus_mapping_t* mb = modbus_mapping_new(8, 0, 8, 0);
    std::vector<int> cl;
    std::vector<std::uint8_t> q(MODBUS_TCP_MAX_ADU_LENGTH);
    while (!stop_) {
      fd_set rd;
      FD_ZERO(&rd);
      FD_SET(fd_, &rd);
      int mx = fd_;
      for (int c : cl) {
        FD_SET(c, &rd);
        mx = std::max(mx, c);
      }
      timeval tv{0, 10000};
      if (select(mx + 1, &rd, nullptr, nullptr, &tv) <= 0) continue;
      if (FD_ISSET(fd_, &rd)) cl.push_back(accept(fd_, nullptr, nullptr));
      for (int c : std::vector<int>(cl)) {
        if (!FD_ISSET(c, &rd)) continue;
        modbus_set_socket(ctx, c);
        const int rc = modbus_receive(ctx, q.data());
        if (rc < 0) {
          close(c);
          std::erase(cl, c);
          continue;
        }
        mb->tab_registers[2] = (mb->tab_registers[1] != 0 && !stall) ? mb->tab_registers[0] : 0;
        modbus_reply(ctx, q.data(), rc, mb);
        setpoint = mb->tab_registers[0];
        run_cmd = mb->tab_registers[1];
      }
    }
    for (int c : cl) close(c);
    close(fd_);
    modbus_set_socket(ctx, -1);
    modbus_mapping_free(mb);
    modbus_free(ctx);
  }
  int fd_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::thread th_;
};

}  // namespace contour::test
