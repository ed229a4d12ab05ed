#include "tools/contour-web/hub.hpp"

#include <algorithm>
#include <cmath>

namespace contour::web {

namespace {
using config::WebRole;

constexpr int kParseError = -32700;
constexpr int kInvalidRequest = -32600;
constexpr int kNoMethod = -32601;
constexpr int kInvalidParams = -32602;
constexpr int kRefused = -32000;
constexpr int kLogin = -32001;
constexpr int kForbidden = -32003;
constexpr int kRateLimited = -32005;
constexpr int kUnreachable = -32010;
constexpr int kMaxFailedLogins = 5;
constexpr double kJogStatusLagS = 0.5;  // a jog this young may not show in the polled status yet

bool is_safety(const std::string& m) { return m == "estop" || m == "hold" || m == "stop"; }

// Commands a viewer may send: queries only.
bool viewer_may(const std::string& m, const json& params) {
  if (m == "status" || m == "result") return true;
  if (m == "gains") return !params.contains("set");
  if (m == "force") return params.empty();
  return false;
}

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// Dotted path lookup ("timing.lateness_max_us"); null when absent.
json lookup(const json& st, const std::string& path) {
  const json* cur = &st;
  std::size_t pos = 0;
  while (pos <= path.size()) {
    const auto dot = path.find('.', pos);
    const std::string key = path.substr(pos, dot == std::string::npos ? std::string::npos : dot - pos);
    if (!cur->is_object()) return nullptr;
    auto it = cur->find(key);
    if (it == cur->end()) return nullptr;
    cur = &*it;
    if (dot == std::string::npos) break;
    pos = dot + 1;
  }
  return *cur;
}
}  // namespace

bool equal_constant_time(std::string_view a, std::string_view b) noexcept {
  // Length differences leak only the length; every byte of the longer one is visited.
  const std::size_t n = std::max(a.size(), b.size());
  unsigned diff = static_cast<unsigned>(a.size() ^ b.size());
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned ca = i < a.size() ? static_cast<unsigned char>(a[i]) : 0u;
    const unsigned cb = i < b.size() ? static_cast<unsigned char>(b[i]) : 0u;
    diff |= ca ^ cb;
  }
  return diff == 0 && n > 0;
}

Hub::Hub(HubOptions opt, DaemonPort& daemon) : opt_(std::move(opt)), daemon_(daemon) {}

Hub::Client* Hub::find(ClientId id) {
  auto it = clients_.find(id);
  return it == clients_.end() ? nullptr : &it->second;
}

ClientId Hub::connect(std::shared_ptr<ClientPort> port, std::string remote, Clock::time_point now) {
  Client c;
  c.id = next_id_++;
  c.port = std::move(port);
  c.remote = std::move(remote);
  c.role = opt_.anonymous_role;
  c.tokens = std::max(1.0, opt_.max_requests_per_s);
  c.refill_at = now;
  c.last_seen = now;
  const ClientId id = c.id;
  log("client " + std::to_string(id) + " connected from " + c.remote + " (role " +
      to_string(c.role) + " until login)");
  clients_.emplace(id, std::move(c));
  return id;
}

void Hub::disconnect(ClientId id, Clock::time_point) {
  Client* c = find(id);
  if (c == nullptr) return;
  if (c->jog_active) stop_jog(*c, "its connection closed");
  daemon_.close_client(id);
  log("client " + std::to_string(id) + " (" + c->remote + ") disconnected");
  clients_.erase(id);
}

void Hub::reply(Client& c, const json& id, json result) {
  if (id.is_null()) return;  // a notification gets no reply
  json r{{"jsonrpc", "2.0"}, {"id", id}, {"result", std::move(result)}};
  c.port->send(std::make_shared<const std::string>(r.dump(-1, ' ', false, json::error_handler_t::replace)), 0);
}

void Hub::error(Client& c, const json& id, int code, const std::string& message) {
  ++counters_.errors;
  json r{{"jsonrpc", "2.0"}, {"id", id}, {"error", {{"code", code}, {"message", message}}}};
  c.port->send(std::make_shared<const std::string>(r.dump(-1, ' ', false, json::error_handler_t::replace)), 0);
}

