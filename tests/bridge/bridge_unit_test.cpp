// contour-bridge, the parts without a broker or daemon: the `mqtt:`/`mtconnect:` config
// sections, the bounded queue's drop policy, the payloads and the daemon-event classifier (fed
// with the daemon's own event texts, daemon/event_log.cpp describe()), the SHDR lines,
// Devices.xml and the credentials file.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include "config/config.hpp"
#include "daemon/event_log.hpp"
#include "daemon/servo_loop.hpp"
#include "tests/support/config_errors.hpp"
#include "tests/support/sim_config.hpp"
#include "tools/contour-bridge/bridge.hpp"
#include "tools/contour-bridge/credentials.hpp"
#include "tools/contour-bridge/devices_xml.hpp"
#include "tools/contour-bridge/out_queue.hpp"
#include "tools/contour-bridge/payloads.hpp"
#include "tools/contour-bridge/shdr.hpp"

namespace {

using nlohmann::json;
using namespace contour::bridge;
using contour::test::any_contains;
using contour::test::config_errors;

// config/sim.yaml, its PLC program paths absolute (tests/support/sim_config.hpp).
std::string sim_yaml() { return contour::test::sim_yaml(); }

contour::config::Config load(const std::string& extra) {
  return contour::config::load_config_string(sim_yaml() + extra, "test.yaml");
}

// ---- config -------------------------------------------------------------------------------

TEST(BridgeConfig, AbsentSectionsAreNotPresent) {
  const auto c = load("");
  EXPECT_FALSE(c.mqtt.present);
  EXPECT_FALSE(c.mtconnect.present);
}

TEST(BridgeConfig, DefaultsAndEveryKey) {
  auto c = load("mqtt:\n  machine_id: m-7\n");
  EXPECT_TRUE(c.mqtt.present);
  EXPECT_EQ(c.mqtt.host, "localhost");
  EXPECT_EQ(c.mqtt.port, 1883);
  EXPECT_EQ(c.mqtt.client_id, "contour-bridge-m-7");
  EXPECT_EQ(c.mqtt.topic_prefix, "contourd");
  EXPECT_FALSE(c.mqtt.commands.enabled);
  EXPECT_EQ(c.mqtt.commands.allow, (std::vector<std::string>{"hold", "resume", "stop"}));
  EXPECT_EQ(c.mqtt.queue_size, 10000);
  c = load(R"(mqtt:
  host: broker.shop
  port: 8884
  machine_id: lathe_3
  topic_prefix: plant1/contourd
  client_id: cb-lathe3
  keepalive_s: 20
  position_rate_hz: 25
  position_deadband_um: 2.5
  state_rate_hz: 4
  queue_size: 500
  max_inflight: 10
  reconnect_min_s: 0.2
  reconnect_max_s: 5
  retain_jobs: 3
  status_interval_s: 2
  credentials_file: /etc/contourd/mqtt.cred
  tls: {ca_file: /etc/ssl/ca.pem, cert_file: c.pem, key_file: k.pem, version: tlsv1.3}
  commands: {enabled: true, allow: [hold, stop, enable], max_per_s: 2}
mtconnect:
  bind: 0.0.0.0
  port: 7879
  device_name: lathe3
  device_uuid: uuid-1
  manufacturer: ACME
  model: L1
  serial_number: "42"
  heartbeat_ms: 5000
  sample_rate_hz: 5
  max_clients: 2
  devices_xml: /run/contour-bridge/Devices.xml
)");
  EXPECT_EQ(c.mqtt.port, 8884);
  EXPECT_EQ(c.mqtt.topic_prefix, "plant1/contourd");
  EXPECT_TRUE(c.mqtt.tls.enabled);
  EXPECT_EQ(c.mqtt.tls.version, "tlsv1.3");
  EXPECT_EQ(c.mqtt.commands.allow, (std::vector<std::string>{"hold", "stop", "enable"}));
  EXPECT_DOUBLE_EQ(c.mqtt.commands.max_per_s, 2.0);
  EXPECT_EQ(c.mtconnect.port, 7879);
  EXPECT_EQ(c.mtconnect.max_clients, 2);
  // TLS changes the default port.
  c = load("mqtt:\n  machine_id: m\n  tls: {ca_file: /x.pem}\n");
  EXPECT_EQ(c.mqtt.port, 8883);
  c = load("mtconnect: {}\n");
  EXPECT_EQ(c.mtconnect.port, 7878);
  EXPECT_EQ(c.mtconnect.bind, "127.0.0.1");
  EXPECT_EQ(c.mtconnect.heartbeat_ms, 10000);
}

TEST(BridgeConfig, ErrorsNameTheKeyAndLine) {
  const std::string base = sim_yaml();
  // `mqtt:` is the line after sim.yaml's last; its map (where a missing key is reported) the next.
  const int map_line = static_cast<int>(std::count(base.begin(), base.end(), '\n')) + 2;
  auto e = config_errors(base + "mqtt:\n  host: x\n");
  EXPECT_TRUE(any_contains(e, "test.yaml:" + std::to_string(map_line) + ":3: mqtt.machine_id"))
      << (e.empty() ? std::string("no error") : e[0]);
  EXPECT_TRUE(any_contains(e, "mqtt.machine_id: required key is missing"));
  e = config_errors(base + "mqtt:\n  machine_id: a/b\n");
  EXPECT_TRUE(any_contains(e, "mqtt.machine_id: 'a/b' must be"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  colour: blue\n");
  EXPECT_TRUE(any_contains(e, "mqtt.colour: unknown key"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  port: 70000\n");
  EXPECT_TRUE(any_contains(e, "mqtt.port: value 70000 out of range"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  topic_prefix: a/#\n");
  EXPECT_TRUE(any_contains(e, "mqtt.topic_prefix"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  reconnect_min_s: 5\n  reconnect_max_s: 1\n");
  EXPECT_TRUE(any_contains(e, "mqtt.reconnect_max_s: must be at least reconnect_min_s"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  commands: {allow: [hold, load]}\n");
  EXPECT_TRUE(any_contains(e, "mqtt.commands.allow[1]: 'load' cannot be allowed over MQTT"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  commands: {allow: [hold, hold]}\n");
  EXPECT_TRUE(any_contains(e, "mqtt.commands.allow[1]: 'hold' is listed twice"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  tls: {ca_file: a, cert_file: c}\n");
  EXPECT_TRUE(any_contains(e, "mqtt.tls.cert_file: client certificates need both"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  tls: {insecure: true}\n");
  EXPECT_TRUE(any_contains(e, "mqtt.tls.ca_file: TLS needs ca_file or ca_path"));
  e = config_errors(base + "mqtt:\n  machine_id: m\n  tls: {ca_file: a, version: sslv3}\n");
  EXPECT_TRUE(any_contains(e, "mqtt.tls.version: 'sslv3' is not one of"));
  e = config_errors(base + "mtconnect:\n  port: 0\n");
  EXPECT_TRUE(any_contains(e, "mtconnect.port: value 0 out of range"));
  e = config_errors(base + "mtconnect:\n  manufacturer: \"<b>\"\n");
  EXPECT_TRUE(any_contains(e, "mtconnect.manufacturer: must be"));
  e = config_errors(base + "mtconnect:\n  heartbeat: 5\n");
  EXPECT_TRUE(any_contains(e, "mtconnect.heartbeat: unknown key"));
}

// ---- the bounded queue --------------------------------------------------------------------

OutMessage msg(MsgClass c, const std::string& payload, const std::string& topic = "t") {
  return OutMessage{topic, payload, c == MsgClass::kPosition ? 0 : 1, false, c};
}

std::vector<std::string> drain(OutQueue& q) {
  std::vector<std::string> v;
  while (!q.empty()) {
    v.push_back(q.front().payload);
    q.pop_front();
  }
  return v;
}

TEST(BridgeQueue, OldestPositionsGoFirstEventsStay) {
  OutQueue q(4);
  q.push(msg(MsgClass::kPosition, "p1"));
  q.push(msg(MsgClass::kEvent, "e1"));
  q.push(msg(MsgClass::kPosition, "p2"));
  q.push(msg(MsgClass::kEvent, "e2"));
  q.push(msg(MsgClass::kEvent, "e3"));  // full: p1 goes
  q.push(msg(MsgClass::kJob, "j1"));    // full: p2 goes
  EXPECT_EQ(q.size(), 4u);
  EXPECT_EQ(q.counters().dropped_positions, 2u);
  EXPECT_EQ(q.counters().dropped_events, 0u);
  q.push(msg(MsgClass::kPosition, "p3"));  // no older sample to drop: this one is dropped
  EXPECT_EQ(q.counters().dropped_positions, 3u);
  EXPECT_EQ(drain(q), (std::vector<std::string>{"e1", "e2", "e3", "j1"}));
}

TEST(BridgeQueue, EventsDroppedOnlyWhenNothingElseIsLeftAndCounted) {
  OutQueue q(3);
  for (const char* e : {"e1", "e2", "e3", "e4"}) q.push(msg(MsgClass::kEvent, e));
  EXPECT_EQ(q.counters().dropped_events, 1u);
  EXPECT_EQ(drain(q), (std::vector<std::string>{"e2", "e3", "e4"}));
  EXPECT_EQ(q.counters().high_water, 3u);
}

TEST(BridgeQueue, StateSnapshotsCoalesceLatestWins) {
  OutQueue q(10);
  q.push(msg(MsgClass::kState, "s1", "state"));
  q.push(msg(MsgClass::kEvent, "e1"));
  q.push(msg(MsgClass::kState, "s2", "state"));
  q.push(msg(MsgClass::kMeta, "b1", "bridge"));
  q.push(msg(MsgClass::kMeta, "b2", "bridge"));
  EXPECT_EQ(q.count(MsgClass::kState), 1u);
  EXPECT_EQ(q.counters().coalesced, 2u);
  // The newest state goes after the event that preceded it.
  EXPECT_EQ(drain(q), (std::vector<std::string>{"e1", "s2", "b2"}));
}

TEST(BridgeQueue, FullOfEventsAStateSnapshotGivesWayBeforeAnEvent) {
  OutQueue q(2);
  q.push(msg(MsgClass::kState, "s1", "state"));
  q.push(msg(MsgClass::kEvent, "e1"));
  q.push(msg(MsgClass::kEvent, "e2"));
  EXPECT_EQ(q.counters().dropped_events, 0u);
  EXPECT_EQ(drain(q), (std::vector<std::string>{"e1", "e2"}));
}

// ---- daemon events, classified from the daemon's own texts ---------------------------------

std::string daemon_text(contour::daemon::RtEvent e) { return contour::daemon::describe(e); }

TEST(BridgePayloads, ClassifiesTheDaemonsEventTexts) {
  using contour::daemon::EventKind;
  using contour::daemon::FaultCause;
  using contour::daemon::MachineState;
  contour::daemon::RtEvent e;
  e.cycle = 5262;
  e.kind = EventKind::kTransition;
  e.from = MachineState::kRunning;
  e.to = MachineState::kReady;
  auto d = classify_event(json{{"event", "log"}, {"text", daemon_text(e)}});
  EXPECT_EQ(d.kind, "transition");
  EXPECT_EQ(d.cycle, 5262u);
  EXPECT_EQ(d.from, "RUNNING");
  EXPECT_EQ(d.to, "READY");
  EXPECT_EQ(d.cause, "");
  e.to = MachineState::kFault;
  e.cause = FaultCause::kFollowingError;
  d = classify_event(json{{"event", "log"}, {"text", daemon_text(e)}});
  EXPECT_EQ(d.kind, "transition");
  EXPECT_EQ(d.to, "FAULT");
  EXPECT_EQ(d.cause, "following error");

  e.kind = EventKind::kFault;
  e.axis = 1;
  e.value = 1.5;
  e.limit = 1.0;
  d = classify_event(json{{"event", "log"}, {"text", daemon_text(e)}});
  EXPECT_EQ(d.kind, "fault");
  EXPECT_EQ(d.cause, "following error");
  e.cause = FaultCause::kEstopInput;
  e.axis = -1;
  d = classify_event(json{{"event", "log"}, {"text", daemon_text(e)}});
  EXPECT_EQ(d.kind, "fault");
  EXPECT_EQ(d.cause, "E-stop input");

  e = {};
  e.cycle = 9;
  e.kind = EventKind::kProgramDone;
  e.job = 12;
  d = classify_event(json{{"event", "log"}, {"text", daemon_text(e)}});
  EXPECT_EQ(d.kind, "program_end");
  EXPECT_EQ(d.job, 12u);
  EXPECT_TRUE(d.completed);
  e.kind = EventKind::kProgramAborted;
  d = classify_event(json{{"event", "log"}, {"text", daemon_text(e)}});
  EXPECT_EQ(d.kind, "program_end");
  EXPECT_FALSE(d.completed);

  e.kind = EventKind::kUnderrun;
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", daemon_text(e)}}).kind, "underrun");
  e.kind = EventKind::kGainsSwapped;
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", daemon_text(e)}}).kind, "gains");
  e.kind = EventKind::kCommandRefused;
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", daemon_text(e)}}).kind, "refused");
  e.kind = EventKind::kSpindleAtSpeed;
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", daemon_text(e)}}).kind, "spindle");

  // Bus messages (CANopen event thread) and socket notices.
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", "node 2: EMCY 0x2310 (current)"}}).kind,
            "emcy");
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", "node 3: heartbeat lost"}}).kind,
            "fault");
  EXPECT_EQ(classify_event(json{{"event", "socket"}, {"text", "client 4 dropped"}}).kind, "socket");
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", "E-STOP by contourctl from pid 3"}}).kind,
            "estop_request");
  EXPECT_EQ(classify_event(json{{"event", "log"}, {"text", "something else"}}).kind, "log");
}

json ready_status() {
  return json::parse(R"({"state":"READY","cause":"none","source":"hold","cycle":100,
    "ref_mm":[1.0,2.0,3.0],"act_mm":[1.0,2.0,3.0005],"cmd_mm_s":[0.0,0.0,0.0],
    "contour_error_um":0.5,"progress_mm":0.0,"line":0,"feed_override":1.0,"job":0,
    "loaded_job":0,"finished_job":0,"finished_ok":false,"jogging":false,"program_hold":false,
    "drives_enabled":true,"spindle":{"present":true,"target_rpm":0.0,"actual_rpm":0.2,
    "command_rpm":0.0,"at_speed":true},"gpio":{"estop_input":false},
    "timing":{"overruns":3}})");
}

json running_status() {
  json s = ready_status();
  s["state"] = "RUNNING";
  s["source"] = "program";
  s["job"] = 4;
  s["loaded_job"] = 4;
  s["line"] = 7;
  s["cmd_mm_s"] = {30.0, 40.0, 0.0};
  s["program"] = {{"job", 4}, {"name", "table2.ngc"}, {"motion_blocks", 20},
                  {"length_mm", 157.6}, {"max_contour_error_um", 12.0}};
  return s;
}

json fault_status() {
  json s = running_status();
  s["state"] = "FAULT";
  s["cause"] = "following error";
  s["job"] = 0;
  s["fault"] = {{"cause", "following error"}, {"axis", 1}, {"value", 1.5}, {"limit", 1.0}};
  return s;
}

TEST(BridgePayloads, StateMapsToMtconnectVocabulary) {
  const Identity id{"m1", {"X", "Y", "Z"}};
  auto p = state_payload(ready_status(), id, true);
  EXPECT_EQ(p["state"], "READY");
  EXPECT_EQ(p["execution"], "READY");
  EXPECT_EQ(p["mode"], "MANUAL");
  EXPECT_TRUE(p["alarms"].empty());
  EXPECT_EQ(p["overrides"]["feed_percent"], 100.0);
  EXPECT_TRUE(p["program"].is_null());
  EXPECT_FALSE(p.contains("homed"));  // not in today's status: not invented
  p = state_payload(running_status(), id, true);
  EXPECT_EQ(p["execution"], "ACTIVE");
  EXPECT_EQ(p["mode"], "AUTOMATIC");
  EXPECT_EQ(p["program"]["name"], "table2.ngc");
  EXPECT_TRUE(p["program"]["running"].get<bool>());
  EXPECT_EQ(p["line"], 7);
  json hold = running_status();
  hold["state"] = "HOLD";
  EXPECT_EQ(state_payload(hold, id, true)["execution"], "FEED_HOLD");
  hold["program_hold"] = true;  // M0/M1/M6
  EXPECT_EQ(state_payload(hold, id, true)["execution"], "PROGRAM_STOPPED");
  p = state_payload(fault_status(), id, true);
  EXPECT_EQ(p["execution"], "INTERRUPTED");
  ASSERT_EQ(p["alarms"].size(), 1u);
  EXPECT_EQ(p["alarms"][0]["code"], "following_error");
  EXPECT_EQ(p["alarms"][0]["axis"], 1);
  // Issue 18 fields pass through when the daemon has them.
  json h = ready_status();
  h["homed"] = {{"X", true}, {"Y", false}, {"Z", true}};
  h["tool"] = 3;
  p = state_payload(h, id, true);
  EXPECT_EQ(p["homed"]["Y"], false);
  EXPECT_EQ(p["tool"], 3);
  p = state_payload(json::object(), id, false);
  EXPECT_EQ(p["state"], "UNAVAILABLE");
  EXPECT_FALSE(p["available"].get<bool>());
  // Sensor noise (0.2 rpm) does not change the snapshot; a real change does.
  json a = ready_status(), b = ready_status();
  b["spindle"]["actual_rpm"] = 0.3;
  EXPECT_EQ(state_payload(a, id, true), state_payload(b, id, true));
  b["line"] = 3;
  EXPECT_NE(state_payload(a, id, true), state_payload(b, id, true));
}

TEST(BridgePayloads, PositionFeedAndWorkCoordinates) {
  const Identity id{"m1", {"X", "Y", "Z"}};
  json st = running_status();
  auto p = position_payload(st, id);
  EXPECT_EQ(p["machine"]["actual_mm"], st["act_mm"]);
  EXPECT_EQ(p["machine"]["commanded_mm"], st["ref_mm"]);
  EXPECT_DOUBLE_EQ(p["feed_mm_s"].get<double>(), 50.0);
  EXPECT_FALSE(p.contains("work"));
  st["work_offset_mm"] = {1.0, 0.0, -2.0};
  p = position_payload(st, id);
  EXPECT_DOUBLE_EQ(p["work"]["actual_mm"][0].get<double>(), 0.0);
  EXPECT_DOUBLE_EQ(p["work"]["actual_mm"][2].get<double>(), 5.0005);
  json moved = st;
  moved["act_mm"][1] = 2.004;
  EXPECT_NEAR(max_axis_move_mm(st, moved), 0.004, 1e-12);
  EXPECT_TRUE(std::isinf(max_axis_move_mm(st, json())));
}

TEST(BridgePayloads, EventPayloadAndTimeStamps) {
  EXPECT_EQ(iso8601_utc(0), "1970-01-01T00:00:00.000Z");
  EXPECT_EQ(iso8601_utc(1234567), "1970-01-01T00:00:01.234Z");
  DaemonEvent e;
  e.kind = "program_end";
  e.job = 3;
  e.completed = true;
  e.text = "cycle 5: program 3 done";
  e.cycle = 5;
  const auto p = event_payload(e, 17, 99, Identity{"m1", {}}, 1234567);
  EXPECT_EQ(p["seq"], 17);
  EXPECT_EQ(p["session"], 99);
  EXPECT_EQ(p["kind"], "program_end");
  EXPECT_EQ(p["job"], 3);
  EXPECT_TRUE(p["completed"].get<bool>());
  EXPECT_EQ(p["ts_us"], 1234567);
  EXPECT_EQ(p["ts"], "1970-01-01T00:00:01.234Z");
}

TEST(BridgeTopics, TopicsAndEnvironmentExpansion) {
  contour::config::MqttConfig c;
  c.topic_prefix = "plant/contourd";
  c.machine_id = "m9";
  const Topics t = make_topics(c);
  EXPECT_EQ(t.state, "plant/contourd/m9/state");
  EXPECT_EQ(t.job(12), "plant/contourd/m9/job/12");
  EXPECT_EQ(t.cmd_result, "plant/contourd/m9/cmd/result");
  ::setenv("CB_TEST_DIR", "/run/x", 1);
  EXPECT_EQ(expand_env("${CB_TEST_DIR:-/tmp}/c.sock"), "/run/x/c.sock");
  ::unsetenv("CB_TEST_DIR");
  EXPECT_EQ(expand_env("${CB_TEST_DIR:-/tmp}/c.sock"), "/tmp/c.sock");
}

// ---- SHDR ---------------------------------------------------------------------------------

// Fields of one SHDR line.
std::vector<std::string> fields(const std::string& line) {
  std::vector<std::string> f;
  std::size_t start = 0;
  for (;;) {
    const std::size_t bar = line.find('|', start);
    f.push_back(line.substr(start, bar == std::string::npos ? bar : bar - start));
    if (bar == std::string::npos) return f;
    start = bar + 1;
  }
}

// Every line valid: time stamp, then key/value pairs of data items or one condition.
void expect_valid_shdr(const std::vector<std::string>& lines, const std::vector<ItemDef>& items) {
  static const std::regex ts(R"(^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$)");
  std::set<std::string> conditions, data;
  for (const auto& it : items) {
    (it.category == ItemCategory::kCondition ? conditions : data).insert(it.key);
  }
  for (const auto& l : lines) {
    const auto f = fields(l);
    ASSERT_GE(f.size(), 3u) << l;
    EXPECT_TRUE(std::regex_match(f[0], ts)) << l;
    if (conditions.count(f[1]) != 0) {
      EXPECT_EQ(f.size(), 7u) << "condition needs 6 fields after the time stamp: " << l;
      EXPECT_TRUE(f[2] == "NORMAL" || f[2] == "WARNING" || f[2] == "FAULT" ||
                  f[2] == "UNAVAILABLE")
          << l;
    } else {
      EXPECT_EQ(f.size() % 2, 1u) << "key/value pairs: " << l;
      for (std::size_t i = 1; i + 1 < f.size(); i += 2) {
        EXPECT_EQ(data.count(f[i]), 1u) << "unknown key " << f[i] << " in " << l;
      }
    }
  }
}

TEST(BridgeShdrModel, SnapshotHasEveryItemAndValidLines) {
  const std::vector<std::string> axes{"X", "Y", "Z"};
  ShdrModel m(axes, true);
  m.update(ready_status(), true);
  const auto snap = m.snapshot_lines("2026-01-01T00:00:00.000Z");
  expect_valid_shdr(snap, m.items());
  std::string all;
  for (const auto& l : snap) all += l + "\n";
  for (const auto& it : m.items()) {
    EXPECT_NE(all.find("|" + it.key + "|"), std::string::npos) << it.key;
  }
  EXPECT_EQ(m.value("avail"), "AVAILABLE");
  EXPECT_EQ(m.value("exec"), "READY");
  EXPECT_EQ(m.value("Zact"), "3.0005");
  EXPECT_EQ(m.value("feed_ovr"), "100");
  EXPECT_EQ(m.value("tool"), "UNAVAILABLE");
  EXPECT_EQ(m.value("overruns"), "3");
  EXPECT_NE(all.find("|system|NORMAL||||"), std::string::npos);
  // No spindle configured: no spindle items.
  ShdrModel ns(axes, false);
  for (const auto& it : ns.items()) EXPECT_NE(it.key.substr(0, 1), "S") << it.key;
}

TEST(BridgeShdrModel, ChangedLinesOnlyWhatChangedAndConditions) {
  ShdrModel m({"X", "Y", "Z"}, true);
  m.update(ready_status(), true);
  const std::string ts = "2026-01-01T00:00:00.000Z";
  auto first = m.changed_lines(ts);
  expect_valid_shdr(first, m.items());
  EXPECT_FALSE(first.empty());
  EXPECT_TRUE(m.changed_lines(ts).empty());  // nothing changed
  m.update(running_status(), true);
  auto run = m.changed_lines(ts);
  expect_valid_shdr(run, m.items());
  std::string all;
  for (const auto& l : run) all += l + "\n";
  EXPECT_NE(all.find("|exec|ACTIVE"), std::string::npos) << all;
  EXPECT_NE(all.find("|mode|AUTOMATIC"), std::string::npos) << all;
  EXPECT_NE(all.find("|line|7"), std::string::npos) << all;
  EXPECT_NE(all.find("|path_feedrate|50.000"), std::string::npos) << all;
  EXPECT_EQ(all.find("|Xact|"), std::string::npos) << "unchanged position re-sent: " << all;
  m.update(fault_status(), true);
  auto fault = m.changed_lines(ts);
  expect_valid_shdr(fault, m.items());
  all.clear();
  for (const auto& l : fault) all += l + "\n";
  EXPECT_NE(all.find("|system|FAULT|following_error|fault|HIGH|following error (axis Y): 1.5 "
                     "beyond limit 1"),
            std::string::npos)
      << all;
  m.update(ready_status(), true);
  auto cleared = m.changed_lines(ts);
  all.clear();
  for (const auto& l : cleared) all += l + "\n";
  EXPECT_NE(all.find("|system|NORMAL||||"), std::string::npos) << all;
  m.update(json::object(), false);
  auto gone = m.changed_lines(ts);
  expect_valid_shdr(gone, m.items());
  all.clear();
  for (const auto& l : gone) all += l + "\n";
  EXPECT_NE(all.find("|avail|UNAVAILABLE"), std::string::npos);
  EXPECT_NE(all.find("|exec|UNAVAILABLE"), std::string::npos);
  EXPECT_NE(all.find("|system|UNAVAILABLE||||"), std::string::npos);
}

TEST(BridgeShdrModel, FieldsNeverBreakTheLine) {
  EXPECT_EQ(shdr_field("a|b\nc\rd"), "a/b c d");
  ShdrModel m({"X"}, false);
  json st = ready_status();
  st["act_mm"] = {1.0};
  st["ref_mm"] = {1.0};
  st["program"] = {{"job", 1}, {"name", "evil|name\nx"}};
  m.update(st, true);
  EXPECT_EQ(m.value("program"), "evil/name x");
  expect_valid_shdr(m.snapshot_lines("2026-01-01T00:00:00.000Z"), m.items());
}

TEST(BridgeShdrModel, JobKpisFromTheResult) {
  ShdrModel m({"X", "Y", "Z"}, true);
  m.set_job_result(json{{"job", 5}, {"completed", true}, {"duration_s", 3.427},
                        {"max_contour_error_um", 47.9119}, {"rms_contour_error_um", 9.4633},
                        {"max_following_error_um", 1323.82}});
  EXPECT_EQ(m.value("job"), "5");
  EXPECT_EQ(m.value("job_completed"), "true");
  EXPECT_EQ(m.value("job_ce_max"), "0.047912");
  EXPECT_EQ(m.value("job_ce_rms"), "0.009463");
  EXPECT_EQ(m.value("job_fe_max"), "1.323820");
  EXPECT_EQ(m.value("job_duration"), "3.427");
}

TEST(BridgeDevicesXml, NamesEveryShdrKeyOnceWithTheExtensionNamespace) {
  DeviceInfo d;
  d.name = "m1";
  d.uuid = "contourd-m1";
  d.manufacturer = "ACME";
  d.axes = {"X", "Y", "Z"};
  d.has_spindle = true;
  const std::string x = devices_xml(d);
  EXPECT_NE(x.find("xmlns:x=\"" + std::string(kExtensionUrn) + "\""), std::string::npos);
  EXPECT_NE(x.find("<MTConnectDevices xmlns=\"urn:mtconnect.org:MTConnectDevices:2.0\""),
            std::string::npos);
  for (const auto& it : shdr_items(d.axes, true)) {
    const std::string name = "name=\"" + it.key + "\"";
    const auto first = x.find(name);
    EXPECT_NE(first, std::string::npos) << it.key;
    EXPECT_EQ(x.find(name, first + 1), std::string::npos) << it.key << " twice";
  }
  EXPECT_NE(x.find("type=\"x:CONTOUR_ERROR\""), std::string::npos);
  EXPECT_NE(x.find("<Linear id=\"m1_Y\" name=\"Y\">"), std::string::npos);
  EXPECT_NE(x.find("manufacturer=\"ACME\""), std::string::npos);
  // Every opened element is closed (a cheap well-formedness check; the sim test runs xmllint).
  std::regex open_tag(R"(<([A-Za-z]+)[ >])");
  std::map<std::string, int> depth;
  for (auto it = std::sregex_iterator(x.begin(), x.end(), open_tag); it != std::sregex_iterator();
       ++it) {
    const std::string tag = (*it)[1];
    const std::size_t end = x.find('>', static_cast<std::size_t>(it->position()));
    if (x[end - 1] != '/') ++depth[tag];
  }
  for (const auto& [tag, n] : depth) {
    std::size_t closes = 0;
    for (std::size_t p = x.find("</" + tag + ">"); p != std::string::npos;
         p = x.find("</" + tag + ">", p + 1)) {
      ++closes;
    }
    EXPECT_EQ(static_cast<std::size_t>(n), closes) << tag;
  }
}

// ---- credentials ----------------------------------------------------------------------------

std::string write_cred(const std::string& text, mode_t mode) {
  static int n = 0;
  const auto p = std::filesystem::temp_directory_path() /
                 ("bridge_cred_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
  std::ofstream(p) << text;
  ::chmod(p.c_str(), mode);
  return p.string();
}

TEST(BridgeCredentials, ReadsAnOwnerOnlyFile) {
  const auto p = write_cred("# broker\nusername: bridge-m1\npassword:  s3cr3t:with:colons \n", 0600);
  const Credentials c = load_credentials(p);
  EXPECT_EQ(c.username, "bridge-m1");
  EXPECT_EQ(c.password, "s3cr3t:with:colons");
  std::filesystem::remove(p);
}

TEST(BridgeCredentials, RefusesOtherModesAndNeverShowsTheSecret) {
  const std::string secret = "hunter2-Secret";
  auto p = write_cred("username: u\npassword: " + secret + "\n", 0644);
  try {
    load_credentials(p);
    FAIL() << "a 0644 credentials file was accepted";
  } catch (const CredentialsError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("has mode 0644"), std::string::npos) << m;
    EXPECT_NE(m.find("chmod 600"), std::string::npos) << m;
    EXPECT_EQ(m.find(secret), std::string::npos) << m;
  }
  std::filesystem::remove(p);
  p = write_cred("password: " + secret + "\ncolour: " + secret + "\n", 0600);
  try {
    load_credentials(p);
    FAIL() << "unknown key accepted";
  } catch (const CredentialsError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(":2: unknown key 'colour'"), std::string::npos) << m;
    EXPECT_EQ(m.find(secret), std::string::npos) << m;
  }
  std::filesystem::remove(p);
  p = write_cred("password: " + secret + "\n", 0600);
  EXPECT_THROW(load_credentials(p), CredentialsError);  // password without username
  std::filesystem::remove(p);
  EXPECT_THROW(load_credentials("/nonexistent/cred"), CredentialsError);
}

}  // namespace
