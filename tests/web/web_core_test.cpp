// contour-web's core without sockets: the JSON-RPC hub (methods, errors, roles, rate limit,
// status diffs, scope fan-out, jog dead-man), the scope decoder, the send queue, the Host/Origin
// and static-path checks, and the `web:` config section.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>
#include <nlohmann/json.hpp>

#include "config/config.hpp"
#include "tests/support/sim_config.hpp"
#include "tools/contour-web/hub.hpp"
#include "tools/contour-web/scope.hpp"
#include "tools/contour-web/security.hpp"
#include "tools/contour-web/send_queue.hpp"

using namespace contour::web;
using contour::config::WebRole;
using nlohmann::json;

namespace {

struct FakeDaemon : DaemonPort {
  struct Req {
    Channel ch;
    ClientId client = 0;  // 0: a shared channel
    json req;
    Reply cb;
  };
  std::vector<Req> reqs;
  std::vector<ClientId> closed;
  bool up = true;
  void request(Channel ch, json req, Reply cb) override { reqs.push_back({ch, 0, std::move(req), std::move(cb)}); }
  void client_request(ClientId c, json req, Reply cb) override {
    reqs.push_back({Channel::kCommand, c, std::move(req), std::move(cb)});
  }
  void close_client(ClientId c) override { closed.push_back(c); }
  bool connected() const override { return up; }
  std::vector<Req> take(const std::string& cmd) {
    std::vector<Req> out, rest;
    for (auto& r : reqs) (r.req.value("cmd", "") == cmd ? out : rest).push_back(std::move(r));
    reqs = std::move(rest);
    return out;
  }
};

struct FakeClient : ClientPort {
  std::vector<json> got;
  std::vector<std::size_t> samples;
  std::string closed;
  void send(std::shared_ptr<const std::string> text, std::size_t n) override {
    got.push_back(json::parse(*text));
    samples.push_back(n);
  }
  void close(const std::string& reason) override { closed = reason; }
  std::uint64_t dropped_samples() const override { return 0; }
  json last() const { return got.empty() ? json() : got.back(); }
};

struct Rig {
  FakeDaemon daemon;
  HubOptions opt;
  std::unique_ptr<Hub> hub;
  Clock::time_point now = Clock::now();
  explicit Rig(HubOptions o = {}) : opt(std::move(o)) { hub = std::make_unique<Hub>(opt, daemon); }
  std::pair<ClientId, std::shared_ptr<FakeClient>> client() {
    auto c = std::make_shared<FakeClient>();
    return {hub->connect(c, "test", now), c};
  }
  void send(ClientId id, const json& msg) { hub->on_message(id, msg.dump(), now); }
  void call(ClientId id, int rid, const std::string& method, json params = json::object()) {
    send(id, {{"jsonrpc", "2.0"}, {"id", rid}, {"method", method}, {"params", params}});
  }
};

json status_with(double x, bool jogging = false) {
  return {{"state", "READY"}, {"act_mm", {x, 0.0, 0.0}}, {"jogging", jogging},
          {"timing", {{"lateness_max_us", 12.5}}}};
}

TEST(Hub, ProtocolErrorsAreJsonRpcErrors) {
  Rig r;
  auto [id, c] = r.client();
  r.hub->on_message(id, "{not json", r.now);
  EXPECT_EQ(c->last()["error"]["code"], -32700);
  r.hub->on_message(id, "[1,2]", r.now);
  EXPECT_EQ(c->last()["error"]["code"], -32600);
  r.send(id, {{"jsonrpc", "2.0"}, {"id", 1}});
  EXPECT_EQ(c->last()["error"]["code"], -32600);
  r.send(id, {{"jsonrpc", "2.0"}, {"id", 2}, {"method", "status"}, {"params", {1, 2}}});
  EXPECT_EQ(c->last()["error"]["code"], -32602);
  r.call(id, 3, "web.nothing");
  EXPECT_EQ(c->last()["error"]["code"], -32601);
  r.call(id, 4, "run", {{"cmd", "estop"}});
  EXPECT_EQ(c->last()["error"]["code"], -32602) << "a 'cmd' inside params must not pick the command";
  EXPECT_TRUE(r.daemon.reqs.empty());
}

TEST(Hub, EverySocketCommandIsAMethodWithTheSameArguments) {
  Rig r;
  auto [id, c] = r.client();
  r.call(id, 7, "jog", {{"axis", "X"}, {"velocity_mm_min", 500}, {"distance_mm", 2}});
  auto jog = r.daemon.take("jog");
  ASSERT_EQ(jog.size(), 1u);
  EXPECT_EQ(jog[0].client, id) << "jog goes over the client's own connection";
  EXPECT_EQ(jog[0].req, json({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 500}, {"distance_mm", 2}}));
  jog[0].cb({{"ok", true}, {"result", {{"axis", "X"}, {"target_mm", 2.0}}}});
  EXPECT_EQ(c->last(), json({{"jsonrpc", "2.0"}, {"id", 7}, {"result", {{"axis", "X"}, {"target_mm", 2.0}}}}));
  r.call(id, 8, "estop");
  auto es = r.daemon.take("estop");
  ASSERT_EQ(es.size(), 1u);
  EXPECT_EQ(es[0].ch, DaemonPort::Channel::kSafety);
  r.call(id, 9, "gains", {{"set", {{"kp", -1}}}});
  auto g = r.daemon.take("gains");
  ASSERT_EQ(g.size(), 1u);
  EXPECT_EQ(g[0].ch, DaemonPort::Channel::kCommand);
  g[0].cb({{"ok", false}, {"error", "gain 'kp' out of range"}});
  EXPECT_EQ(c->last()["error"], json({{"code", -32000}, {"message", "gain 'kp' out of range"}}));
  r.call(id, 10, "status");
  r.daemon.take("status")[0].cb({{"ok", false}, {"unreachable", true}, {"error", "contourd unreachable: x"}});
  EXPECT_EQ(c->last()["error"]["code"], -32010);
}

