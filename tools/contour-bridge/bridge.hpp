#pragma once
// contour-bridge's core: one thread, one poll(2) loop over
//   - the daemon's command socket (DaemonLink: `subscribe events`, periodic `status`, `result`
//     when a job ends, forwarded MQTT commands),
//   - the MQTT broker connection (MqttLink, fed from the bounded OutQueue),
//   - the SHDR adapter's listening socket and its agents (ShdrServer).
// What it publishes and why: tools/contour-bridge/README.md. Nothing here runs in, or waits for,
// contourd's RT loop: the daemon answers these requests on its socket thread.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "config/config.hpp"
#include "tools/contour-bridge/daemon_link.hpp"
#include "tools/contour-bridge/mqtt_link.hpp"
#include "tools/contour-bridge/out_queue.hpp"
#include "tools/contour-bridge/payloads.hpp"
#include "tools/contour-bridge/shdr.hpp"
#include "tools/contour-bridge/shdr_server.hpp"

namespace contour::bridge {

// `${VAR}` / `${VAR:-default}` in a path, as contourd expands socket.path.
std::string expand_env(const std::string& s);

struct BridgeOptions {
  std::string socket_path;  // "" = the config's socket.path
};

// Topic names under `<topic_prefix>/<machine_id>`.
struct Topics {
  std::string base, state, position, event, online, bridge, cmd, cmd_result;
  [[nodiscard]] std::string job(std::uint64_t n) const { return base + "/job/" + std::to_string(n); }
};
Topics make_topics(const config::MqttConfig& c);

class Bridge {
 public:
  using Clock = std::chrono::steady_clock;

  // Throws std::runtime_error / CredentialsError on anything that cannot work (credentials file,
  // TLS files, SHDR port in use): main() exits 78 for those, they need a config change.
  Bridge(const config::Config& cfg, const BridgeOptions& opt);
  ~Bridge();

  // Runs until `stop` is set (SIGTERM/SIGINT); publishes "offline" and disconnects cleanly.
  int run(const std::atomic<bool>& stop);

  // The bridge's counters (also published on `<base>/bridge`).
  [[nodiscard]] nlohmann::json counters() const;

 private:
  void try_daemon_connect(Clock::time_point now);
  void on_daemon_lost(const std::string& why);
  void on_daemon_event(const nlohmann::json& line);
  void process_event(const nlohmann::json& line);
  void request_status();
  void on_status(const nlohmann::json& st);
  void fetch_result(std::uint64_t job);
  void publish_event(const DaemonEvent& e);
  void publish_state(bool force);
  void maybe_publish_position(const nlohmann::json& st);
  void publish_bridge_status();
  void shdr_flush();
  void on_mqtt_connected();
  void on_mqtt_message(const std::string& topic, const std::string& payload);
  void answer_command(const nlohmann::json& id, const std::string& cmd, bool ok,
                      const nlohmann::json& body);
  void enqueue(std::string topic, std::string payload, int qos, bool retain, MsgClass cls);

  config::Config cfg_;
  Identity id_;
  Topics topics_;
  bool mqtt_enabled_;
  std::int64_t session_;
  Clock::time_point started_;

  DaemonLink daemon_;
  double daemon_backoff_s_ = 0.0;
  Clock::time_point daemon_retry_at_{};
  std::uint64_t daemon_connects_ = 0;
  std::uint64_t daemon_losses_ = 0;
  std::string daemon_error_logged_;

  nlohmann::json status_;
  bool have_status_ = false;
  bool status_inflight_ = false;
  Clock::time_point next_poll_{};
  Clock::duration poll_period_;

  // Event pipeline: a READY -> RUNNING transition holds later events until the status that names
  // the started job has been read (program_start, then what followed, in order).
  bool barrier_ = false;
  std::deque<nlohmann::json> held_;
  std::uint64_t event_seq_ = 0;
  std::uint64_t events_in_ = 0;

  std::uint64_t last_job_requested_ = 0;
  std::deque<std::pair<std::uint64_t, std::string>> job_cache_;  // retained summaries
  std::uint64_t jobs_published_ = 0;

  nlohmann::json last_state_;  // without time stamp
  nlohmann::json last_pos_status_;
  Clock::time_point next_position_{};
  std::uint64_t positions_sampled_ = 0;

  OutQueue queue_;
  std::unique_ptr<MqttLink> mqtt_;
  Clock::time_point next_bridge_status_{};
  std::uint64_t commands_ok_ = 0, commands_refused_ = 0;
  double cmd_tokens_ = 0.0;
  Clock::time_point cmd_tokens_at_{};

  std::unique_ptr<ShdrModel> shdr_model_;
  std::unique_ptr<ShdrServer> shdr_;
};

}  // namespace contour::bridge
