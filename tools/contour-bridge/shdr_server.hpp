#pragma once
// The SHDR adapter's TCP side (MTConnect agents connect to it): non-blocking, driven by the
// bridge's poll loop. A new client first gets `* shdrVersion: 2` and the snapshot of every item,
// then the changes. `* PING` from the agent is answered `* PONG <heartbeat_ms>` (the agent then
// pings every heartbeat_ms and drops the connection after two silent periods). A client that
// stops reading (more than kMaxBacklogBytes unsent) is dropped: an agent reconnects and gets a
// fresh snapshot, the bridge never blocks or grows without bound for it.
#include <poll.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace contour::bridge {

struct ShdrServerStats {
  std::uint64_t accepted = 0;
  std::uint64_t refused = 0;  // beyond max_clients
  std::uint64_t dropped = 0;  // slow readers
  std::uint64_t pings = 0;
  std::size_t clients = 0;
};

class ShdrServer {
 public:
  static constexpr std::size_t kMaxBacklogBytes = 4u << 20;

  // Binds and listens; throws std::runtime_error naming the address on failure.
  ShdrServer(const std::string& bind, int port, int heartbeat_ms, std::size_t max_clients,
             std::vector<std::string> header_lines);
  ~ShdrServer();
  ShdrServer(const ShdrServer&) = delete;
  ShdrServer& operator=(const ShdrServer&) = delete;

  [[nodiscard]] int port() const { return port_; }

  // Appends this server's descriptors; handle() takes the same entries back.
  void add_poll_fds(std::vector<pollfd>& fds) const;
  // snapshot(): the lines a new client gets after the header.
  void handle(const std::vector<pollfd>& fds, const std::function<std::vector<std::string>()>& snapshot);

  // Sends lines to every connected client.
  void broadcast(const std::vector<std::string>& lines);
  [[nodiscard]] const ShdrServerStats& stats() const { return stats_; }

 private:
  struct Client {
    int fd;
    std::string in, out;
  };
  void accept_clients(const std::function<std::vector<std::string>()>& snapshot);
  bool flush(Client& c);  // false: drop
  bool read(Client& c);   // false: drop

  int listen_fd_ = -1;
  int port_ = 0;
  int heartbeat_ms_;
  std::size_t max_clients_;
  std::vector<std::string> header_;
  std::vector<Client> clients_;
  ShdrServerStats stats_;
};

}  // namespace contour::bridge