TEST(Hub, RolesAndLogin) {
  HubOptions o;
  o.anonymous_role = WebRole::kNone;
  o.tokens = {{"shop", WebRole::kOperator, "operator-token-0123456789"},
              {"office", WebRole::kViewer, "viewer-token-0123456789"}};
  Rig r(o);
  auto [id, c] = r.client();
  r.call(id, 1, "status");
  EXPECT_EQ(c->last()["error"]["code"], -32001);
  r.call(id, 2, "web.login", {{"token", "viewer-token-0123456789"}});
  EXPECT_EQ(c->last()["result"]["role"], "viewer");
  for (const auto& [m, p] : std::vector<std::pair<std::string, json>>{
           {"run", json::object()}, {"estop", json::object()}, {"gains", {{"set", {{"cp", 1}}}}},
           {"override", {{"percent", 50}}}, {"shutdown", json::object()}, {"force", {{"enable", true}}}}) {
    r.call(id, 3, m, p);
    EXPECT_EQ(c->last()["error"]["code"], -32003) << m;
  }
  EXPECT_TRUE(r.daemon.reqs.empty()) << "nothing reached the daemon";
  r.call(id, 4, "gains");
  r.call(id, 5, "status");
  EXPECT_EQ(r.daemon.reqs.size(), 2u);
  // Wrong tokens: refused, and the fifth closes the connection.
  auto [id2, c2] = r.client();
  for (int i = 0; i < 5; ++i) r.call(id2, 10 + i, "web.login", {{"token", "operator-token-012345678X"}});
  EXPECT_EQ(c2->last()["error"]["message"], "invalid token");
  EXPECT_FALSE(c2->closed.empty());
  auto [id3, c3] = r.client();
  r.call(id3, 1, "web.login", {{"token", "operator-token-0123456789"}});
  EXPECT_EQ(c3->last()["result"]["role"], "operator");
  r.call(id3, 2, "run");
  EXPECT_EQ(r.daemon.take("run").size(), 1u);
}

TEST(Hub, ViewerMayStopOnlyWhenConfigured) {
  HubOptions o;
  o.anonymous_role = WebRole::kViewer;
  o.viewer_may_stop = true;
  Rig r(o);
  auto [id, c] = r.client();
  r.call(id, 1, "estop");
  r.call(id, 2, "hold");
  r.call(id, 3, "resume");
  EXPECT_EQ(r.daemon.take("estop").size(), 1u);
  EXPECT_EQ(r.daemon.take("hold").size(), 1u);
  EXPECT_EQ(c->last()["error"]["code"], -32003);
}

TEST(Hub, RateLimitNeverRefusesTheSafetyCommands) {
  HubOptions o;
  o.max_requests_per_s = 20;
  Rig r(o);
  auto [id, c] = r.client();
  int limited = 0;
  for (int i = 0; i < 60; ++i) {
    r.call(id, i, "status");
    if (c->last().contains("error") && c->last()["error"]["code"] == -32005) ++limited;
  }
  EXPECT_EQ(limited, 40);  // 20 burst tokens, no time passes
  for (int i = 0; i < 10; ++i) r.call(id, 100 + i, "estop");
  EXPECT_EQ(r.daemon.take("estop").size(), 10u);
  r.daemon.take("status");
  r.now += std::chrono::seconds(1);
  r.call(id, 200, "status");
  EXPECT_EQ(r.daemon.take("status").size(), 1u) << "the bucket refills";
}