void Hub::on_message(ClientId cid, std::string_view text, Clock::time_point now) {
  Client* cp = find(cid);
  if (cp == nullptr) return;
  Client& c = *cp;
  c.last_seen = now;
  ++counters_.requests;
  json req;
  try {
    req = json::parse(text);
  } catch (const json::exception&) {
    error(c, nullptr, kParseError, "parse error: not JSON");
    return;
  }
  if (!req.is_object()) {
    error(c, nullptr, kInvalidRequest, "invalid request: expected one JSON-RPC 2.0 object (no batches)");
    return;
  }
  json id = req.contains("id") ? req["id"] : json(nullptr);
  if (!(id.is_null() || id.is_string() || id.is_number())) {
    error(c, nullptr, kInvalidRequest, "invalid request: id must be a string or a number");
    return;
  }
  if (req.value("jsonrpc", "") != "2.0" || !req.contains("method") || !req["method"].is_string()) {
    error(c, id, kInvalidRequest, "invalid request: needs \"jsonrpc\": \"2.0\" and a string \"method\"");
    return;
  }
  const std::string method = req["method"].get<std::string>();
  json params = req.contains("params") ? req["params"] : json::object();
  if (params.is_null()) params = json::object();
  if (!params.is_object()) {
    error(c, id, kInvalidParams, "invalid params: give them by name (a JSON object)");
    return;
  }
  // Rate limit (token bucket, 1 s burst); the safety commands and the dead-man always pass.
  const double rate = opt_.max_requests_per_s;
  c.tokens = std::min(std::max(1.0, rate), c.tokens + rate * seconds(now - c.refill_at));
  c.refill_at = now;
  if (!is_safety(method) && method != "web.deadman") {
    if (c.tokens < 1.0) {
      ++counters_.rate_limited;
      error(c, id, kRateLimited,
            "rate limited: more than " + std::to_string(static_cast<long>(rate)) +
                " requests/s from this connection (web.max_requests_per_s); estop, hold and stop "
                "are never refused");
      return;
    }
    c.tokens -= 1.0;
  }
  handle(c, id, method, params, now);
}

void Hub::handle(Client& c, const json& id, const std::string& method, const json& params,
                 Clock::time_point now) {
  if (method == "web.login") {
    const auto t = params.find("token");
    if (t == params.end() || !t->is_string()) {
      error(c, id, kInvalidParams, "web.login needs {\"token\": STRING}");
      return;
    }
    const std::string& given = t->get_ref<const std::string&>();
    const ResolvedToken* match = nullptr;
    for (const auto& tok : opt_.tokens) {
      if (equal_constant_time(given, tok.value)) match = &tok;
    }
    if (match == nullptr) {
      ++counters_.login_failures;
      ++c.failed_logins;
      log("client " + std::to_string(c.id) + " (" + c.remote + "): login with an invalid token");
      error(c, id, kLogin, "invalid token");
      if (c.failed_logins >= kMaxFailedLogins) c.port->close("too many invalid tokens");
      return;
    }
    c.role = match->role;
    c.name = match->name;
    log("client " + std::to_string(c.id) + " (" + c.remote + ") logged in as '" + c.name +
        "' (" + to_string(c.role) + ")");
    reply(c, id, {{"name", c.name}, {"role", to_string(c.role)}});
    return;
  }
  if (method == "web.info") {
    json sig = json::array();
    for (const auto& s : scope_signals()) {
      sig.push_back({{"name", s.name}, {"unit", s.unit}, {"meaning", s.meaning}});
    }
    reply(c, id,
          {{"version", kVersion},
           {"client", c.id},
           {"role", to_string(c.role)},
           {"name", c.name},
           {"login_required", c.role == WebRole::kNone},
           {"daemon", {{"connected", daemon_.connected()}, {"status", have_status_}}},
           {"status_rate_hz", opt_.status_rate_hz},
           {"jog_deadman_ms", opt_.jog_deadman_ms},
           {"viewer_may_stop", opt_.viewer_may_stop},
           {"max_message_bytes", opt_.max_message_bytes},
           {"max_requests_per_s", opt_.max_requests_per_s},
           {"signals", sig},
           {"counters",
            {{"samples_in", counters_.samples_in},
             {"sample_gaps", counters_.sample_gaps},
             {"daemon_dropped", counters_.daemon_dropped},
             {"client_dropped", c.port->dropped_samples()},
             {"deadman_stops", counters_.deadman_stops}}}});
    return;
  }
  if (c.role == WebRole::kNone) {
    error(c, id, kLogin, "login required: call web.login with a token first");
    return;
  }
  if (method == "web.deadman") {
    reply(c, id, c.jog_active);
    return;
  }
  if (method == "subscribe") {
    try {
      reply(c, id, subscribe(c, params));
    } catch (const std::invalid_argument& e) {
      error(c, id, kInvalidParams, e.what());
    }
    return;
  }
  if (method == "unsubscribe") {
    const std::string topic = params.value("topic", "");
    if (topic == "status") c.status_sub = false;
    else if (topic == "telemetry") c.scope_sub = false;
    else if (topic == "events") c.events_sub = false;
    else {
      error(c, id, kInvalidParams, "unsubscribe needs topic \"status\", \"telemetry\" or \"events\"");
      return;
    }
    reply(c, id, {{"topic", topic}});
    return;
  }
  if (method.rfind("web.", 0) == 0 || method.empty()) {
    error(c, id, kNoMethod, "no such method '" + method + "'");
    return;
  }
  if (params.contains("cmd") || params.contains("id")) {
    error(c, id, kInvalidParams, "invalid params: 'cmd' and 'id' are not command arguments");
    return;
  }
  if (!allowed(c, method, params)) {
    ++counters_.forbidden;
    error(c, id, kForbidden,
          "forbidden: the " + std::string(to_string(c.role)) + " role cannot send '" + method +
              "' (operator only)");
    return;
  }
  forward(c, id, method, params, now);
}

