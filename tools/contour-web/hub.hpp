#pragma once
// contour-web's core: the JSON-RPC 2.0 API over WebSocket (Moonraker's shape) between browser
// clients and contourd's command socket. No sockets and no threads here: the HTTP/WebSocket
// server (http_server.hpp) and the daemon link (daemon_link.hpp) drive it from one io_context
// thread, and the unit tests drive it with fakes.
//
// Methods (params: a JSON object, or absent):
//   every contourd socket command, same name and arguments (daemon/PROTOCOL.md): the request is
//     forwarded as {"cmd": METHOD, ...params}; the daemon's "result" is the JSON-RPC result, its
//     refusal the error {code: -32000, message: the daemon's text}.
//     estop, hold, stop go over a connection of their own (never queued behind other commands)
//     and are never rate limited; jog goes over the client's own daemon connection, so that a
//     daemon-side dead-man (continuous jog) ends with the browser.
//   web.login {token}      -> {name, role}             (the token is compared in constant time)
//   web.info               -> {version, role, daemon, limits, signals}
//   web.deadman            -> true: keeps the client's jog alive (send every < jog_deadman_ms)
//   subscribe {fields: [NAME|DOTTED.PATH, ...]} or {topic: "status", fields}
//       -> {status: snapshot}; then notify_status_update [changed fields, t_s] at most
//          status_rate_hz (only fields that changed since the last notification)
//   subscribe {topic: "telemetry", signals: [...], decimation: N}
//       -> {topic, signals, decimation}; then notify_scope {...} batches (scope.hpp) with every
//          sample whose cycle is a multiple of N (default 1: every sample)
//   subscribe {topic: "events"} -> {events: [recent]}; then notify_event {...}
//   unsubscribe {topic: "status"|"telemetry"|"events"}
// Errors: -32700 parse error, -32600 invalid request, -32601 no such method, -32602 invalid
// params, -32000 refused by contourd, -32001 login required / invalid token, -32003 forbidden for
// the role, -32005 rate limited, -32010 contourd unreachable.
//
// Roles: viewer (status, result, gains and force queries, subscriptions), operator (every
// command). estop/hold/stop need operator unless web.viewer_may_stop.
// Dead-man (web.jog_deadman_ms): a client that started a jog and then goes silent (no message of
// any kind) for that long, or whose connection closes, has its jog stopped (`stop` on the safety
// connection while the daemon reports jogging) and its own daemon connection closed.
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "config/web_config.hpp"
#include "tools/contour-web/scope.hpp"

namespace contour::web {

using nlohmann::json;
using Clock = std::chrono::steady_clock;
using ClientId = std::uint64_t;

inline constexpr const char* kVersion = "0.1.0";

struct ResolvedToken {
  std::string name;
  config::WebRole role = config::WebRole::kViewer;
  std::string value;  // never logged
};

struct HubOptions {
  double status_rate_hz = 10.0;
  double max_requests_per_s = 50.0;
  int jog_deadman_ms = 500;
  bool viewer_may_stop = false;
  config::WebRole anonymous_role = config::WebRole::kOperator;
  std::vector<ResolvedToken> tokens;
  std::size_t max_events = 200;        // kept for new event subscribers
  std::size_t max_message_bytes = 256 * 1024;
  std::size_t client_queue_bytes = 4u << 20;
  int max_clients = 16;
};

// The daemon side as the hub sees it (DaemonLink; a fake in the tests). Replies are the daemon's
// reply objects {"ok": true, "result": ...} / {"ok": false, "error": TEXT}; a lost or impossible
// connection answers {"ok": false, "error": ..., "unreachable": true}.
class DaemonPort {
 public:
  enum class Channel { kCommand, kSafety, kPoll };
  using Reply = std::function<void(const json& reply)>;
  virtual ~DaemonPort() = default;
  virtual void request(Channel ch, json req, Reply cb) = 0;
  // On the client's own daemon connection (opened on first use).
  virtual void client_request(ClientId client, json req, Reply cb) = 0;
  virtual void close_client(ClientId client) = 0;
  [[nodiscard]] virtual bool connected() const = 0;
};

// A browser connection as the hub sees it (the WebSocket session).
class ClientPort {
 public:
  virtual ~ClientPort() = default;
  // samples > 0: a scope batch of that many samples, which the session may drop (oldest first,
  // counted) when the client is slow; 0: a reply, status or event, never dropped (a client that
  // lets client_queue_bytes of those pile up is closed).
  virtual void send(std::shared_ptr<const std::string> text, std::size_t samples) = 0;
  virtual void close(const std::string& reason) = 0;
  [[nodiscard]] virtual std::uint64_t dropped_samples() const = 0;
};

struct HubCounters {
  std::uint64_t requests = 0;
  std::uint64_t errors = 0;
  std::uint64_t rate_limited = 0;
  std::uint64_t forbidden = 0;
  std::uint64_t login_failures = 0;
  std::uint64_t samples_in = 0;       // telemetry samples received from contourd
  std::uint64_t sample_gaps = 0;      // cycles missing between consecutive samples
  std::uint64_t daemon_dropped = 0;   // contourd's count for our subscription (dropped + source)
  std::uint64_t deadman_stops = 0;
  std::uint64_t status_polls = 0;
};

class Hub {
 public:
  Hub(HubOptions opt, DaemonPort& daemon);

