#pragma once
// contour-bridge's broker connection: libmosquitto (Debian's libmosquitto1) driven by the
// bridge's own poll loop (mosquitto_loop_read/write/misc, no library thread), so that publishing,
// callbacks and reconnecting all happen on one thread, in order:
//   - connect and reconnect are asynchronous (mosquitto_connect_async/reconnect_async); after a
//     lost connection the next attempt waits reconnect_min_s, doubling up to reconnect_max_s, with
//     +-20 % jitter (2,000 bridges must not hit a restarted broker in the same millisecond);
//   - the last will `<prefix>/<id>/online` = "offline" (retained, QoS 1) is set before connecting;
//   - drain() hands queued messages to the library only while connected, while fewer than
//     mqtt.max_inflight QoS 1 messages wait for their PUBACK and while the library's own output
//     is written out: the bridge's OutQueue is the one place messages wait (bounded), the library
//     never accumulates an unbounded backlog. QoS 1 messages the library already holds when the
//     connection drops are re-sent by it after the reconnect, before anything newer.
//   - TLS (CA file/path, client certificate and key, host name check), username/password.
#include <chrono>
#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <unordered_set>

#include "config/shopnet_config.hpp"
#include "tools/contour-bridge/credentials.hpp"
#include "tools/contour-bridge/out_queue.hpp"

struct mosquitto;
struct mosquitto_message;

namespace contour::bridge {

struct MqttStats {
  std::uint64_t connects = 0;          // CONNACK accepted
  std::uint64_t disconnects = 0;       // established connections lost
  std::uint64_t connect_failures = 0;  // attempts that never got a CONNACK (refused, auth, TLS)
  std::uint64_t published = 0;         // handed to the library
  std::uint64_t acked = 0;             // QoS 1 PUBACKs
  std::uint64_t lost_qos0 = 0;         // QoS 0 samples written into a connection that broke
  std::uint64_t publish_errors = 0;    // refused by the library for good (too large, bad topic)
  std::uint64_t commands_in = 0;       // messages received on subscribed topics
};

class MqttLink {
 public:
  using Clock = std::chrono::steady_clock;
  struct Handlers {
    std::function<void()> connected;
    std::function<void(const std::string& why)> disconnected;
    std::function<void(const std::string& topic, const std::string& payload)> message;
    std::function<void(const std::string& text)> log;  // connection problems (never secrets)
  };

  // Throws std::runtime_error (bad TLS files, library failure) naming the config key.
  MqttLink(const config::MqttConfig& cfg, const Credentials& cred, std::string online_topic,
           Handlers h);
  ~MqttLink();
  MqttLink(const MqttLink&) = delete;
  MqttLink& operator=(const MqttLink&) = delete;

  void start();
  [[nodiscard]] int fd() const;
  [[nodiscard]] short poll_events() const;
  void handle(short revents);
  // Keepalive and reconnects; returns when it next wants to run.
  Clock::time_point tick(Clock::time_point now);

  [[nodiscard]] bool connected() const { return connected_; }
  std::size_t drain(OutQueue& q);
  // Publishes at once, ahead of the queue (the "online" message from the connect callback).
  void publish_now(const std::string& topic, const std::string& payload, int qos, bool retain);
  void subscribe(const std::string& topic, int qos);
  // Publishes "offline" on the online topic, waits (bounded) until the library has written and
  // the broker acknowledged what it holds, then disconnects cleanly (no last will).
  void shutdown(std::chrono::milliseconds max_wait);

  [[nodiscard]] const MqttStats& stats() const { return stats_; }
  [[nodiscard]] std::size_t inflight() const { return qos1_mids_.size(); }
  [[nodiscard]] const std::string& last_error() const { return last_error_; }
  [[nodiscard]] double backoff_s() const { return backoff_s_; }

 private:
  static void on_connect_cb(mosquitto*, void* self, int rc);
  static void on_disconnect_cb(mosquitto*, void* self, int rc);
  static void on_publish_cb(mosquitto*, void* self, int mid);
  static void on_message_cb(mosquitto*, void* self, const mosquitto_message* m);
  static int password_cb(char* buf, int size, int rwflag, void* mosq);

  void attempt(Clock::time_point now);
  void schedule_retry(Clock::time_point now);
  void lost(const std::string& why);

  config::MqttConfig cfg_;
  Credentials cred_;
  std::string online_topic_;
  Handlers h_;
  mosquitto* m_ = nullptr;
  bool started_ = false;
  bool connected_ = false;
  bool connecting_ = false;  // a socket exists, CONNACK not yet seen
  bool stopping_ = false;
  Clock::time_point retry_at_{};
  Clock::time_point connect_started_{};
  double backoff_s_ = 0.0;
  std::unordered_set<int> qos1_mids_;
  MqttStats stats_;
  std::string last_error_;
  std::string refusal_;  // CONNACK refusal text, reported when the socket closes
  std::mt19937 rng_;
};

}  // namespace contour::bridge
