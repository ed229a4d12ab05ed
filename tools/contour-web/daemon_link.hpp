#pragma once
// contour-web's side of contourd's command socket (JSON lines over a Unix stream socket, see
// daemon/PROTOCOL.md). Several connections, each with its own job, so that none waits behind
// another's traffic inside contour-web:
//   stream   subscribed to `telemetry` and `events`; re-established every second while contourd
//            is away (its state is what DaemonPort::connected() reports)
//   poll     `status` at web.status_rate_hz (the hub's status subscriptions and dead-man)
//   command  every forwarded command but the safety ones and jog
//   safety   estop, hold, stop only
//   client N a browser's own connection for jog, opened on its first jog and closed when the
//            browser goes (a daemon-side continuous-jog dead-man ends with it)
// Requests carry contour-web's own ids; replies are matched by id and answered once. A lost
// connection answers every pending request with {"ok": false, "unreachable": true, "error"}.
// Single-threaded: everything runs on the io_context's thread.
#include <utility>  // before Boost 1.74's asio/awaitable.hpp, which uses std::exchange without it
#include <boost/asio.hpp>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "tools/contour-web/hub.hpp"

namespace contour::web {

namespace asio = boost::asio;

class DaemonConnection : public std::enable_shared_from_this<DaemonConnection> {
 public:
  using Reply = DaemonPort::Reply;
  static constexpr std::size_t kMaxLineBytes = 64u << 20;  // a telemetry batch line fits

  DaemonConnection(asio::io_context& io, std::string path, std::string name);
  // Connects if needed (queued meanwhile).
  void request(nlohmann::json req, Reply cb);
  void close(const std::string& why);
  [[nodiscard]] bool up() const { return state_ == State::kUp; }
  [[nodiscard]] bool idle() const { return state_ == State::kIdle; }
  [[nodiscard]] const std::string& name() const { return name_; }

  std::function<void(const nlohmann::json&)> on_line;          // lines that are not our replies
  std::function<void(bool up, const std::string& why)> on_state;

 private:
  enum class State { kIdle, kConnecting, kUp };
  void connect();
  void read();
  void write();
  void fail(const std::string& why);

  asio::io_context& io_;
  std::string path_;
  std::string name_;
  asio::local::stream_protocol::socket sock_;
  State state_ = State::kIdle;
  std::deque<std::string> out_;
  bool writing_ = false;
  std::map<std::uint64_t, Reply> pending_;
  std::uint64_t next_id_ = 1;
  asio::streambuf in_{kMaxLineBytes};
  std::uint64_t generation_ = 0;  // handlers of a closed socket are ignored
};

class DaemonLink final : public DaemonPort {
 public:
  DaemonLink(asio::io_context& io, std::string socket_path);
  // Opens the stream connection (and keeps reopening it); lines go to `on_line`.
  void start(std::function<void(const nlohmann::json&)> on_line,
             std::function<void(bool, const std::string&)> on_state);

  void request(Channel ch, nlohmann::json req, Reply cb) override;
  void client_request(ClientId client, nlohmann::json req, Reply cb) override;
  void close_client(ClientId client) override;
  [[nodiscard]] bool connected() const override { return stream_ && stream_->up(); }
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  void open_stream();
  void keepalive();

  asio::io_context& io_;
  std::string path_;
  std::shared_ptr<DaemonConnection> stream_, poll_, command_, safety_;
  std::map<ClientId, std::shared_ptr<DaemonConnection>> clients_;
  asio::steady_timer retry_;
  asio::steady_timer keepalive_;
  std::function<void(const nlohmann::json&)> on_line_;
  std::function<void(bool, const std::string&)> on_state_;
  bool was_up_ = false;
};

}  // namespace contour::web