  // Browser connections. `remote` names the peer in log lines.
  ClientId connect(std::shared_ptr<ClientPort> port, std::string remote, Clock::time_point now);
  void on_message(ClientId id, std::string_view text, Clock::time_point now);
  void disconnect(ClientId id, Clock::time_point now);
  [[nodiscard]] std::size_t clients() const { return clients_.size(); }

  // From the daemon link.
  void on_daemon_line(const json& line);  // telemetry batches, events
  void on_daemon_state(bool up, const std::string& why);
  // Called every ~10 ms: status polling at status_rate_hz, dead-man checks.
  void tick(Clock::time_point now);

  [[nodiscard]] const HubCounters& counters() const { return counters_; }
  [[nodiscard]] const json& last_status() const { return status_; }
  // A line for the log (stdout/journal): never contains a token.
  std::function<void(const std::string&)> log = [](const std::string&) {};

 private:
  struct Client {
    ClientId id = 0;
    std::shared_ptr<ClientPort> port;
    std::string remote;
    config::WebRole role = config::WebRole::kNone;
    std::string name;  // token name ("" anonymous)
    double tokens = 0.0;
    Clock::time_point refill_at{};
    Clock::time_point last_seen{};
    int failed_logins = 0;
    // status subscription
    bool status_sub = false;
    std::vector<std::string> fields;  // empty: all top-level fields
    json sent;                        // last values sent, by field
    // scope
    bool scope_sub = false;
    std::vector<std::string> signals;
    std::uint32_t decimation = 1;
    bool events_sub = false;
    // jog dead-man
    bool jog_active = false;
    Clock::time_point jog_started{};
  };

  void reply(Client& c, const json& id, json result);
  void error(Client& c, const json& id, int code, const std::string& message);
  void handle(Client& c, const json& id, const std::string& method, const json& params,
              Clock::time_point now);
  void forward(Client& c, const json& id, const std::string& method, const json& params,
               Clock::time_point now);
  [[nodiscard]] bool allowed(const Client& c, const std::string& method, const json& params) const;
  json subscribe(Client& c, const json& params);
  void on_status(const json& st, Clock::time_point now);
  [[nodiscard]] json pick_fields(const Client& c) const;
  void publish_event(json ev);
  void stop_jog(Client& c, const std::string& why);
  Client* find(ClientId id);

  HubOptions opt_;
  DaemonPort& daemon_;
  std::map<ClientId, Client> clients_;
  ClientId next_id_ = 1;
  json status_ = json::object();
  bool have_status_ = false;
  bool poll_pending_ = false;
  Clock::time_point next_poll_{};
  Clock::time_point started_ = Clock::now();
  std::deque<json> events_;
  ScopeDecoder scope_;
  HubCounters counters_;
};

// Constant-time comparison (token check).
[[nodiscard]] bool equal_constant_time(std::string_view a, std::string_view b) noexcept;

}  // namespace contour::web
