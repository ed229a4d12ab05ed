#include "tools/contour-bridge/mqtt_link.hpp"

#include <mosquitto.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <thread>

namespace contour::bridge {

namespace {

// A connect that has neither succeeded nor failed after this long is abandoned and retried (a
// broker host that drops SYNs would otherwise hold the attempt for the kernel's ~2 min).
constexpr std::chrono::seconds kConnectTimeout{10};

struct LibInit {
  LibInit() { mosquitto_lib_init(); }
  ~LibInit() { mosquitto_lib_cleanup(); }
};

std::string rc_text(int rc) {
  if (rc == MOSQ_ERR_ERRNO) return std::strerror(errno);
  return mosquitto_strerror(rc);
}

}  // namespace

MqttLink::MqttLink(const config::MqttConfig& cfg, const Credentials& cred,
                   std::string online_topic, Handlers h)
    : cfg_(cfg),
      cred_(cred),
      online_topic_(std::move(online_topic)),
      h_(std::move(h)),
      rng_(static_cast<std::mt19937::result_type>(
          std::chrono::steady_clock::now().time_since_epoch().count() ^ ::getpid())) {
  static LibInit init;
  // clean session: the bridge keeps no broker-side state; what it must deliver waits in its own
  // queue (and QoS 1 messages in flight are re-sent by the library after a reconnect).
  m_ = mosquitto_new(cfg_.client_id.c_str(), true, this);
  if (m_ == nullptr) throw std::runtime_error("mqtt: mosquitto_new failed (out of memory?)");
  mosquitto_connect_callback_set(m_, &MqttLink::on_connect_cb);
  mosquitto_disconnect_callback_set(m_, &MqttLink::on_disconnect_cb);
  mosquitto_publish_callback_set(m_, &MqttLink::on_publish_cb);
  mosquitto_message_callback_set(m_, &MqttLink::on_message_cb);
  mosquitto_int_option(m_, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
  mosquitto_int_option(m_, MOSQ_OPT_SEND_MAXIMUM, cfg_.max_inflight);
  mosquitto_int_option(m_, MOSQ_OPT_TCP_NODELAY, 1);
  int rc = mosquitto_will_set(m_, online_topic_.c_str(), 7, "offline", 1, true);
  if (rc != MOSQ_ERR_SUCCESS) {
    throw std::runtime_error("mqtt: last will on " + online_topic_ + ": " + rc_text(rc));
  }
  if (!cred_.username.empty()) {
    rc = mosquitto_username_pw_set(m_, cred_.username.c_str(),
                                   cred_.password.empty() ? nullptr : cred_.password.c_str());
    if (rc != MOSQ_ERR_SUCCESS) {
      throw std::runtime_error("mqtt.credentials_file: username/password refused by libmosquitto: " +
                               rc_text(rc));
    }
  }
  if (cfg_.tls.enabled) {
    auto opt = [](const std::string& s) { return s.empty() ? nullptr : s.c_str(); };
    for (auto [key, path] : {std::pair{"ca_file", &cfg_.tls.ca_file},
                             std::pair{"cert_file", &cfg_.tls.cert_file},
                             std::pair{"key_file", &cfg_.tls.key_file}}) {
      if (!path->empty() && ::access(path->c_str(), R_OK) != 0) {
        throw std::runtime_error(std::string("mqtt.tls.") + key + ": " + *path + ": " +
                                 std::strerror(errno));
      }
    }
    rc = mosquitto_tls_set(m_, opt(cfg_.tls.ca_file), opt(cfg_.tls.ca_path),
                           opt(cfg_.tls.cert_file), opt(cfg_.tls.key_file),
                           cfg_.tls.key_file.empty() ? nullptr : &MqttLink::password_cb);
    if (rc != MOSQ_ERR_SUCCESS) {
      throw std::runtime_error("mqtt.tls: the CA/certificate/key files were refused: " +
                               rc_text(rc));
    }
    rc = mosquitto_tls_opts_set(m_, 1, opt(cfg_.tls.version), opt(cfg_.tls.ciphers));
    if (rc != MOSQ_ERR_SUCCESS) {
      throw std::runtime_error("mqtt.tls.version/ciphers refused: " + rc_text(rc));
    }
    mosquitto_tls_insecure_set(m_, cfg_.tls.insecure);
  }
}

MqttLink::~MqttLink() {
  if (m_ != nullptr) mosquitto_destroy(m_);
}

int MqttLink::password_cb(char* buf, int size, int, void* mosq) {
  // OpenSSL's user data here is the `struct mosquitto*` (libmosquitto sets it so), not ours.
  const auto* me = static_cast<MqttLink*>(mosquitto_userdata(static_cast<mosquitto*>(mosq)));
  if (me == nullptr) return 0;
  const std::string& pw = me->cred_.key_password;
  if (size <= 0) return 0;
  const int n = std::min(static_cast<int>(pw.size()), size - 1);
  std::memcpy(buf, pw.data(), static_cast<std::size_t>(n));
  buf[n] = '\0';
  return n;
}

void MqttLink::start() {
  started_ = true;
  attempt(Clock::now());
}

void MqttLink::attempt(Clock::time_point now) {
  connecting_ = false;
  const int rc = stats_.connects + stats_.connect_failures == 0
                     ? mosquitto_connect_async(m_, cfg_.host.c_str(), cfg_.port, cfg_.keepalive_s)
                     : mosquitto_reconnect_async(m_);
  if (rc == MOSQ_ERR_SUCCESS) {
    connecting_ = true;
    connect_started_ = now;
    return;
  }
  ++stats_.connect_failures;
  last_error_ = cfg_.host + ":" + std::to_string(cfg_.port) + ": " + rc_text(rc);
  if (h_.log) h_.log("mqtt: cannot connect to " + last_error_);
  schedule_retry(now);
}

void MqttLink::schedule_retry(Clock::time_point now) {
  backoff_s_ = backoff_s_ <= 0.0 ? cfg_.reconnect_min_s
                                 : std::min(cfg_.reconnect_max_s, backoff_s_ * 2.0);
  std::uniform_real_distribution<double> jitter(0.8, 1.2);
  const double wait = std::min(cfg_.reconnect_max_s, backoff_s_ * jitter(rng_));
  retry_at_ = now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(wait));
}

int MqttLink::fd() const { return m_ != nullptr ? mosquitto_socket(m_) : -1; }

short MqttLink::poll_events() const {
  if ((!connected_ && !connecting_) || fd() < 0) return 0;  // no socket, or a stale one
  return static_cast<short>(POLLIN | (mosquitto_want_write(m_) ? POLLOUT : 0));
}

void MqttLink::handle(short revents) {
  if ((!connected_ && !connecting_) || fd() < 0) return;
  if ((revents & (POLLIN | POLLHUP | POLLERR)) != 0) mosquitto_loop_read(m_, 1);
  if (fd() >= 0 && (revents & POLLOUT) != 0) mosquitto_loop_write(m_, 1);
  if (fd() < 0 && (connected_ || connecting_)) lost("connection closed");
}

MqttLink::Clock::time_point MqttLink::tick(Clock::time_point now) {
  if (!started_ || stopping_) return now + std::chrono::seconds(1);
  if (connected_ || connecting_) {
    if (fd() >= 0) mosquitto_loop_misc(m_);  // keepalive PINGREQ, or close when it timed out
    if (fd() < 0) {
      if (connected_ || connecting_) lost("keepalive timeout");
    } else if (connecting_ && now - connect_started_ > kConnectTimeout) {
      // The stale socket is closed by the next reconnect attempt (mosquitto_reconnect_async).
      lost("no answer from the broker within " + std::to_string(kConnectTimeout.count()) + " s");
    }
  }
  if (!connected_ && !connecting_) {
    if (now >= retry_at_) attempt(now);
    if (!connecting_) return retry_at_;
  }
  return now + std::chrono::milliseconds(500);
}

void MqttLink::lost(const std::string& why) {
  const bool was = connected_;
  connected_ = false;
  connecting_ = false;
  if (was) {
    ++stats_.disconnects;
  } else {
    ++stats_.connect_failures;
  }
  last_error_ = refusal_.empty() ? why : refusal_;
  refusal_.clear();
  schedule_retry(Clock::now());
  if (was && h_.disconnected) h_.disconnected(last_error_);
  if (!was && h_.log) {
    h_.log("mqtt: connect to " + cfg_.host + ":" + std::to_string(cfg_.port) +
           " failed: " + last_error_);
  }
}

void MqttLink::on_connect_cb(mosquitto*, void* self, int rc) {
  auto* me = static_cast<MqttLink*>(self);
  if (rc != 0) {
    // Refused by the broker (not authorised, bad credentials, client id): it closes the link.
    me->refusal_ = std::string("broker refused the connection: ") + mosquitto_connack_string(rc);
    return;
  }
  me->connecting_ = false;
  me->connected_ = true;
  me->backoff_s_ = 0.0;
  ++me->stats_.connects;
  if (me->h_.connected) me->h_.connected();
}

void MqttLink::on_disconnect_cb(mosquitto*, void* self, int rc) {
  auto* me = static_cast<MqttLink*>(self);
  if (me->stopping_) return;
  if (me->connected_ || me->connecting_) {
    me->lost(rc == 0 ? "disconnected" : std::string("connection lost: ") + mosquitto_strerror(rc));
  }
}

void MqttLink::on_publish_cb(mosquitto*, void* self, int mid) {
  auto* me = static_cast<MqttLink*>(self);
  if (me->qos1_mids_.erase(mid) != 0) ++me->stats_.acked;
}

void MqttLink::on_message_cb(mosquitto*, void* self, const mosquitto_message* m) {
  auto* me = static_cast<MqttLink*>(self);
  ++me->stats_.commands_in;
  if (!me->h_.message || m == nullptr || m->topic == nullptr) return;
  const std::string payload(static_cast<const char*>(m->payload),
                            static_cast<std::size_t>(std::max(m->payloadlen, 0)));
  me->h_.message(m->topic, payload);
}

std::size_t MqttLink::drain(OutQueue& q) {
  std::size_t n = 0;
  while (connected_ && !q.empty() && qos1_mids_.size() < static_cast<std::size_t>(cfg_.max_inflight) &&
         !mosquitto_want_write(m_)) {
    const OutMessage& msg = q.front();
    int mid = 0;
    const int rc = mosquitto_publish(m_, &mid, msg.topic.c_str(), static_cast<int>(msg.payload.size()),
                                     msg.payload.data(), msg.qos, msg.retain);
    switch (rc) {
      case MOSQ_ERR_INVAL:
      case MOSQ_ERR_MALFORMED_UTF8:
      case MOSQ_ERR_PAYLOAD_SIZE:
      case MOSQ_ERR_OVERSIZE_PACKET:
      case MOSQ_ERR_QOS_NOT_SUPPORTED:
        // Can never be sent: dropped and counted (a bug or a broker limit, not an outage).
        ++stats_.publish_errors;
        last_error_ = "publish to " + msg.topic + " refused: " + rc_text(rc);
        if (h_.log) h_.log("mqtt: " + last_error_);
        q.pop_front();
        continue;
      case MOSQ_ERR_NOMEM:
        return n;  // not taken: stays first in our queue
      default:
        break;
    }
    if (msg.qos == 0 && rc != MOSQ_ERR_SUCCESS) {
      if (rc == MOSQ_ERR_NO_CONN) return n;  // never sent: keep it
      ++stats_.lost_qos0;                     // written into a connection that just broke
    }
    // QoS 1: the library holds it from here on (re-sent after a reconnect until PUBACK).
    if (msg.qos > 0) qos1_mids_.insert(mid);
    ++stats_.published;
    ++n;
    q.pop_front();
    if (rc != MOSQ_ERR_SUCCESS) break;
  }
  return n;
}

void MqttLink::publish_now(const std::string& topic, const std::string& payload, int qos,
                           bool retain) {
  int mid = 0;
  const int rc = mosquitto_publish(m_, &mid, topic.c_str(), static_cast<int>(payload.size()),
                                   payload.data(), qos, retain);
  if (rc == MOSQ_ERR_SUCCESS) {
    if (qos > 0) qos1_mids_.insert(mid);
    ++stats_.published;
  } else if (h_.log) {
    h_.log("mqtt: publish " + topic + ": " + rc_text(rc));
  }
}

void MqttLink::subscribe(const std::string& topic, int qos) {
  const int rc = mosquitto_subscribe(m_, nullptr, topic.c_str(), qos);
  if (rc != MOSQ_ERR_SUCCESS && h_.log) h_.log("mqtt: subscribe " + topic + ": " + rc_text(rc));
}

void MqttLink::shutdown(std::chrono::milliseconds max_wait) {
  if (m_ == nullptr || !connected_) return;
  int mid = 0;
  if (mosquitto_publish(m_, &mid, online_topic_.c_str(), 7, "offline", 1, true) == MOSQ_ERR_SUCCESS) {
    qos1_mids_.insert(mid);
  }
  const auto until = Clock::now() + max_wait;
  while (Clock::now() < until && fd() >= 0 && (!qos1_mids_.empty() || mosquitto_want_write(m_))) {
    pollfd p{fd(), poll_events(), 0};
    ::poll(&p, 1, 20);
    handle(p.revents);
  }
  stopping_ = true;
  mosquitto_disconnect(m_);
  // Write the DISCONNECT packet out.
  for (int i = 0; i < 10 && fd() >= 0 && mosquitto_want_write(m_); ++i) {
    mosquitto_loop_write(m_, 1);
  }
  connected_ = false;
}

}  // namespace contour::bridge
