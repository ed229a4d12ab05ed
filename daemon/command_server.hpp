#pragma once
// Command socket: Unix domain stream socket, one JSON object per line in each direction.
// The line protocol itself (parse, checks, reply shape) is daemon/command_protocol.hpp.
//
// Request:  {"id": <any>, "cmd": "<name>", ...args}
// Reply:    {"id": <echoed>, "ok": true, "result": {...}}  or  {"id": ..., "ok": false, "error": "..."}
// Event:    {"event": "<topic>", ...}  (only to clients that subscribed, e.g. telemetry stream)
//
// One server thread (poll(2)) serves several clients at once. Malformed JSON, non-object requests,
// missing/non-string "cmd" and lines longer than max_line_bytes get an error reply; an oversize
// line is discarded up to its newline. A slow client whose output backlog exceeds
// max_backlog_bytes is disconnected rather than allowed to grow memory. The handler runs on the
// server thread (never on the RT thread) and must not block for long.
// The socket file is created with `mode` (default 0660: group-writable, not world-writable) and,
// when `group` is set, chowned to that group.
#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/command_protocol.hpp"

namespace contour::daemon {

struct CommandServerOptions {
  std::string path = "/run/contourd/contourd.sock";
  mode_t mode = 0660;
  std::string group;                     // empty: keep the process group
  std::size_t max_line_bytes = 64 * 1024;
  std::size_t max_clients = 16;
  std::size_t max_backlog_bytes = 4 * 1024 * 1024;
};

struct ClientInfo {
  std::uint64_t id = 0;   // unique per connection
  uid_t uid = 0;          // peer credentials (SO_PEERCRED)
  pid_t pid = 0;
};

struct CommandServerStats {
  std::uint64_t connections = 0;
  std::uint64_t requests = 0;
  std::uint64_t errors = 0;        // malformed / oversize / rejected requests
  std::uint64_t dropped_clients = 0;
  std::size_t clients = 0;
};

class CommandServer {
 public:
  // Returns the reply's "result" object, or throws CommandError for an error reply.
  using Handler = std::function<nlohmann::json(const nlohmann::json& request, const ClientInfo&)>;

  CommandServer(CommandServerOptions opt, Handler handler);
  ~CommandServer();
  CommandServer(const CommandServer&) = delete;
  CommandServer& operator=(const CommandServer&) = delete;

  // Binds and listens (throws std::runtime_error naming the path on failure), starts the thread.
  void start();
  void stop();

  // Subscriptions: the handler may call subscribe(client, topic); publish() queues a line for every
  // subscriber of the topic (thread-safe, non-blocking; called from non-RT threads only).
  void subscribe(std::uint64_t client, const std::string& topic);
  void unsubscribe(std::uint64_t client, const std::string& topic);
  void publish(const std::string& topic, const nlohmann::json& event);

  [[nodiscard]] CommandServerStats stats() const;
  [[nodiscard]] const std::string& path() const { return opt_.path; }

 private:
  struct Client {
    int fd = -1;
    ClientInfo info;
    std::string in;
    std::string out;
    bool discarding = false;  // inside an oversize line
    std::vector<std::string> topics;
  };
  void run();
  void accept_clients();
  void reap_hung_up_clients();
  bool read_client(Client& c);
  bool flush_client(Client& c);
  void handle_line(Client& c, const std::string& line);
  void queue(Client& c, const nlohmann::json& j);
  void close_client(std::uint64_t id);

  CommandServerOptions opt_;
  Handler handler_;
  int listen_fd_ = -1;
  int wake_pipe_[2] = {-1, -1};
  std::thread thread_;
  std::atomic<bool> running_{false};
  mutable std::mutex mu_;  // guards clients_ and stats_ (server thread vs publish/stats callers)
  std::map<std::uint64_t, Client> clients_;
  std::uint64_t next_id_ = 1;
  CommandServerStats stats_;
};

}  // namespace contour::daemon