bool Hub::allowed(const Client& c, const std::string& method, const json& params) const {
  if (c.role == WebRole::kOperator) return true;
  if (c.role != WebRole::kViewer) return false;
  if (is_safety(method)) return opt_.viewer_may_stop;
  return viewer_may(method, params);
}

void Hub::forward(Client& c, const json& id, const std::string& method, const json& params,
                  Clock::time_point now) {
  json req = params;
  req["cmd"] = method;
  const ClientId cid = c.id;
  auto done = [this, cid, id, method](const json& rep) {
    Client* cl = find(cid);
    if (cl == nullptr) return;  // the browser left meanwhile
    if (rep.value("ok", false)) {
      reply(*cl, id, rep.contains("result") ? rep["result"] : json(nullptr));
      return;
    }
    const std::string msg = rep.value("error", std::string("refused"));
    if (method == "jog") cl->jog_active = false;
    error(*cl, id, rep.value("unreachable", false) ? kUnreachable : kRefused, msg);
  };
  if (method == "jog") {
    c.jog_active = true;
    c.jog_started = now;
    daemon_.client_request(cid, std::move(req), done);
    return;
  }
  if (method == "stop") c.jog_active = false;  // released: nothing left for the dead-man
  daemon_.request(is_safety(method) ? DaemonPort::Channel::kSafety : DaemonPort::Channel::kCommand,
                  std::move(req), done);
}

json Hub::subscribe(Client& c, const json& params) {
  std::string topic = params.value("topic", "");
  if (topic.empty()) topic = params.contains("signals") ? "telemetry" : "status";
  if (topic == "status") {
    std::vector<std::string> fields;
    if (params.contains("fields")) {
      const json& f = params["fields"];
      if (!f.is_array()) throw std::invalid_argument("fields must be a list of status field names");
      for (const auto& x : f) {
        if (!x.is_string() || x.get<std::string>().empty()) {
          throw std::invalid_argument("fields must be a list of status field names");
        }
        fields.push_back(x.get<std::string>());
      }
    }
    c.status_sub = true;
    c.fields = std::move(fields);
    c.sent = pick_fields(c);
    return {{"topic", "status"}, {"status", c.sent}, {"rate_hz", opt_.status_rate_hz},
            {"daemon_connected", daemon_.connected()}};
  }
  if (topic == "telemetry") {
    std::vector<std::string> names;
    if (params.contains("signals")) {
      const json& s = params["signals"];
      if (!s.is_array()) throw std::invalid_argument("signals must be a list of signal names");
      for (const auto& x : s) {
        if (!x.is_string() || signal_index(x.get<std::string>()) < 0) {
          throw std::invalid_argument("unknown signal " + x.dump() + " (web.info lists them)");
        }
        names.push_back(x.get<std::string>());
      }
    } else {
      for (const auto& s : scope_signals()) names.emplace_back(s.name);
    }
    std::uint32_t dec = 1;
    if (params.contains("decimation")) {
      const json& d = params["decimation"];
      if (!d.is_number_integer() || d.get<long>() < 1 || d.get<long>() > 10000) {
        throw std::invalid_argument("decimation must be an integer 1..10000");
      }
      dec = static_cast<std::uint32_t>(d.get<long>());
    }
    c.signals = names;
    c.decimation = dec;
    c.scope_sub = true;
    return {{"topic", "telemetry"}, {"signals", names}, {"decimation", dec}};
  }
  if (topic == "events") {
    c.events_sub = true;
    json recent = json::array();
    for (const auto& e : events_) recent.push_back(e);
    return {{"topic", "events"}, {"events", recent}};
  }
  throw std::invalid_argument("subscribe: topic must be \"status\", \"telemetry\" or \"events\"");
}

json Hub::pick_fields(const Client& c) const {
  if (c.fields.empty()) return status_;
  json out = json::object();
  for (const auto& f : c.fields) out[f] = lookup(status_, f);
  return out;
}