TEST(Hub, StatusSubscriptionSendsASnapshotThenOnlyChangedFields) {
  Rig r;
  auto [id, c] = r.client();
  r.hub->tick(r.now);
  r.daemon.take("status")[0].cb({{"ok", true}, {"result", status_with(1.0)}});
  r.call(id, 1, "subscribe", {{"fields", {"state", "act_mm", "timing.lateness_max_us"}}});
  const json snap = c->last()["result"]["status"];
  EXPECT_EQ(snap, json({{"state", "READY"}, {"act_mm", {1.0, 0.0, 0.0}}, {"timing.lateness_max_us", 12.5}}));
  const std::size_t n0 = c->got.size();
  r.now += std::chrono::milliseconds(150);
  r.hub->tick(r.now);
  r.daemon.take("status")[0].cb({{"ok", true}, {"result", status_with(1.0)}});
  EXPECT_EQ(c->got.size(), n0) << "nothing changed: no notification";
  r.now += std::chrono::milliseconds(150);
  r.hub->tick(r.now);
  r.daemon.take("status")[0].cb({{"ok", true}, {"result", status_with(2.0)}});
  ASSERT_EQ(c->got.size(), n0 + 1);
  EXPECT_EQ(c->last()["method"], "notify_status_update");
  EXPECT_EQ(c->last()["params"][0], json({{"act_mm", {2.0, 0.0, 0.0}}}));
  // The poll runs at status_rate_hz (10 Hz): never early, never two in flight.
  r.now += std::chrono::milliseconds(20);
  r.hub->tick(r.now);
  EXPECT_TRUE(r.daemon.take("status").empty()) << "20 ms after the last poll";
  r.now += std::chrono::milliseconds(150);
  r.hub->tick(r.now);
  r.now += std::chrono::milliseconds(150);
  r.hub->tick(r.now);
  EXPECT_EQ(r.daemon.take("status").size(), 1u) << "one poll in flight at most";
}

json batch(std::uint64_t first, int n, std::uint64_t job = 3) {
  json samples = json::array();
  for (int i = 0; i < n; ++i) {
    const std::uint64_t cyc = first + static_cast<std::uint64_t>(i);
    const double x = 0.01 * static_cast<double>(cyc);  // 10 mm/s = 600 mm/min
    samples.push_back({{"cycle", cyc}, {"t_s", 1e-3 * static_cast<double>(cyc)}, {"job", job}, {"line", 4},
                       {"in_program", true}, {"ref_mm", {x, 0, 0}}, {"act_mm", {x - 0.002, 0.001, 0}},
                       {"eps_um", {0, 1, 0}}, {"model_error_um", 1.0}, {"true_error_um", 1.5},
                       {"override", 1.0}, {"force_n", 0}, {"spindle_rpm", 0}});
  }
  return {{"event", "telemetry"}, {"count", n}, {"dropped", 0}, {"source_dropped", 0}, {"samples", samples}};
}

TEST(Hub, ScopeChannelCarriesEverySampleAndDecimatesOnlyOnRequest) {
  Rig r;
  auto [a, ca] = r.client();
  auto [b, cb] = r.client();
  r.call(a, 1, "subscribe", {{"topic", "telemetry"}, {"signals", {"true_error_um", "ferr_x_um", "path_velocity_mm_min"}}});
  r.call(b, 1, "subscribe", {{"topic", "telemetry"}, {"signals", {"true_error_um"}}, {"decimation", 10}});
  r.call(b, 2, "subscribe", {{"topic", "telemetry"}, {"signals", {"nonsense"}}});
  EXPECT_EQ(cb->last()["error"]["code"], -32602);
  r.hub->on_daemon_line(batch(1, 20));
  r.hub->on_daemon_line(batch(21, 20));
  std::vector<std::uint64_t> cyc_a, cyc_b;
  for (std::size_t i = 0; i < ca->got.size(); ++i) {
    if (ca->got[i].value("method", "") != "notify_scope") continue;
    EXPECT_GT(ca->samples[i], 0u) << "scope batches are droppable";
    const json& p = ca->got[i]["params"];
    for (const auto& x : p["cycle"]) cyc_a.push_back(x.get<std::uint64_t>());
    EXPECT_EQ(p["signals"].size(), 3u);
    EXPECT_DOUBLE_EQ(p["signals"]["ferr_x_um"][0].get<double>(), 2.0);
    EXPECT_DOUBLE_EQ(p["signals"]["true_error_um"][0].get<double>(), 1.5);
  }
  for (const auto& m : cb->got) {
    if (m.value("method", "") != "notify_scope") continue;
    for (const auto& x : m["params"]["cycle"]) cyc_b.push_back(x.get<std::uint64_t>());
  }
  ASSERT_EQ(cyc_a.size(), 40u);
  for (std::size_t i = 0; i < 40; ++i) EXPECT_EQ(cyc_a[i], i + 1);
  EXPECT_EQ(cyc_b, (std::vector<std::uint64_t>{10, 20, 30, 40}));
  // Path velocity from consecutive references: 10 mm/s.
  const json last = ca->last()["params"]["signals"]["path_velocity_mm_min"];
  EXPECT_NEAR(last.back().get<double>(), 600.0, 1e-6);
  EXPECT_EQ(r.hub->counters().samples_in, 40u);
  EXPECT_EQ(r.hub->counters().sample_gaps, 0u);
  r.hub->on_daemon_line(batch(50, 1));  // cycles 41..49 missing
  EXPECT_EQ(r.hub->counters().sample_gaps, 9u);
  EXPECT_EQ(ca->last()["params"]["gaps"], 9u);
}

