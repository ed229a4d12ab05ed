// contour-bridge with the real engines (issue 22): mosquitto from Debian on a free loopback port,
// contourd on config/sim.yaml, contour-bridge, contourctl. A subscriber receives the retained
// state, the job summary with the same figures as `contourctl --json run --wait`, the events in
// order; the broker is killed and restarted mid-run: reconnect, events kept, the run's figures
// unchanged; TLS with a password from a 0600 file; commands off by default, then an allow-list.
#include <gtest/gtest.h>

#include <set>

#include "tests/bridge/bridge_support.hpp"

namespace {

using namespace contour::test::bridge;
using contour::test::DaemonProcess;
using nlohmann::json;
using std::chrono::milliseconds;
using std::chrono::seconds;

const std::string kTable2 = std::string(CONTOUR_SOURCE_DIR) + "/config/programs/table2.ngc";

std::string mqtt_section(int port, const std::string& id, const std::string& more = "") {
  return "mqtt:\n  host: 127.0.0.1\n  port: " + std::to_string(port) + "\n  machine_id: " + id +
         "\n  reconnect_min_s: 0.2\n  reconnect_max_s: 1\n  status_interval_s: 1\n" + more;
}

Child start_bridge(const TempDir& dir, const std::string& cfg, const std::string& sock,
                   const std::string& tag = "bridge") {
  return Child({bin("tools/contour-bridge/contour-bridge"), "--config", cfg, "--socket", sock},
               dir / (tag + ".out"), dir / (tag + ".log"));
}

// The same object as contourctl printed: same keys, same values. `overruns` and
// `telemetry_dropped` are the daemon's counters at the moment `result` is asked (it counts
// overruns until the call, not until the job's end): the bridge asks first, so its value can only
// be smaller or equal.
void expect_same_summary(const json& mqtt, const json& ctl) {
  std::set<std::string> a, b;
  for (auto it = mqtt.begin(); it != mqtt.end(); ++it) a.insert(it.key());
  for (auto it = ctl.begin(); it != ctl.end(); ++it) b.insert(it.key());
  EXPECT_EQ(a, b) << "field names differ:\n mqtt " << mqtt.dump() << "\n ctl  " << ctl.dump();
  for (auto it = ctl.begin(); it != ctl.end(); ++it) {
    if (!mqtt.contains(it.key())) continue;
    if (it.key() == "overruns" || it.key() == "telemetry_dropped") {
      EXPECT_LE(mqtt[it.key()].get<std::uint64_t>(), it.value().get<std::uint64_t>()) << it.key();
    } else {
      EXPECT_EQ(mqtt[it.key()], it.value()) << it.key();
    }
  }
}

// Events as received: parsed, duplicates (QoS 1 re-sends) removed by seq, in arrival order.
std::vector<json> events(Subscriber& s, const std::string& topic) {
  std::vector<json> out;
  std::set<std::uint64_t> seen;
  for (const auto& m : s.on(topic)) {
    json j = json::parse(m.payload, nullptr, false);
    if (j.is_discarded()) {
      ADD_FAILURE() << "event payload is not JSON: " << m.payload;
      continue;
    }
    if (seen.insert(j["seq"].get<std::uint64_t>()).second) out.push_back(j);
  }
  return out;
}

// Arrival order is seq order and no seq is missing from first to last.
void expect_contiguous(const std::vector<json>& ev, std::uint64_t first) {
  ASSERT_FALSE(ev.empty());
  std::uint64_t expect = first;
  for (const auto& e : ev) {
    EXPECT_EQ(e["seq"].get<std::uint64_t>(), expect) << "event lost or out of order: " << e.dump();
    expect = e["seq"].get<std::uint64_t>() + 1;
  }
}

// Index of the first event at or after `from` that satisfies pred; -1 if none.
long find_event(const std::vector<json>& ev, std::size_t from,
                const std::function<bool(const json&)>& pred) {
  for (std::size_t i = from; i < ev.size(); ++i) {
    if (pred(ev[i])) return static_cast<long>(i);
  }
  return -1;
}

// transition READY->RUNNING, program_start, program_end (completed), transition RUNNING->READY
// for `job`, in this order.
void expect_run_events(const std::vector<json>& ev, std::uint64_t job) {
  const long a = find_event(ev, 0, [](const json& e) {
    return e["kind"] == "transition" && e["from"] == "READY" && e["to"] == "RUNNING";
  });
  ASSERT_GE(a, 0) << "no READY -> RUNNING";
  const long b = find_event(ev, static_cast<std::size_t>(a), [&](const json& e) {
    return e["kind"] == "program_start" && e["job"] == job;
  });
  ASSERT_GE(b, 0) << "no program_start for job " << job;
  const long c = find_event(ev, static_cast<std::size_t>(b), [&](const json& e) {
    return e["kind"] == "program_end" && e["job"] == job && e["completed"] == true;
  });
  ASSERT_GE(c, 0) << "no program_end for job " << job;
  const long d = find_event(ev, static_cast<std::size_t>(c), [](const json& e) {
    return e["kind"] == "transition" && e["from"] == "RUNNING" && e["to"] == "READY";
  });
  ASSERT_GE(d, 0) << "no RUNNING -> READY after the end of job " << job;
}

TEST(BridgeMqtt, RetainedStateJobSummaryEventsInOrderAndLastWill) {
  require_mosquitto();
  TempDir dir("mqtt");
  Broker broker(dir.path(), free_port());
  const std::string cfg = write_file(dir / "m.yaml", sim_config(mqtt_section(broker.port(), "m1")));
  DaemonProcess d("bridge_mqtt", daemon_options(cfg));
  ASSERT_TRUE(d.connected()) << d.log();
  Subscriber live(broker.port(), {"contourd/m1/#"}, {});
  ASSERT_TRUE(live.wait_subscribed());
  Child bridge = start_bridge(dir, cfg, d.sock());
  ASSERT_TRUE(live.wait_topic("contourd/m1/state", seconds(30),
                              [](const json& j) { return j.value("state", "") == "READY"; }))
      << bridge.err();

  // A subscriber that comes later gets the retained snapshot and "online" from the broker.
  Subscriber late(broker.port(), {"contourd/m1/state", "contourd/m1/online"}, {});
  ASSERT_TRUE(late.wait_for(
      [](const std::vector<Message>& v) {
        bool state = false, online = false;
        for (const auto& m : v) {
          state |= m.topic == "contourd/m1/state" && m.retained &&
                   json::parse(m.payload).value("state", "") == "READY";
          online |= m.topic == "contourd/m1/online" && m.retained && m.payload == "online";
        }
        return state && online;
      },
      seconds(20)));

  const auto t_run = contour::bridge::now_us();
  const json ctl = contourctl_run_wait(d.sock(), kTable2, dir.path().string(), "1");
  ASSERT_TRUE(ctl.value("completed", false)) << ctl.dump();
  const auto job = ctl["job"].get<std::uint64_t>();
  const std::string job_topic = "contourd/m1/job/" + std::to_string(job);
  ASSERT_TRUE(live.wait_topic(job_topic, seconds(30))) << bridge.err();
  const auto jm = live.on(job_topic).back();
  EXPECT_TRUE(jm.retained || live.on(job_topic).size() == 1);
  expect_same_summary(json::parse(jm.payload), ctl);

  ASSERT_TRUE(live.wait_topic("contourd/m1/event", seconds(20), [](const json& e) {
    return e["kind"] == "transition" && e["to"] == "READY";
  }));
  const auto ev = events(live, "contourd/m1/event");
  expect_contiguous(ev, 1);
  expect_run_events(ev, job);
  for (const auto& e : ev) {
    EXPECT_EQ(e["machine_id"], "m1");
    EXPECT_TRUE(e.contains("ts") && e.contains("ts_us") && e.contains("session")) << e.dump();
  }

  // Positions while the axes moved: machine coordinates, actual and commanded, three axes.
  const auto pos = live.on("contourd/m1/position");
  EXPECT_GE(pos.size(), 5u);
  std::int64_t last_ts = 0;
  for (const auto& m : pos) {
    EXPECT_FALSE(m.retained);
    const json p = json::parse(m.payload);
    EXPECT_EQ(p["machine"]["actual_mm"].size(), 3u) << m.payload;
    EXPECT_EQ(p["machine"]["commanded_mm"].size(), 3u) << m.payload;
    EXPECT_GE(p["ts_us"].get<std::int64_t>(), last_ts);
    last_ts = p["ts_us"].get<std::int64_t>();
  }
  EXPECT_GT(last_ts, t_run);
  // The state followed the run: ACTIVE with the program's name, then READY with finished_job.
  bool active = false;
  for (const auto& m : live.on("contourd/m1/state")) {
    const json s = json::parse(m.payload);
    active |= s["execution"] == "ACTIVE" && s["program"].is_object() &&
              s["program"]["name"].get<std::string>().find("table2.ngc") != std::string::npos;
  }
  EXPECT_TRUE(active);
  // The bridge publishes the READY transition event as it comes and the state from its next
  // status poll (right after the event): the state with finished_job may arrive just after it.
  EXPECT_TRUE(live.wait_topic("contourd/m1/state", seconds(20), [job](const json& s) {
    return s.value("finished_job", 0ULL) == job;
  })) << "no state with finished_job " << job;
  EXPECT_EQ(json::parse(live.on("contourd/m1/state").back().payload)["finished_job"], job);

  // The bridge dies without a word: the broker publishes its last will.
  bridge.signal(SIGKILL);
  EXPECT_TRUE(live.wait_for(
      [](const std::vector<Message>& v) {
        return !v.empty() && [&] {
          for (auto it = v.rbegin(); it != v.rend(); ++it) {
            if (it->topic == "contourd/m1/online") return it->payload == "offline";
          }
          return false;
        }();
      },
      seconds(30)))
      << "no last will 'offline' after the bridge was killed";
}

TEST(BridgeMqtt, BrokerKilledMidRunReconnectsEventsKeptFiguresUnchanged) {
  require_mosquitto();
  TempDir dir("restart");
  // Persistence so that the test's own subscriber keeps its session across the broker's crash
  // (the bridge needs none: it holds what it could not send).
  Broker broker(dir.path(), free_port(),
                "persistence true\npersistence_location " + dir.path().string() +
                    "/\nautosave_interval 1\n");
  // A small queue: the outage lasts longer than it holds position samples.
  const std::string cfg = write_file(
      dir / "m.yaml", sim_config(mqtt_section(broker.port(), "m2", "  queue_size: 16\n")));
  DaemonProcess d("bridge_restart", daemon_options(cfg));
  ASSERT_TRUE(d.connected()) << d.log();
  Subscriber::Options so;
  so.client_id = "test-persistent-sub";
  so.clean_session = false;
  Subscriber sub(broker.port(), {"contourd/m2/#"}, so);
  ASSERT_TRUE(sub.wait_subscribed());
  Child bridge = start_bridge(dir, cfg, d.sock());
  ASSERT_TRUE(sub.wait_topic("contourd/m2/state", seconds(30),
                             [](const json& j) { return j.value("state", "") == "READY"; }))
      << bridge.err();

  // Reference run with the broker up, from the origin.
  const json ref = contourctl_run_wait(d.sock(), kTable2, dir.path().string(), "ref");
  ASSERT_TRUE(ref.value("completed", false)) << ref.dump();
  ASSERT_TRUE(sub.wait_topic("contourd/m2/job/" + std::to_string(ref["job"].get<int>()), seconds(30)));
  for (const char* axis : {"X", "Y", "Z"}) {
    d.ok({{"cmd", "set-position"}, {"axis", axis}, {"position_mm", 0.0}});
  }
  // The broker has saved the subscriber's session at least once (autosave).
  ASSERT_TRUE(wait_until([&] { return std::filesystem::exists(dir / "mosquitto.db"); }, seconds(20)))
      << broker.log();

  // The same run again; the broker is killed while it runs and comes back after it ended.
  Child run({bin("tools/contourctl"), "--socket", d.sock(), "--json", "run", kTable2, "--wait",
             "--timeout", "120", "--quiet"},
            dir / "ctl_run.out", dir / "ctl_run.err");
  const auto job = ref["job"].get<std::uint64_t>() + 1;
  ASSERT_TRUE(sub.wait_topic("contourd/m2/event", seconds(30), [&](const json& e) {
    return e["kind"] == "program_start" && e["job"] == job;
  })) << bridge.err();
  broker.kill(SIGKILL);
  ASSERT_EQ(run.wait(seconds(150)), 0) << run.err();
  std::string last;
  std::istringstream in(run.out());
  for (std::string l; std::getline(in, l);) {
    if (!l.empty()) last = l;
  }
  const json ctl = json::parse(last);
  ASSERT_TRUE(ctl.value("completed", false)) << ctl.dump();
  ASSERT_EQ(ctl["job"], job);
  // The bridge noticed (it retries while the broker is away).
  ASSERT_TRUE(wait_until([&] { return bridge.err().find("connection to 127.0.0.1") != std::string::npos; },
                         seconds(20)))
      << bridge.err();
  broker.start();

  const std::string job_topic = "contourd/m2/job/" + std::to_string(job);
  ASSERT_TRUE(sub.wait_topic(job_topic, seconds(60))) << bridge.err() << broker.log();
  const json summary = json::parse(sub.on(job_topic).back().payload);
  expect_same_summary(summary, ctl);
  // The run's figures are those of the reference run: the broker's absence never reached the loop.
  for (const char* k : {"completed", "duration_s", "max_contour_error_um", "rms_contour_error_um",
                        "max_following_error_um", "max_model_error_um", "end_overshoot_um",
                        "samples", "faults"}) {
    EXPECT_EQ(summary[k], ref[k]) << k;
  }
  ASSERT_TRUE(sub.wait_topic("contourd/m2/event", seconds(30), [&](const json& e) {
    return e["kind"] == "transition" && e["from"] == "RUNNING" && e["to"] == "READY" &&
           e["cycle"].get<std::uint64_t>() > 0;
  }));
  // Every event, in order, none lost: the ones of the reference run and those of the run during
  // which the broker was gone.
  ASSERT_TRUE(wait_until(
      [&] {
        const auto ev = events(sub, "contourd/m2/event");
        return find_event(ev, 0, [&](const json& e) {
                 return e["kind"] == "program_end" && e["job"] == job;
               }) >= 0 &&
               std::count_if(ev.begin(), ev.end(), [](const json& e) {
                 return e["kind"] == "transition" && e["to"] == "READY";
               }) >= 2;
      },
      seconds(30)));
  const auto ev = events(sub, "contourd/m2/event");
  expect_contiguous(ev, 1);
  expect_run_events(ev, job);
  // The bridge's own counters: one lost connection, reconnected, nothing dropped but positions.
  ASSERT_TRUE(sub.wait_topic("contourd/m2/bridge", seconds(30), [](const json& b) {
    return b["mqtt"]["disconnects"].get<int>() >= 1 && b["mqtt"]["connected"] == true;
  })) << bridge.err();
  json counters;
  for (const auto& m : sub.on("contourd/m2/bridge")) {
    const json b = json::parse(m.payload);
    if (b["mqtt"]["disconnects"].get<int>() >= 1) counters = b;
  }
  EXPECT_EQ(counters["queue"]["dropped_events"], 0) << counters.dump();
  EXPECT_EQ(counters["mqtt"]["publish_errors"], 0) << counters.dump();
  EXPECT_GE(counters["mqtt"]["connects"].get<int>(), 2) << counters.dump();
  EXPECT_GT(counters["queue"]["high_water"].get<int>(), 1) << counters.dump();
  EXPECT_LE(counters["queue"]["high_water"].get<int>(), 16) << "the queue is bounded";
  std::printf("outage: queue high water %d of 16, %d position samples dropped, %d events dropped\n",
              counters["queue"]["high_water"].get<int>(),
              counters["queue"]["dropped_positions"].get<int>(),
              counters["queue"]["dropped_events"].get<int>());
  // What the bridge held while the broker was away went out after the reconnect: at least the
  // end-of-program event, the transition and the job summary.
  {
    const std::string log = bridge.err();
    const std::string mark = " messages queued)";
    const auto p = log.rfind(mark);
    ASSERT_NE(p, std::string::npos) << log;
    const auto open = log.rfind('(', p);
    EXPECT_GE(std::stoi(log.substr(open + 1, p - open - 1)), 3) << log;
  }
  // And "online" again after the reconnect.
  const auto online = sub.on("contourd/m2/online");
  ASSERT_FALSE(online.empty());
  EXPECT_EQ(online.back().payload, "online");
}

TEST(BridgeMqtt, StartsBeforeItsBrokerAndConnectsWhenItComes) {
  require_mosquitto();
  TempDir dir("late");
  const int port = free_port();
  const std::string cfg = write_file(dir / "m.yaml", sim_config(mqtt_section(port, "m5")));
  DaemonProcess d("bridge_late", daemon_options(cfg));
  ASSERT_TRUE(d.connected()) << d.log();
  Child bridge = start_bridge(dir, cfg, d.sock());
  ASSERT_TRUE(wait_until([&] { return bridge.err().find("cannot connect") != std::string::npos ||
                                      bridge.err().find("failed") != std::string::npos; },
                         seconds(20)))
      << bridge.err();
  Broker broker(dir.path(), port);
  Subscriber sub(port, {"contourd/m5/#"}, {});
  ASSERT_TRUE(sub.wait_topic("contourd/m5/state", seconds(30),
                             [](const json& j) { return j.value("state", "") == "READY"; }))
      << bridge.err();
  EXPECT_TRUE(bridge.running());
}

// A CA and a broker certificate for 127.0.0.1 (openssl CLI, EC keys: fast).
bool make_certs(const TempDir& dir) {
  const std::string d = dir.path().string();
  write_file(d + "/san.ext", "subjectAltName=IP:127.0.0.1,DNS:localhost\n");
  const std::string cmd =
      "cd " + d +
      " && openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout "
      "ca.key -out ca.crt -subj /CN=contour-test-ca -days 2 "
      "&& openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout server.key "
      "-out server.csr -subj /CN=localhost "
      "&& openssl x509 -req -in server.csr -CA ca.crt -CAkey ca.key -CAcreateserial -out "
      "server.crt -days 2 -extfile san.ext && chmod 644 server.key "
      // The bridge's client certificate, its key protected by a passphrase; the reader's.
      "&& openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -keyout client.key "
      "-passout pass:key-Passphrase-9 -out client.csr -subj /CN=bridge-m3 "
      "&& openssl x509 -req -in client.csr -CA ca.crt -CAkey ca.key -CAcreateserial -out "
      "client.crt -days 2 "
      "&& openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout reader.key "
      "-out reader.csr -subj /CN=reader "
      "&& openssl x509 -req -in reader.csr -CA ca.crt -CAkey ca.key -CAcreateserial -out "
      "reader.crt -days 2 && chmod 644 client.key reader.key";
  return std::system(("(" + cmd + ") >" + d + "/certs.log 2>&1").c_str()) == 0;
}

TEST(BridgeMqtt, TlsWithPasswordFromAnOwnerOnlyFile) {
  require_mosquitto();
  if (std::system("command -v openssl >/dev/null 2>&1") != 0) {
    std::printf("SKIPPED: openssl (CLI) is not installed: no certificates for the TLS broker\n");
    std::exit(77);
  }
  TempDir dir("tls");
  ASSERT_TRUE(make_certs(dir)) << slurp(dir / "certs.log");
  const std::string secret = "Pa55-not-in-any-log";
  const std::string pw = dir / "passwd";
  write_file(pw, "");
  ASSERT_EQ(std::system(("mosquitto_passwd -b " + pw + " bridge " + secret + " && mosquitto_passwd -b " +
                         pw + " reader reader-pw").c_str()),
            0);
  ::chmod(pw.c_str(), 0644);
  const int port = free_port();
  Broker broker(dir.path(), port,
                "cafile " + dir / "ca.crt" + "\ncertfile " + dir / "server.crt" + "\nkeyfile " +
                    dir / "server.key" + "\nrequire_certificate false\nallow_anonymous false\n" +
                    "password_file " + pw + "\n");
  const std::string cred = write_file(dir / "mqtt.cred", "username: bridge\npassword: " + secret + "\n", 0600);
  const std::string tls = "  tls:\n    ca_file: " + dir / "ca.crt" + "\n  credentials_file: " + cred + "\n";
  const std::string cfg = write_file(dir / "m.yaml", sim_config(mqtt_section(port, "m3", tls)));
  DaemonProcess d("bridge_tls", daemon_options(cfg));
  ASSERT_TRUE(d.connected()) << d.log();
  Subscriber::Options so;
  so.username = "reader";
  so.password = "reader-pw";
  so.ca_file = dir / "ca.crt";
  Subscriber sub(port, {"contourd/m3/#"}, so);
  ASSERT_TRUE(sub.wait_subscribed()) << broker.log();
  {
    Child bridge = start_bridge(dir, cfg, d.sock());
    ASSERT_TRUE(sub.wait_topic("contourd/m3/state", seconds(30),
                               [](const json& j) { return j.value("state", "") == "READY"; }))
        << bridge.err() << broker.log();
    EXPECT_NE(bridge.err().find("TLS"), std::string::npos);
    EXPECT_EQ(bridge.stop(SIGTERM), 0);
    EXPECT_EQ(bridge.err().find(secret), std::string::npos) << "the password was logged";
    // A clean stop says "offline" itself.
    EXPECT_TRUE(sub.wait_for(
        [](const std::vector<Message>& v) {
          return !v.empty() && v.back().topic == "contourd/m3/online" && v.back().payload == "offline";
        },
        seconds(20)));
  }
  {
    // A wrong password: refused by the broker, said so, the bridge keeps retrying.
    const std::string bad = write_file(dir / "bad.cred", "username: bridge\npassword: wrong-" + secret + "\n", 0600);
    const std::string cfg2 = write_file(
        dir / "m2.yaml",
        sim_config(mqtt_section(port, "m3", "  tls:\n    ca_file: " + dir / "ca.crt" +
                                                "\n  credentials_file: " + bad + "\n")));
    Child bridge = start_bridge(dir, cfg2, d.sock(), "bridge_bad");
    EXPECT_TRUE(wait_until([&] { return bridge.err().find("not authorised") != std::string::npos; },
                           seconds(30)))
        << bridge.err();
    EXPECT_TRUE(bridge.running());
    EXPECT_EQ(bridge.err().find(secret), std::string::npos) << "the password was logged";
  }
  {
    // Client certificates instead of a password (the broker takes the certificate's CN as the
    // user name); the key's passphrase comes from the credentials file.
    const int cport = free_port();
    TempDir bdir("tls_cert_broker");
    Broker cbroker(bdir.path(), cport,
                   "cafile " + dir / "ca.crt" + "\ncertfile " + dir / "server.crt" + "\nkeyfile " +
                       dir / "server.key" +
                       "\nrequire_certificate true\nuse_identity_as_username true\n"
                       "allow_anonymous false\n");
    Subscriber::Options co;
    co.ca_file = dir / "ca.crt";
    co.cert_file = dir / "reader.crt";
    co.key_file = dir / "reader.key";
    Subscriber csub(cport, {"contourd/m3c/#"}, co);
    ASSERT_TRUE(csub.wait_subscribed()) << cbroker.log();
    const std::string kp = write_file(dir / "key.cred", "key_password: key-Passphrase-9\n", 0600);
    const std::string ccfg = write_file(
        dir / "mc.yaml",
        sim_config(mqtt_section(cport, "m3c", "  tls:\n    ca_file: " + dir / "ca.crt" +
                                                   "\n    cert_file: " + dir / "client.crt" +
                                                   "\n    key_file: " + dir / "client.key" +
                                                   "\n  credentials_file: " + kp + "\n")));
    Child bridge = start_bridge(dir, ccfg, d.sock(), "bridge_cert");
    ASSERT_TRUE(csub.wait_topic("contourd/m3c/state", seconds(30),
                                [](const json& j) { return j.value("state", "") == "READY"; }))
        << bridge.err() << cbroker.log();
    EXPECT_EQ(bridge.err().find("key-Passphrase-9"), std::string::npos) << "the passphrase was logged";
  }
  {
    // The credentials file readable by others: refused at start, exit 78, the fix named.
    ::chmod(cred.c_str(), 0644);
    Child bridge = start_bridge(dir, cfg, d.sock(), "bridge_mode");
    EXPECT_EQ(bridge.wait(seconds(30)), 78);
    EXPECT_NE(bridge.err().find("chmod 600"), std::string::npos) << bridge.err();
    EXPECT_EQ(bridge.err().find(secret), std::string::npos) << "the password was logged";
  }
}

TEST(BridgeMqtt, CommandsOffByDefaultThenOnlyTheAllowList) {
  require_mosquitto();
  TempDir dir("cmd");
  Broker broker(dir.path(), free_port());
  const std::string cfg = write_file(dir / "m.yaml", sim_config(mqtt_section(broker.port(), "m4")));
  DaemonProcess d("bridge_cmd", daemon_options(cfg));
  ASSERT_TRUE(d.connected()) << d.log();
  Subscriber sub(broker.port(), {"contourd/m4/#"}, {});
  ASSERT_TRUE(sub.wait_subscribed());
  // A program that runs long enough to be held: 60 mm at 600 mm/min.
  const json slow{{"cmd", "run"}, {"program", "G21 G90\nG01 X60 F600\nM2\n"}, {"name", "slow.ngc"}};
  {
    Child bridge = start_bridge(dir, cfg, d.sock());
    ASSERT_TRUE(sub.wait_topic("contourd/m4/state", seconds(30),
                               [](const json& j) { return j.value("state", "") == "READY"; }))
        << bridge.err();
    d.ok(slow);
    sub.publish("contourd/m4/cmd", "hold");
    sub.publish("contourd/m4/cmd", R"({"cmd":"hold","id":1})");
    // Bounded wait for something that must not happen: no answer, no hold.
    std::this_thread::sleep_for(milliseconds(1500));
    EXPECT_TRUE(sub.on("contourd/m4/cmd/result").empty());
    EXPECT_EQ(d.state(), "RUNNING");
    d.ok({{"cmd", "stop"}});
    EXPECT_EQ(bridge.stop(SIGTERM), 0);
  }
  const std::string cfg2 = write_file(
      dir / "m2.yaml",
      sim_config(mqtt_section(broker.port(), "m4", "  commands:\n    enabled: true\n")));
  Child bridge = start_bridge(dir, cfg2, d.sock(), "bridge_cmd");
  ASSERT_TRUE(wait_until([&] { return bridge.err().find("mqtt: connected") != std::string::npos; },
                         seconds(30)))
      << bridge.err();
  ASSERT_TRUE(sub.wait_topic("contourd/m4/bridge", seconds(30), [](const json& b) {
    return b["commands"]["enabled"] == true;
  }));
  auto answer = [&](const json& id) {
    json a;
    EXPECT_TRUE(sub.wait_topic("contourd/m4/cmd/result", seconds(30), [&](const json& r) {
      if (r["id"] != id) return false;
      a = r;
      return true;
    })) << "no answer to id " << id.dump() << "\n" << bridge.err();
    return a;
  };
  d.wait_status([](const json& st) { return st["state"] == "READY"; });
  d.ok(slow);
  sub.publish("contourd/m4/cmd", R"({"cmd":"enable","id":"e1"})");
  json a = answer("e1");
  EXPECT_FALSE(a.value("ok", true));
  EXPECT_NE(a.value("error", "").find("not allowed over MQTT"), std::string::npos) << a.dump();
  sub.publish("contourd/m4/cmd", R"({"cmd":"shutdown","id":"s1"})");
  EXPECT_FALSE(answer("s1").value("ok", true));
  sub.publish("contourd/m4/cmd", R"({"id":"x1","cmd":)");
  EXPECT_EQ(answer(nullptr).value("error", ""), "payload is not a JSON object");
  sub.publish("contourd/m4/cmd", R"({"cmd":"hold","id":"h1"})");
  a = answer("h1");
  EXPECT_TRUE(a.value("ok", false)) << a.dump();
  EXPECT_EQ(d.wait_status([](const json& st) { return st["state"] == "HOLD"; }, 3000)["state"], "HOLD");
  sub.publish("contourd/m4/cmd", R"({"cmd":"resume","id":2})");
  EXPECT_TRUE(answer(2).value("ok", false));
  EXPECT_EQ(d.wait_status([](const json& st) { return st["state"] == "RUNNING"; }, 3000)["state"],
            "RUNNING");
  sub.publish("contourd/m4/cmd", R"({"cmd":"stop","id":3})");
  EXPECT_TRUE(answer(3).value("ok", false));
  EXPECT_EQ(d.wait_status([](const json& st) { return st["state"] == "READY"; }, 3000)["state"], "READY");
  // A command the daemon refuses comes back with the daemon's reason.
  sub.publish("contourd/m4/cmd", R"({"cmd":"resume","id":4})");
  a = answer(4);
  EXPECT_FALSE(a.value("ok", true));
  EXPECT_NE(a.value("error", "").find("READY"), std::string::npos) << a.dump();
}

}  // namespace