void Hub::on_status(const json& st, Clock::time_point now) {
  status_ = st;
  have_status_ = true;
  const bool jogging = st.value("jogging", false);
  for (auto& [id, c] : clients_) {
    // A jog that ended on its own (distance reached, refused, stopped elsewhere).
    if (c.jog_active && !jogging && seconds(now - c.jog_started) > kJogStatusLagS) c.jog_active = false;
    if (!c.status_sub) continue;
    json now_vals = pick_fields(c);
    json diff = json::object();
    for (auto it = now_vals.begin(); it != now_vals.end(); ++it) {
      auto old = c.sent.find(it.key());
      if (old == c.sent.end() || *old != it.value()) diff[it.key()] = it.value();
    }
    if (diff.empty()) continue;
    c.sent = std::move(now_vals);
    json msg{{"jsonrpc", "2.0"},
             {"method", "notify_status_update"},
             {"params", {diff, seconds(now - started_)}}};
    c.port->send(std::make_shared<const std::string>(msg.dump(-1, ' ', false, json::error_handler_t::replace)), 0);
  }
}

void Hub::publish_event(json ev) {
  events_.push_back(ev);
  while (events_.size() > opt_.max_events) events_.pop_front();
  std::shared_ptr<const std::string> text;
  for (auto& [id, c] : clients_) {
    if (!c.events_sub) continue;
    if (!text) {
      json msg{{"jsonrpc", "2.0"}, {"method", "notify_event"}, {"params", ev}};
      text = std::make_shared<const std::string>(msg.dump(-1, ' ', false, json::error_handler_t::replace));
    }
    c.port->send(text, 0);
  }
}

void Hub::on_daemon_line(const json& line) {
  if (!line.is_object()) return;
  const std::string ev = line.value("event", "");
  if (ev == "telemetry") {
    ScopeBlock b;
    const std::uint64_t gaps0 = scope_.gaps();
    scope_.decode(line, b);
    counters_.samples_in += b.size();
    counters_.sample_gaps += scope_.gaps() - gaps0;
    counters_.daemon_dropped = b.daemon_dropped;
    if (b.size() == 0) return;
    for (auto& [id, c] : clients_) {
      if (!c.scope_sub) continue;
      std::vector<int> idx;
      for (const auto& n : c.signals) idx.push_back(signal_index(n));
      std::size_t n = 0;
      std::string msg = scope_message(b, idx, c.decimation, c.port->dropped_samples(), &n);
      if (n == 0) continue;
      c.port->send(std::make_shared<const std::string>(std::move(msg)), n);
    }
    return;
  }
  if (ev.empty()) return;  // a reply on the stream connection (subscribe), not an event
  json e = line;
  e["source"] = "contourd";
  publish_event(std::move(e));
}

void Hub::on_daemon_state(bool up, const std::string& why) {
  publish_event({{"event", "web"}, {"text", up ? "connected to contourd" : "contourd connection lost: " + why}});
  if (!up) {
    have_status_ = false;
    poll_pending_ = false;
    status_ = json{{"state", "UNREACHABLE"}, {"daemon_error", why}};
    on_status(status_, Clock::now());
    have_status_ = false;
  }
}

void Hub::stop_jog(Client& c, const std::string& why) {
  c.jog_active = false;
  const bool jogging = status_.value("jogging", false);
  const bool young = seconds(Clock::now() - c.jog_started) <= kJogStatusLagS;
  const std::string text = "jog dead-man: client " + std::to_string(c.id) + " (" + c.remote +
                           ") " + why + "; stopping its jog";
  ++counters_.deadman_stops;
  log(text);
  publish_event({{"event", "web"}, {"text", text}});
  // Its own daemon connection goes first: a daemon-side dead-man (continuous jog) acts on it.
  daemon_.close_client(c.id);
  if (jogging || young) {
    daemon_.request(DaemonPort::Channel::kSafety, {{"cmd", "stop"}}, [this](const json& rep) {
      if (!rep.value("ok", false)) log("jog dead-man: stop: " + rep.value("error", std::string("?")));
    });
  }
}

void Hub::tick(Clock::time_point now) {
  // Status polling: one request in flight at most.
  if (!poll_pending_ && now >= next_poll_) {
    poll_pending_ = true;
    ++counters_.status_polls;
    next_poll_ = now + std::chrono::duration_cast<Clock::duration>(
                           std::chrono::duration<double>(1.0 / opt_.status_rate_hz));
    daemon_.request(DaemonPort::Channel::kPoll, {{"cmd", "status"}}, [this](const json& rep) {
      poll_pending_ = false;
      if (rep.value("ok", false) && rep.contains("result") && rep["result"].is_object()) {
        on_status(rep["result"], Clock::now());
      }
    });
  }
  // Jog dead-man: silence from a jogging client.
  const auto limit = std::chrono::milliseconds(opt_.jog_deadman_ms);
  for (auto& [id, c] : clients_) {
    if (c.jog_active && now - c.last_seen > limit) {
      stop_jog(c, "sent nothing for " + std::to_string(opt_.jog_deadman_ms) + " ms");
    }
  }
}

}  // namespace contour::web