TEST(Hub, JogDeadManStopsASilentOrVanishedClient) {
  Rig r;
  auto [id, c] = r.client();
  r.call(id, 1, "jog", {{"axis", "X"}, {"velocity_mm_min", 600}, {"distance_mm", 100}});
  r.daemon.take("jog")[0].cb({{"ok", true}, {"result", {{"axis", "X"}}}});
  // Keepalives within the dead-man time keep it going.
  for (int i = 0; i < 5; ++i) {
    r.now += std::chrono::milliseconds(200);
    r.send(id, {{"jsonrpc", "2.0"}, {"method", "web.deadman"}});
    r.hub->tick(r.now);
  }
  EXPECT_TRUE(r.daemon.take("stop").empty());
  r.daemon.take("status");
  r.now += std::chrono::milliseconds(600);
  r.hub->tick(r.now);
  auto stop = r.daemon.take("stop");
  ASSERT_EQ(stop.size(), 1u) << "silence for more than jog_deadman_ms stops the jog";
  EXPECT_EQ(stop[0].ch, DaemonPort::Channel::kSafety);
  EXPECT_EQ(r.daemon.closed, std::vector<ClientId>{id}) << "its own daemon connection is closed";
  EXPECT_EQ(r.hub->counters().deadman_stops, 1u);
  // A vanished client: disconnect during a jog.
  auto [id2, c2] = r.client();
  r.call(id2, 1, "jog", {{"axis", "Y"}, {"velocity_mm_min", 600}, {"distance_mm", 100}});
  r.hub->disconnect(id2, r.now);
  EXPECT_EQ(r.daemon.take("stop").size(), 1u);
  // Released (stop sent by the client): nothing left for the dead-man; a finished jog neither.
  auto [id3, c3] = r.client();
  r.call(id3, 1, "jog", {{"axis", "Y"}, {"velocity_mm_min", 600}, {"distance_mm", 1}});
  r.call(id3, 2, "stop");
  EXPECT_EQ(r.daemon.take("stop").size(), 1u);
  r.now += std::chrono::seconds(2);
  r.hub->tick(r.now);
  r.hub->disconnect(id3, r.now);
  EXPECT_TRUE(r.daemon.take("stop").empty());
}

TEST(SendQueue, DropsOldestScopeBatchesCountedNeverReplies) {
  SendQueue q(1000);
  auto s = [](std::size_t n, char ch) { return std::make_shared<const std::string>(std::string(n, ch)); };
  q.push(s(300, 'a'), 10);  // on the wire
  q.begin_write();
  q.push(s(300, 'r'), 0);   // a reply
  q.push(s(300, 'b'), 10);
  q.push(s(300, 'c'), 10);  // 1200 > 1000: 'b' goes (not 'a', being written; not the reply)
  EXPECT_EQ(q.dropped_samples(), 10u);
  EXPECT_EQ(q.bytes(), 900u);
  q.end_write();
  EXPECT_EQ((*q.front().text)[0], 'r');
  for (int i = 0; i < 10; ++i) q.push(s(300, 'x'), 0);
  EXPECT_TRUE(q.overflow()) << "replies alone beyond twice the limit";
}

