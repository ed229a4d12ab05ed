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
// line is discarded up to its newline. The handler runs on the server thread (never on the RT
// thread) and must not block for long.
// The socket file is created with `mode` (default 0660: group-writable, not world-writable) and,
// when `group` is set, chowned to that group.
//
// The operator can always get through (issue 17); the limits, each counted in CommandServerStats
// and reported through `on_notice` (naming the client: id, pid, uid, fd):
// - idle: a client without a complete request for idle_timeout_s is dropped (a slow-loris writer
//   sending a partial line byte by byte counts as idle). Subscribers (events/telemetry) are
//   consumers and exempt while subscribed.
// - full table: a new connection is never refused; the longest-idle client is closed to make room,
//   after its pending input has been served (a queued estop in it still runs). Order: clients that
//   never sent a complete request (oldest connection first), then those that did (oldest last
//   request first), subscribers last. Clients accepted in the same poll round are not candidates,
//   and while there are such, only silent clients are (a burst of connections cannot sweep out the
//   established clients in one round); otherwise the connection waits in the listen backlog for
//   the next round, which follows at once.
// - rate: more than max_requests_per_s requests (token bucket, 1 s burst) get the error reply
//   "rate limited ..."; estop, hold and stop are never refused.
// - buffered bytes: a client with more than max_buffered_bytes of replies/events unread is
//   dropped; its input is bounded by max_line_bytes plus one read (the server stops reading a
//   client while it has unprocessed complete lines).
// - fairness: per poll round each client gets at most kReadBudgetBytes read and kLinesPerRound
//   requests handled, so no client can keep the thread busy while others wait.
//
// Sample streams (the `telemetry` topic, issue 21): publish_stream() hands the server a chunk of
// pre-encoded samples, each with its sequence number (the loop cycle); the topic is a stream topic
// from then on. Every subscriber has its own bounded queue of samples (max_stream_samples), filled
// with every sample whose sequence number is a multiple of the decimation it asked for
// (subscribe(..., StreamOptions), default 1: every sample). The server moves queued samples into
// the client's output as batch lines while its unsent output is below kStreamLowWaterBytes:
//   {"event": TOPIC, "count": N, "decimation": K, "dropped": D, "source_dropped": S,
//    "samples": [ {sample}, ... ]}
// D counts this client's samples the server dropped (oldest first) because the client did not
// read fast enough: a slow or stuck subscriber never blocks the publisher or other clients and is
// not disconnected for it. S is the publisher's own count (telemetry: samples the RT loop could
// not hand to the writer, telemetry ring full), passed through. Both are cumulative. A
// subscriber sees gaps in the sample sequence numbers exactly where D or S grew.
// publish() of a single event on a stream topic goes into the same queues as a one-sample chunk
// (its "event" key removed), so a subscriber sees one format.
#include <sys/types.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <set>
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
  std::size_t max_backlog_bytes = 4 * 1024 * 1024;  // socket.max_buffered_bytes (output)
  double idle_timeout_s = 60.0;           // socket.idle_timeout_s
  double max_requests_per_s = 500.0;      // socket.max_requests_per_s (estop/hold/stop exempt)
  double max_notices_per_s = 20.0;        // on_notice calls; the rest are counted and summarised
  std::size_t max_stream_samples = 8192;  // per subscriber and stream topic (8 s at 1 kHz)
  std::size_t max_batch_samples = 200;    // samples per batch line
};

struct ClientInfo {
  std::uint64_t id = 0;   // unique per connection
  uid_t uid = 0;          // peer credentials (SO_PEERCRED)
  pid_t pid = 0;
  int fd = -1;            // server-side descriptor (for log lines; reused after close)
};

// What the server did to whom (dropped, evicted, rate-limited), for the daemon's log and the
// `events` subscription. Emitted on the server thread with no lock held.
struct ServerNotice {
  enum class Kind { kDroppedIdle, kEvicted, kRateLimited, kDroppedBuffer };
  Kind kind = Kind::kDroppedIdle;
  ClientInfo client;
  std::string text;  // one line naming the rule, the client (id, pid, uid, fd) and the figures
};
[[nodiscard]] const char* to_string(ServerNotice::Kind k) noexcept;

