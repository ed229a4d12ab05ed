#include "tools/contour-bridge/bridge.hpp"

#include <poll.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "tools/contour-bridge/credentials.hpp"

namespace contour::bridge {

using nlohmann::json;

namespace {

constexpr double kDaemonRetryMinS = 0.2;
constexpr double kDaemonRetryMaxS = 5.0;
constexpr std::size_t kMaxCommandBytes = 64 * 1024;

MqttLink::Clock::duration seconds(double s) {
  return std::chrono::duration_cast<MqttLink::Clock::duration>(std::chrono::duration<double>(s));
}

bool is_safety_command(const std::string& c) { return c == "hold" || c == "stop" || c == "estop"; }

}  // namespace

std::string expand_env(const std::string& s) {
  std::string out;
  std::size_t i = 0;
  while (i < s.size()) {
    if (s[i] == '$' && i + 1 < s.size() && s[i + 1] == '{') {
      const std::size_t end = s.find('}', i);
      if (end == std::string::npos) {
        out += s.substr(i);
        break;
      }
      std::string var = s.substr(i + 2, end - i - 2);
      std::string def;
      if (const std::size_t d = var.find(":-"); d != std::string::npos) {
        def = var.substr(d + 2);
        var = var.substr(0, d);
      }
      const char* v = std::getenv(var.c_str());
      out += (v != nullptr && *v != '\0') ? std::string(v) : def;
      i = end + 1;
    } else {
      out += s[i++];
    }
  }
  return out;
}

Topics make_topics(const config::MqttConfig& c) {
  Topics t;
  t.base = c.topic_prefix + "/" + c.machine_id;
  t.state = t.base + "/state";
  t.position = t.base + "/position";
  t.event = t.base + "/event";
  t.online = t.base + "/online";
  t.bridge = t.base + "/bridge";
  t.cmd = t.base + "/cmd";
  t.cmd_result = t.base + "/cmd/result";
  return t;
}

Bridge::Bridge(const config::Config& cfg, const BridgeOptions& opt)
    : cfg_(cfg),
      topics_(make_topics(cfg.mqtt)),
      mqtt_enabled_(cfg.mqtt.present),
      session_(now_us()),
      started_(Clock::now()),
      daemon_(
          expand_env(opt.socket_path.empty() ? cfg.socket.path : opt.socket_path),
          [this](const json& l) { on_daemon_event(l); },
          [this](const std::string& why) { on_daemon_lost(why); }),
      queue_(static_cast<std::size_t>(cfg.mqtt.present ? cfg.mqtt.queue_size : 16)) {
  if (!cfg_.mqtt.present && !cfg_.mtconnect.present) {
    throw std::runtime_error(cfg_.source +
                             ": neither `mqtt:` nor `mtconnect:` is configured: the bridge has "
                             "nothing to do");
  }
  id_.machine_id = cfg_.mqtt.present ? cfg_.mqtt.machine_id
                                     : (cfg_.mtconnect.device_name.empty()
                                            ? std::string("contourd")
                                            : cfg_.mtconnect.device_name);
  for (const auto& a : cfg_.machine.axes) id_.axes.push_back(a.name);
  double rate = cfg_.mqtt.present ? std::max(cfg_.mqtt.state_rate_hz, cfg_.mqtt.position_rate_hz)
                                  : 0.0;
  if (cfg_.mtconnect.present) rate = std::max(rate, cfg_.mtconnect.sample_rate_hz);
  rate = std::clamp(rate, 0.5, 50.0);
  poll_period_ = seconds(1.0 / rate);

  if (mqtt_enabled_) {
    Credentials cred;
    if (!cfg_.mqtt.credentials_file.empty()) cred = load_credentials(cfg_.mqtt.credentials_file);
    if (!cred.password.empty() && !cfg_.mqtt.tls.enabled) {
      spdlog::warn("mqtt: a password without TLS (no mqtt.tls): it travels in clear to {}:{}",
                   cfg_.mqtt.host, cfg_.mqtt.port);
    }
    MqttLink::Handlers h;
    h.connected = [this] { on_mqtt_connected(); };
    h.disconnected = [this](const std::string& why) {
      spdlog::warn("mqtt: connection to {}:{} lost ({}); {} messages queued, reconnecting",
                   cfg_.mqtt.host, cfg_.mqtt.port, why, queue_.size());
    };
    h.message = [this](const std::string& t, const std::string& p) { on_mqtt_message(t, p); };
    h.log = [](const std::string& text) { spdlog::warn("{}", text); };
    mqtt_ = std::make_unique<MqttLink>(cfg_.mqtt, cred, topics_.online, std::move(h));
  }
  if (cfg_.mtconnect.present) {
    const bool spindle = cfg_.spindle.type != "none";
    shdr_model_ = std::make_unique<ShdrModel>(id_.axes, spindle);
    std::vector<std::string> header{"* shdrVersion: 2"};
    if (!cfg_.mtconnect.manufacturer.empty()) {
      header.push_back("* manufacturer: " + cfg_.mtconnect.manufacturer);
    }
    if (!cfg_.mtconnect.serial_number.empty()) {
      header.push_back("* serialNumber: " + cfg_.mtconnect.serial_number);
    }
    shdr_ = std::make_unique<ShdrServer>(cfg_.mtconnect.bind, cfg_.mtconnect.port,
                                         cfg_.mtconnect.heartbeat_ms,
                                         static_cast<std::size_t>(cfg_.mtconnect.max_clients),
                                         header);
    spdlog::info("mtconnect: SHDR adapter on {}:{} (heartbeat {} ms)", cfg_.mtconnect.bind,
                 shdr_->port(), cfg_.mtconnect.heartbeat_ms);
  }
}

Bridge::~Bridge() = default;

void Bridge::enqueue(std::string topic, std::string payload, int qos, bool retain, MsgClass cls) {
  if (!mqtt_enabled_) return;
  queue_.push(OutMessage{std::move(topic), std::move(payload), qos, retain, cls});
}

// ---- daemon side ---------------------------------------------------------------------------

void Bridge::try_daemon_connect(Clock::time_point now) {
  if (daemon_.connect()) {
    ++daemon_connects_;
    daemon_backoff_s_ = 0.0;
    daemon_error_logged_.clear();
    spdlog::info("contourd: connected to {}", daemon_.path());
    // A restarted contourd numbers its jobs from 1 again: the next status names the last finished
    // job (its summary is published again, or for the first time).
    last_job_requested_ = 0;
    daemon_.call({{"cmd", "subscribe"}, {"topic", "events"}}, [](bool ok, const json& r) {
      if (!ok) spdlog::error("contourd: subscribe events refused: {}", r.dump());
    });
    next_poll_ = now;
    return;
  }
  if (daemon_.error() != daemon_error_logged_) {
    spdlog::warn("contourd: {}; retrying", daemon_.error());
    daemon_error_logged_ = daemon_.error();
  }
  daemon_backoff_s_ = daemon_backoff_s_ <= 0.0 ? kDaemonRetryMinS
                                               : std::min(kDaemonRetryMaxS, daemon_backoff_s_ * 2);
  daemon_retry_at_ = now + seconds(daemon_backoff_s_);
}

void Bridge::on_daemon_lost(const std::string& why) {
  ++daemon_losses_;
  spdlog::warn("contourd: {} ({}); reconnecting", why, daemon_.path());
  have_status_ = false;
  status_inflight_ = false;
  barrier_ = false;
  held_.clear();
  daemon_retry_at_ = Clock::now() + seconds(kDaemonRetryMinS);
  publish_state(false);
  if (shdr_model_) {
    shdr_model_->update(json::object(), false);
    shdr_flush();
  }
}

void Bridge::request_status() {
  status_inflight_ = true;
  daemon_.call({{"cmd", "status"}}, [this](bool ok, const json& st) {
    status_inflight_ = false;
    if (ok) {
      on_status(st);
    } else {
      spdlog::warn("contourd: status refused: {}", st.dump());
    }
  });
}

void Bridge::on_status(const json& st) {
  status_ = st;
  have_status_ = true;
  publish_state(false);
  maybe_publish_position(st);
  // A job that ended while its event was missed (bridge restarted, reconnect): its summary. Only
  // the most recent job: the daemon's `result` is final for the last finished job.
  const std::uint64_t fin = st.value("finished_job", 0ULL);
  const std::string s = st.value("state", std::string());
  if (fin > last_job_requested_ && s != "RUNNING" && s != "HOLD") fetch_result(fin);
  if (shdr_model_) {
    shdr_model_->update(st, true);
    shdr_flush();
  }
}

void Bridge::on_daemon_event(const json& line) {
  ++events_in_;
  if (barrier_) {
    held_.push_back(line);
    return;
  }
  process_event(line);
}

void Bridge::process_event(const json& line) {
  const DaemonEvent e = classify_event(line);
  publish_event(e);
  if (e.kind == "fault" || e.kind == "emcy") spdlog::warn("contourd: {}", e.text);
  if (e.kind == "transition") {
    next_poll_ = Clock::now();  // state and SHDR follow the transition at once
    if (e.from == "READY" && e.to == "RUNNING") {
      barrier_ = true;
      daemon_.call({{"cmd", "status"}}, [this](bool ok, const json& st) {
        if (ok) {
          std::uint64_t job = st.value("job", 0ULL);
          if (job == 0) job = st.value("finished_job", 0ULL);  // already over
          if (job != 0) {
            DaemonEvent start;
            start.kind = "program_start";
            start.job = job;
            start.text = "program " + std::to_string(job) + " started";
            if (st.contains("program") && st["program"].value("job", 0ULL) == job) {
              start.name = st["program"].value("name", std::string());
            }
            publish_event(start);
          }
          on_status(st);
        }
        barrier_ = false;
        while (!barrier_ && !held_.empty()) {
          const json l = held_.front();
          held_.pop_front();
          process_event(l);
        }
      });
    }
  }
  if (e.kind == "program_end") fetch_result(e.job);
}

void Bridge::fetch_result(std::uint64_t job) {
  if (job == 0 || job <= last_job_requested_) return;
  last_job_requested_ = job;
  daemon_.call({{"cmd", "result"}, {"job", job}}, [this, job](bool ok, const json& r) {
    if (!ok) {
      spdlog::warn("contourd: result of job {} refused: {}", job, r.dump());
      if (last_job_requested_ == job) last_job_requested_ = job - 1;  // the next status retries
      return;
    }
    // The daemon's reply verbatim: the object `contourctl --json run --wait` prints.
    std::string payload = r.dump();
    ++jobs_published_;
    spdlog::info("job {}: {} in {:.3f} s, max contour error {:.1f} um", job,
                 r.value("completed", false) ? "completed" : "NOT completed",
                 r.value("duration_s", 0.0), r.value("max_contour_error_um", 0.0));
    enqueue(topics_.job(job), payload, 1, true, MsgClass::kJob);
    if (cfg_.mqtt.retain_jobs > 0) {
      job_cache_.erase(std::remove_if(job_cache_.begin(), job_cache_.end(),
                                      [job](const auto& e) { return e.first == job; }),
                       job_cache_.end());
      job_cache_.emplace_back(job, std::move(payload));
      while (job_cache_.size() > static_cast<std::size_t>(cfg_.mqtt.retain_jobs)) {
        job_cache_.pop_front();
      }
    }
    if (shdr_model_) {
      shdr_model_->set_job_result(r);
      shdr_flush();
    }
  });
}

// ---- what is published ------------------------------------------------------------------------

void Bridge::publish_event(const DaemonEvent& e) {
  const std::int64_t ts = now_us();
  enqueue(topics_.event, event_payload(e, ++event_seq_, session_, id_, ts).dump(), 1, false,
          MsgClass::kEvent);
}

void Bridge::publish_state(bool force) {
  const bool available = daemon_.connected() && have_status_;
  json p = state_payload(status_, id_, available);
  if (!force && p == last_state_) return;
  last_state_ = p;
  const std::int64_t ts = now_us();
  p["ts"] = iso8601_utc(ts);
  p["ts_us"] = ts;
  p["session"] = session_;
  enqueue(topics_.state, p.dump(), 1, true, MsgClass::kState);
}

void Bridge::maybe_publish_position(const json& st) {
  if (!mqtt_enabled_ || cfg_.mqtt.position_rate_hz <= 0.0) return;
  const auto now = Clock::now();
  if (now < next_position_) return;
  const double moved_um = max_axis_move_mm(st, last_pos_status_) * 1000.0;
  if (!last_pos_status_.is_null() && !(moved_um > cfg_.mqtt.position_deadband_um)) return;
  last_pos_status_ = st;
  next_position_ = now + seconds(1.0 / cfg_.mqtt.position_rate_hz);
  ++positions_sampled_;
  json p = position_payload(st, id_);
  const std::int64_t ts = now_us();
  p["ts"] = iso8601_utc(ts);
  p["ts_us"] = ts;
  enqueue(topics_.position, p.dump(), 0, false, MsgClass::kPosition);
}

json Bridge::counters() const {
  const QueueCounters& q = queue_.counters();
  json j{{"machine_id", id_.machine_id},
         {"session", session_},
         {"uptime_s", std::chrono::duration<double>(Clock::now() - started_).count()},
         {"daemon", {{"connected", daemon_.connected()},
                     {"connects", daemon_connects_},
                     {"losses", daemon_losses_},
                     {"events", events_in_}}},
         {"queue", {{"depth", queue_.size()},
                    {"capacity", queue_.capacity()},
                    {"high_water", q.high_water},
                    {"enqueued", q.enqueued},
                    {"coalesced", q.coalesced},
                    {"dropped_positions", q.dropped_positions},
                    {"dropped_events", q.dropped_events}}},
         {"published", {{"events", event_seq_},
                        {"jobs", jobs_published_},
                        {"position_samples", positions_sampled_}}},
         {"commands", {{"enabled", cfg_.mqtt.commands.enabled},
                       {"forwarded", commands_ok_},
                       {"refused", commands_refused_}}}};
  if (mqtt_) {
    const MqttStats& s = mqtt_->stats();
    j["mqtt"] = {{"connected", mqtt_->connected()},
                 {"connects", s.connects},
                 {"reconnects", s.connects > 0 ? s.connects - 1 : 0},
                 {"disconnects", s.disconnects},
                 {"connect_failures", s.connect_failures},
                 {"published", s.published},
                 {"acked", s.acked},
                 {"inflight", mqtt_->inflight()},
                 {"lost_qos0", s.lost_qos0},
                 {"publish_errors", s.publish_errors},
                 {"backoff_s", mqtt_->backoff_s()},
                 {"last_error", mqtt_->last_error()}};
  }
  if (shdr_) {
    const ShdrServerStats& s = shdr_->stats();
    j["shdr"] = {{"port", shdr_->port()},
                 {"clients", s.clients},
                 {"accepted", s.accepted},
                 {"refused", s.refused},
                 {"dropped", s.dropped},
                 {"pings", s.pings}};
  }
  return j;
}

void Bridge::publish_bridge_status() {
  json c = counters();
  const std::int64_t ts = now_us();
  c["ts"] = iso8601_utc(ts);
  c["ts_us"] = ts;
  enqueue(topics_.bridge, c.dump(), 1, true, MsgClass::kMeta);
}

void Bridge::shdr_flush() {
  if (!shdr_ || !shdr_model_) return;
  shdr_->broadcast(shdr_model_->changed_lines(iso8601_utc(now_us())));
}

// ---- MQTT side -------------------------------------------------------------------------------

void Bridge::on_mqtt_connected() {
  spdlog::info("mqtt: connected to {}:{} as {} ({} messages queued)", cfg_.mqtt.host,
               cfg_.mqtt.port, cfg_.mqtt.client_id, queue_.size());
  // First "online", then the current snapshot and the retained job summaries (a broker that
  // restarted without persistence has lost them), then whatever waited in the queue.
  // Inside the connect callback the library queues the packet and writes it before anything
  // drained later (and before the QoS 1 messages it re-sends from the previous connection).
  mqtt_->publish_now(topics_.online, "online", 1, true);
  publish_state(true);
  for (const auto& [job, payload] : job_cache_) {
    if (!queue_.contains_topic(topics_.job(job))) {
      enqueue(topics_.job(job), payload, 1, true, MsgClass::kJob);
    }
  }
  publish_bridge_status();
  if (cfg_.mqtt.commands.enabled) mqtt_->subscribe(topics_.cmd, 1);
}

void Bridge::answer_command(const json& id, const std::string& cmd, bool ok, const json& body) {
  json a{{"id", id}, {"cmd", cmd}, {"ok", ok}, {"ts", iso8601_utc(now_us())}};
  a[ok ? "result" : "error"] = body;
  enqueue(topics_.cmd_result, a.dump(), 1, false, MsgClass::kEvent);
}

void Bridge::on_mqtt_message(const std::string& topic, const std::string& payload) {
  if (topic != topics_.cmd) return;
  if (!cfg_.mqtt.commands.enabled) return;  // not subscribed then; defensive
  json id = nullptr;
  std::string cmd;
  auto refuse = [&](const std::string& why) {
    ++commands_refused_;
    spdlog::warn("mqtt command{}: refused: {}", cmd.empty() ? "" : " '" + cmd + "'", why);
    answer_command(id, cmd, false, why);
  };
  if (payload.size() > kMaxCommandBytes) return refuse("payload larger than 64 KiB");
  json req;
  if (!payload.empty() && payload.find_first_not_of(" \t\r\n") != std::string::npos &&
      payload[payload.find_first_not_of(" \t\r\n")] == '{') {
    req = json::parse(payload, nullptr, false);
    if (req.is_discarded() || !req.is_object()) return refuse("payload is not a JSON object");
  } else {
    // A bare command word ("hold").
    std::string w = payload;
    while (!w.empty() && std::isspace(static_cast<unsigned char>(w.back())) != 0) w.pop_back();
    while (!w.empty() && std::isspace(static_cast<unsigned char>(w.front())) != 0) w.erase(0, 1);
    req = json{{"cmd", w}};
  }
  if (req.contains("id")) id = req["id"];
  if (!req.contains("cmd") || !req["cmd"].is_string() || req["cmd"].get<std::string>().empty()) {
    return refuse("missing \"cmd\" (a command name)");
  }
  cmd = req["cmd"].get<std::string>();
  const auto& allow = cfg_.mqtt.commands.allow;
  if (std::find(allow.begin(), allow.end(), cmd) == allow.end()) {
    std::string list;
    for (const auto& a : allow) list += (list.empty() ? "" : ", ") + a;
    return refuse("'" + cmd + "' is not allowed over MQTT (mqtt.commands.allow: " +
                  (list.empty() ? std::string("none") : list) + ")");
  }
  // Rate: a token bucket of max_per_s; safety commands (hold, stop, estop) are never refused.
  const auto now = Clock::now();
  const double rate = cfg_.mqtt.commands.max_per_s;
  cmd_tokens_ = std::min(std::max(1.0, rate),
                         cmd_tokens_ + rate * std::chrono::duration<double>(now - cmd_tokens_at_).count());
  cmd_tokens_at_ = now;
  if (!is_safety_command(cmd)) {
    if (cmd_tokens_ < 1.0) {
      return refuse("rate limited (mqtt.commands.max_per_s " + std::to_string(rate) + ")");
    }
    cmd_tokens_ -= 1.0;
  }
  json fwd = req;
  fwd.erase("id");
  spdlog::info("mqtt command '{}' (id {}) forwarded to contourd", cmd, id.dump());
  ++commands_ok_;
  daemon_.call(fwd, [this, id, cmd](bool ok, const json& r) {
    if (!ok) spdlog::warn("mqtt command '{}' (id {}): contourd: {}", cmd, id.dump(), r.dump());
    answer_command(id, cmd, ok, r);
  });
}

// ---- the loop ----------------------------------------------------------------------------------

int Bridge::run(const std::atomic<bool>& stop) {
  if (mqtt_) {
    spdlog::info("mqtt: publishing to {}:{} under {}/ (client id {}{}{})", cfg_.mqtt.host,
                 cfg_.mqtt.port, topics_.base, cfg_.mqtt.client_id,
                 cfg_.mqtt.tls.enabled ? ", TLS" : "",
                 cfg_.mqtt.credentials_file.empty() ? "" : ", credentials from file");
    mqtt_->start();
  }
  publish_state(true);  // UNAVAILABLE until the daemon answers
  if (shdr_model_) shdr_model_->update(json::object(), false);
  next_bridge_status_ = Clock::now() + seconds(cfg_.mqtt.status_interval_s);
  std::vector<pollfd> fds;
  while (!stop.load()) {
    auto now = Clock::now();
    if (!daemon_.connected() && now >= daemon_retry_at_) try_daemon_connect(now);
    if (daemon_.connected() && !status_inflight_ && now >= next_poll_) {
      request_status();
      next_poll_ = std::max(next_poll_ + poll_period_, now);
    }
    Clock::time_point wake = now + std::chrono::seconds(1);
    if (mqtt_) {
      wake = std::min(wake, mqtt_->tick(now));
      if (now >= next_bridge_status_) {
        publish_bridge_status();
        next_bridge_status_ = now + seconds(cfg_.mqtt.status_interval_s);
      }
      wake = std::min(wake, next_bridge_status_);
      mqtt_->drain(queue_);
    }
    if (daemon_.connected()) {
      if (!status_inflight_) wake = std::min(wake, next_poll_);
    } else {
      wake = std::min(wake, daemon_retry_at_);
    }

    fds.clear();
    const int dfd = daemon_.fd();
    if (dfd >= 0) fds.push_back(pollfd{dfd, daemon_.poll_events(), 0});
    const int mfd = mqtt_ ? mqtt_->fd() : -1;
    const short mev = mqtt_ ? mqtt_->poll_events() : 0;
    if (mfd >= 0 && mev != 0) fds.push_back(pollfd{mfd, mev, 0});
    const std::size_t shdr_first = fds.size();
    if (shdr_) shdr_->add_poll_fds(fds);
    const auto wait_ms = std::chrono::duration_cast<std::chrono::milliseconds>(wake - now).count();
    const int timeout = static_cast<int>(std::clamp<long long>(wait_ms, 0, 1000));
    const int n = ::poll(fds.data(), fds.size(), timeout);
    if (n < 0) {
      if (errno == EINTR) continue;
      spdlog::error("poll: {}", std::strerror(errno));
      return 1;
    }
    for (std::size_t i = 0; i < shdr_first; ++i) {
      if (fds[i].revents == 0) continue;
      if (fds[i].fd == dfd) daemon_.handle(fds[i].revents);
      if (mqtt_ && fds[i].fd == mfd) mqtt_->handle(fds[i].revents);
    }
    if (shdr_) {
      const std::vector<pollfd> mine(fds.begin() + static_cast<std::ptrdiff_t>(shdr_first),
                                     fds.end());
      shdr_->handle(mine, [this] { return shdr_model_->snapshot_lines(iso8601_utc(now_us())); });
    }
    if (mqtt_) mqtt_->drain(queue_);  // what the daemon just said goes out now
  }
  spdlog::info("contour-bridge: stopping ({} messages still queued)", queue_.size());
  if (mqtt_) {
    // Give the queue a last chance (bounded), then "offline" and a clean disconnect.
    const auto until = Clock::now() + std::chrono::seconds(2);
    while (mqtt_->connected() && !queue_.empty() && Clock::now() < until) {
      mqtt_->drain(queue_);
      pollfd p{mqtt_->fd(), mqtt_->poll_events(), 0};
      if (p.fd < 0) break;
      ::poll(&p, 1, 20);
      mqtt_->handle(p.revents);
    }
    mqtt_->shutdown(std::chrono::milliseconds(2000));
  }
  return 0;
}

}  // namespace contour::bridge