TEST(Security, HostAndOriginChecks) {
  OriginPolicy p{{"hmi.example.com"}, {"https://hmi.example.com"}};
  EXPECT_TRUE(host_allowed("127.0.0.1:8080", p));
  EXPECT_TRUE(host_allowed("localhost:8080", p));
  EXPECT_TRUE(host_allowed("[::1]:8080", p));
  EXPECT_TRUE(host_allowed("192.0.2.7:8080", p));  // an IP literal: typed by a user
  EXPECT_TRUE(host_allowed("HMI.example.com", p));
  EXPECT_FALSE(host_allowed("evil.example:8080", p));  // DNS rebinding
  EXPECT_FALSE(host_allowed("", p));
  EXPECT_TRUE(origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080", p));
  EXPECT_TRUE(origin_allowed("", "127.0.0.1:8080", p));  // not a browser page
  EXPECT_TRUE(origin_allowed("https://hmi.example.com", "hmi.example.com", p));
  EXPECT_FALSE(origin_allowed("http://evil.example", "127.0.0.1:8080", p));
  EXPECT_FALSE(origin_allowed("http://localhost:8080", "127.0.0.1:8080", p));
  EXPECT_FALSE(origin_allowed("null", "127.0.0.1:8080", p));
  EXPECT_FALSE(origin_allowed("http://evil.example:8080", "evil.example:8080", p));
}

TEST(Security, StaticPaths) {
  EXPECT_EQ(static_path("/"), "index.html");
  EXPECT_EQ(static_path("/app.js?v=1"), "app.js");
  EXPECT_EQ(static_path("/vendor/uplot/uPlot.min.css"), "vendor/uplot/uPlot.min.css");
  EXPECT_EQ(static_path("/../etc/passwd"), "");
  EXPECT_EQ(static_path("/vendor/../../x"), "");
  EXPECT_EQ(static_path("/.git/config"), "");
  EXPECT_EQ(static_path("/a//b"), "");
  EXPECT_EQ(static_path("/%2e%2e/x"), "");
  EXPECT_EQ(static_path("relative"), "");
}

// config/sim.yaml with a `web:` section appended.
contour::config::Config load(const std::string& web) {
  return contour::config::load_config_string(contour::test::sim_yaml() + "\nweb:\n" + web, "web.yaml");
}
std::string errors_of(const std::string& web) {
  try {
    load(web);
  } catch (const contour::config::ConfigError& e) {
    std::string all;
    for (const auto& m : e.errors()) all += m + "\n";
    return all;
  }
  return "";
}

TEST(WebConfig, ValidatesAndNeverEchoesATokenValue) {
  const auto c = load("  listen: 127.0.0.1:9090\n  status_rate_hz: 20\n");
  EXPECT_EQ(c.web.port, 9090);
  EXPECT_EQ(c.web.anonymous_role, WebRole::kOperator);
  EXPECT_DOUBLE_EQ(c.web.status_rate_hz, 20.0);
  EXPECT_NE(errors_of("  listen: 0.0.0.0:8080\n").find("needs at least one token"), std::string::npos);
  EXPECT_NE(errors_of("  listen: 0.0.0.0:8080\n  tokens: [{name: a, role: operator, token: abcdefghijklmnopq}]\n"
                      "  anonymous_role: viewer\n").find("anonymous_role must be none"), std::string::npos);
  EXPECT_EQ(errors_of("  listen: 0.0.0.0:8080\n  tokens: [{name: a, role: operator, token: abcdefghijklmnopq}]\n"), "");
  const std::string shortie = errors_of("  tokens: [{name: a, role: operator, token: secret123}]\n");
  EXPECT_NE(shortie.find("too short"), std::string::npos);
  EXPECT_EQ(shortie.find("secret123"), std::string::npos) << shortie;
  EXPECT_NE(errors_of("  listen: 8080\n").find("HOST:PORT"), std::string::npos);
  EXPECT_NE(errors_of("  listen: 127.0.0.1:99999\n").find("0..65535"), std::string::npos);
  EXPECT_NE(errors_of("  allowed_origins: [hmi.example.com]\n").find("http"), std::string::npos);
  EXPECT_NE(errors_of("  bogus: 1\n").find("unknown key"), std::string::npos);
  EXPECT_NE(errors_of("  tokens: [{name: a, role: admin, token: abcdefghijklmnopq}]\n").find("role"), std::string::npos);
  const auto t = load("  tokens: [{name: a, role: viewer, token_file: /etc/contourd/web.token}]\n");
  EXPECT_EQ(t.web.anonymous_role, WebRole::kNone) << "tokens configured: anonymous clients need one";
}

}  // namespace