// One sample of a stream topic: its sequence number (telemetry: the loop cycle) and its JSON
// object text (no newline).
struct StreamItem {
  std::uint64_t seq = 0;
  std::string json;
};
struct StreamChunk {
  std::vector<StreamItem> items;  // in sequence order
  std::uint64_t source_dropped = 0;  // the publisher's cumulative loss count (passed through)
};
struct StreamOptions {
  std::uint32_t decimation = 1;  // only samples whose seq is a multiple of this (1: every sample)
};

struct CommandServerStats {
  std::uint64_t connections = 0;
  std::uint64_t requests = 0;
  std::uint64_t errors = 0;          // malformed / oversize / rejected / rate-limited requests
  std::uint64_t dropped_clients = 0; // closed by the server: idle + evicted + oversize_buffer
  std::uint64_t dropped_idle = 0;    // no complete request within idle_timeout_s
  std::uint64_t evicted_idle = 0;    // longest-idle client closed to make room for a new one
  std::uint64_t rate_limited = 0;    // requests refused by the per-client rate limit
  std::uint64_t oversize_buffer = 0; // clients dropped for > max_backlog_bytes unread output
  std::uint64_t notices_suppressed = 0;  // notices over max_notices_per_s (counted, not emitted)
  std::uint64_t stream_samples_sent = 0;  // samples moved into subscribers' output (all clients)
  std::uint64_t stream_dropped = 0;       // samples dropped from slow subscribers' queues
  std::size_t clients = 0;
};

class CommandServer {
 public:
  // Returns the reply's "result" object, or throws CommandError for an error reply.
  using Handler = std::function<nlohmann::json(const nlohmann::json& request, const ClientInfo&)>;
  using NoticeHandler = std::function<void(const ServerNotice&)>;

  // Per poll round and client: bytes read and requests handled (fairness between clients).
  static constexpr std::size_t kReadBudgetBytes = 16 * 1024;
  static constexpr int kLinesPerRound = 8;
  // Stream samples are moved into a client's output only while less than this is unsent.
  static constexpr std::size_t kStreamLowWaterBytes = 64 * 1024;

  CommandServer(CommandServerOptions opt, Handler handler, NoticeHandler on_notice = {});
  ~CommandServer();
  CommandServer(const CommandServer&) = delete;
  CommandServer& operator=(const CommandServer&) = delete;

  // Binds and listens (throws std::runtime_error naming the path on failure), starts the thread.
  void start();
  void stop();

  // Subscriptions: the handler may call subscribe(client, topic); publish() queues a line for every
  // subscriber of the topic (thread-safe, non-blocking; called from non-RT threads only).
  void subscribe(std::uint64_t client, const std::string& topic);
  // The same, with options for a stream topic (kept until unsubscribe; ignored for other topics).
  void subscribe(std::uint64_t client, const std::string& topic, StreamOptions opt);
  void unsubscribe(std::uint64_t client, const std::string& topic);
  void publish(const std::string& topic, const nlohmann::json& event);
  // Queues a chunk of samples for every subscriber of a stream topic (see the header comment).
  // Thread-safe, non-blocking, never drops a client; called from non-RT threads only.
  void publish_stream(const std::string& topic, std::shared_ptr<const StreamChunk> chunk);
  // Samples dropped so far for this client and topic (0 if unknown).
  [[nodiscard]] std::uint64_t stream_dropped(std::uint64_t client, const std::string& topic) const;
  // Called on the server thread, with no lock held, once for every client that is gone (hung up,
  // dropped, evicted), after the round in which it went: a dead-man (continuous jog) or a
  // per-client resource ends with its client. Set before start().
  using DisconnectHandler = std::function<void(const ClientInfo&)>;
  void on_disconnect(DisconnectHandler h) { on_disconnect_ = std::move(h); }

  [[nodiscard]] CommandServerStats stats() const;
  [[nodiscard]] const std::string& path() const { return opt_.path; }

 private:
  using Clock = std::chrono::steady_clock;
  struct StreamRef {
    std::shared_ptr<const StreamChunk> chunk;
    std::uint32_t index = 0;
  };
  struct StreamQueue {
    std::string topic;
    StreamOptions opt;
    std::deque<StreamRef> refs;  // bounded by max_stream_samples, oldest dropped
    std::uint64_t dropped = 0;
    std::uint64_t source_dropped = 0;
  };
  struct Client {
    int fd = -1;
    ClientInfo info;
    std::string in;           // received, not yet processed (complete lines + one partial line)
    std::string out;
    bool discarding = false;  // inside an oversize line
    bool eof = false;         // peer hung up: serve what is in `in`, then close
    bool fresh = true;        // accepted in this poll round (not yet polled: never evicted)
    bool requested = false;   // has sent a complete request
    bool overflow = false;    // out > max_backlog_bytes: dropped at the end of the round
    std::vector<std::string> topics;
    std::map<std::string, StreamOptions> stream_opts;  // options given at subscribe
    std::vector<StreamQueue> streams;                  // stream topics it is subscribed to
    Clock::time_point connected_at{};
    Clock::time_point last_request{};  // last complete request line (connect time before one)
    double tokens = 0.0;               // rate limit bucket
    Clock::time_point refill_at{};
    bool rate_noticed = false;         // one notice per burst over the rate
  };
  void run();
  void accept_clients();
  void reap_hung_up_clients();
  bool evict_longest_idle(const ClientInfo& for_whom);
  [[nodiscard]] bool has_eviction_candidate() const;
  void drop_idle_clients(Clock::time_point now);
  enum class ReadResult { kDrained, kMore, kClosed };  // EAGAIN / budget used / EOF or error
  ReadResult read_client(Client& c);    // appends up to kReadBudgetBytes to c.in
  bool serve_pending(Client& c);        // reads + handles what it sent; false: it hung up
  bool process_input(Client& c);        // handles up to kLinesPerRound lines; false: close
  [[nodiscard]] bool has_complete_line(const Client& c) const;
  bool flush_client(Client& c);
  void pump_streams(Client& c);  // queued stream samples -> batch lines in c.out (mu_ held)
  void enqueue_stream(Client& c, const std::string& topic,
                      const std::shared_ptr<const StreamChunk>& chunk);  // mu_ held
  void handle_line(Client& c, const std::string& line);
  void queue(Client& c, const nlohmann::json& j);
  void notice(ServerNotice::Kind k, const ClientInfo& who, std::string text);
  void emit_notices();  // also the disconnect callbacks
  // Closes the client's descriptor, erases it (caller holds mu_) and queues its disconnect.
  std::map<std::uint64_t, Client>::iterator close_client(std::map<std::uint64_t, Client>::iterator it);
  [[nodiscard]] static std::string describe(const ClientInfo& c);

  CommandServerOptions opt_;
  Handler handler_;
  NoticeHandler on_notice_;
  int listen_fd_ = -1;
  int wake_pipe_[2] = {-1, -1};
  std::thread thread_;
  std::atomic<bool> running_{false};
  mutable std::mutex mu_;  // guards clients_ and stats_ (server thread vs publish/stats callers)
  std::map<std::uint64_t, Client> clients_;
  std::uint64_t next_id_ = 1;
  CommandServerStats stats_;
  DisconnectHandler on_disconnect_;
  std::vector<ClientInfo> pending_disconnects_;  // guarded by mu_
  std::set<std::string> stream_topics_;          // guarded by mu_
  std::vector<ServerNotice> pending_notices_;  // server thread only; emitted without mu_
  double notice_tokens_ = 0.0;
  Clock::time_point notice_refill_at_{};
  std::uint64_t notices_suppressed_since_ = 0;  // suppressed since the last emitted notice
  std::atomic<std::uint64_t> notices_suppressed_{0};
};

}  // namespace contour::daemon
