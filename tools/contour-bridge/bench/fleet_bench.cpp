// contour-bridge-fleet — a shop in one machine (issue 22): one mosquitto broker on a loopback
// port, N contourd instances on the simulated machine (config/sim.yaml, each its own socket and
// machine_id), one contour-bridge per daemon, and one subscriber on `contourd/+/#` that sees
// every message. Each machine runs a part program P times (from the same start position); the
// subscriber counts messages per topic, measures publish -> receive latency (the payload's
// `ts_us`, set when the bridge publishes, against the arrival time; same host, same clock) and
// checks that every machine's job summaries arrived.
//
//   contour-bridge-fleet [--machines 20] [--programs 3] [--program FILE] [--position-rate 10]
//                        [--check] [--json] [--keep DIR]
// Prints a table and, last, one JSON object. --check: exit 1 unless every job summary arrived
// with the figures of that job. Figures are reported, never asserted (tools/contour-bridge/
// README.md "Fleet benchmark" has the measured numbers and the broker topology they imply).
#include <fcntl.h>
#include <mosquitto.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tools/contour-bridge/payloads.hpp"

extern char** environ;

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string slurp(const std::string& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string exe_dir() {
  char b[4096];
  const ssize_t n = ::readlink("/proc/self/exe", b, sizeof b - 1);
  if (n <= 0) return ".";
  b[n] = '\0';
  return fs::path(b).parent_path().string();
}

std::string find_mosquitto() {
  for (const char* p : {"/usr/sbin/mosquitto", "/usr/bin/mosquitto", "/usr/local/sbin/mosquitto"}) {
    if (::access(p, X_OK) == 0) return p;
  }
  return {};
}

int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

bool port_open(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

// Every child started, stopped on every way out of main (also after an exception): a benchmark
// must never leave daemons running on a shared machine.
std::vector<pid_t> g_children;

pid_t spawn(const std::vector<std::string>& args, const std::string& log) {
  std::vector<std::string> a = args;
  std::vector<char*> argv;
  for (auto& s : a) argv.push_back(s.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  if (posix_spawn(&pid, a[0].c_str(), &fa, nullptr, argv.data(), environ) != 0) pid = -1;
  posix_spawn_file_actions_destroy(&fa);
  if (pid > 0) g_children.push_back(pid);
  return pid;
}

void stop(pid_t pid) {
  if (pid <= 0) return;
  const auto it = std::find(g_children.begin(), g_children.end(), pid);
  if (it == g_children.end()) return;  // already stopped
  g_children.erase(it);
  ::kill(pid, SIGTERM);
  for (int i = 0; i < 500; ++i) {
    if (::waitpid(pid, nullptr, WNOHANG) == pid) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
}

// CPU seconds (user + system) of a process so far, from /proc/PID/stat.
double cpu_s(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string s;
  std::getline(in, s);
  const auto rp = s.rfind(')');
  if (rp == std::string::npos) return 0.0;
  std::istringstream f(s.substr(rp + 2));
  std::string tok;
  unsigned long long ut = 0, st = 0;
  for (int i = 3; i <= 15 && f >> tok; ++i) {
    if (i == 14) ut = std::stoull(tok);
    if (i == 15) st = std::stoull(tok);
  }
  return static_cast<double>(ut + st) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

// Blocking JSON-lines client of one daemon.
class Ctl {
 public:
  bool connect(const std::string& path) {
    fd_ = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strncpy(a.sun_path, path.c_str(), sizeof a.sun_path - 1);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
      ::close(fd_);
      fd_ = -1;
      return false;
    }
    return true;
  }
  ~Ctl() {
    if (fd_ >= 0) ::close(fd_);
  }
  json call(json req) {
    req["id"] = ++id_;
    const std::string l = req.dump() + "\n";
    if (::send(fd_, l.data(), l.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(l.size())) {
      return json{{"ok", false}, {"error", "send failed"}};
    }
    for (;;) {
      const auto nl = buf_.find('\n');
      if (nl != std::string::npos) {
        json r = json::parse(buf_.substr(0, nl), nullptr, false);
        buf_.erase(0, nl + 1);
        if (r.is_discarded() || r.contains("event")) continue;
        return r;
      }
      char tmp[65536];
      const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
      if (n <= 0) return json{{"ok", false}, {"error", "connection closed"}};
      buf_.append(tmp, static_cast<std::size_t>(n));
    }
  }

 private:
  int fd_ = -1;
  long id_ = 0;
  std::string buf_;
};

struct Received {
  std::string kind;  // state position event job online bridge other
  std::string machine;
  std::int64_t latency_us = -1;
  json job;  // job summaries
};

class FleetSubscriber {
 public:
  explicit FleetSubscriber(int port) {
    mosquitto_lib_init();
    m_ = mosquitto_new("fleet-bench-subscriber", true, this);
    mosquitto_connect_callback_set(m_, [](mosquitto* m, void*, int rc) {
      if (rc == 0) mosquitto_subscribe(m, nullptr, "contourd/+/#", 1);
    });
    mosquitto_message_callback_set(m_, &FleetSubscriber::on_message);
    mosquitto_connect_async(m_, "127.0.0.1", port, 30);
    mosquitto_loop_start(m_);
  }
  ~FleetSubscriber() {
    mosquitto_disconnect(m_);
    mosquitto_loop_stop(m_, true);
    mosquitto_destroy(m_);
  }
  std::vector<Received> take() {
    std::lock_guard lk(mu_);
    return rx_;
  }
  std::size_t jobs() {
    std::lock_guard lk(mu_);
    return jobs_;
  }
  bool has_state(const std::string& machine) {
    std::lock_guard lk(mu_);
    return states_.count(machine) != 0;
  }

 private:
  static void on_message(mosquitto*, void* self, const mosquitto_message* m) {
    const std::int64_t now = contour::bridge::now_us();
    auto* s = static_cast<FleetSubscriber*>(self);
    Received r;
    const std::string topic = m->topic;
    // contourd/<id>/<kind>[/<n>]
    const auto a = topic.find('/');
    const auto b = topic.find('/', a + 1);
    if (a == std::string::npos || b == std::string::npos) return;
    r.machine = topic.substr(a + 1, b - a - 1);
    std::string rest = topic.substr(b + 1);
    r.kind = rest.rfind("job/", 0) == 0 ? "job" : rest;
    const std::string payload(static_cast<const char*>(m->payload), static_cast<std::size_t>(m->payloadlen));
    if (r.kind != "online") {
      json j = json::parse(payload, nullptr, false);
      if (!j.is_discarded()) {
        if (j.contains("ts_us") && !m->retain) r.latency_us = now - j["ts_us"].get<std::int64_t>();
        if (r.kind == "job") r.job = j;
      }
    }
    std::lock_guard lk(s->mu_);
    if (r.kind == "job") ++s->jobs_;
    if (r.kind == "state") s->states_.insert(r.machine);
    s->rx_.push_back(std::move(r));
  }

  mosquitto* m_ = nullptr;
  std::mutex mu_;
  std::vector<Received> rx_;
  std::size_t jobs_ = 0;
  std::set<std::string> states_;
};

double percentile(std::vector<std::int64_t> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5);
  return static_cast<double>(v[std::min(i, v.size() - 1)]) / 1000.0;
}

}  // namespace

int run_fleet(int argc, char** argv);

extern "C" void on_fatal_signal(int sig) {
  for (pid_t p : g_children) ::kill(p, SIGTERM);  // kill(2) is async-signal-safe
  ::_exit(128 + sig);
}

struct Reaper {
  ~Reaper() {
    while (!g_children.empty()) stop(g_children.back());
  }
};

int main(int argc, char** argv) {
  Reaper reaper;
  std::signal(SIGINT, on_fatal_signal);
  std::signal(SIGTERM, on_fatal_signal);
  try {
    return run_fleet(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contour-bridge-fleet: %s\n", e.what());
    return 1;
  }
}

int run_fleet(int argc, char** argv) {
  CLI::App app{"contour-bridge-fleet: N contourd + N contour-bridge + one broker + one subscriber"};
  int machines = 20, programs = 3;
  double position_rate = 10.0;
  bool check = false, as_json = false, without_bridges = false, rt = false;
  double state_rate = 10.0;
  std::string program = std::string(CONTOUR_SOURCE_DIR) + "/config/programs/table2.ngc";
  std::string keep;
  app.add_option("--machines", machines, "contourd instances (each with its bridge)")->check(CLI::Range(1, 200));
  app.add_option("--programs", programs, "runs of the program per machine")->check(CLI::Range(1, 1000));
  app.add_option("--program", program, "part program (RS274/NGC)");
  app.add_option("--position-rate", position_rate, "mqtt.position_rate_hz of every bridge");
  app.add_flag("--check", check, "exit 1 unless every job summary arrived");
  app.add_flag("--without-bridges", without_bridges,
               "daemons only (the loop-timing baseline to compare with)");
  app.add_flag("--rt", rt, "keep config/sim.yaml's SCHED_FIFO loop (needs the privilege)");
  app.add_option("--state-rate", state_rate, "mqtt.state_rate_hz (status reads per second)");
  app.add_flag("--json", as_json, "only the JSON summary on stdout");
  app.add_option("--keep", keep, "work directory to create and keep (logs, configs)");
  CLI11_PARSE(app, argc, argv);

  const std::string mosq = find_mosquitto();
  if (mosq.empty()) {
    std::printf("SKIPPED: the mosquitto broker is not installed (tools/deps.d/bridge.list)\n");
    return 77;
  }
  const std::string bin = exe_dir();  // build/<preset>/tools/contour-bridge
  const std::string bridge_bin = bin + "/contour-bridge";
  const std::string contourd_bin = fs::path(bin).parent_path().parent_path().string() + "/daemon/contourd";
  for (const auto& b : {bridge_bin, contourd_bin}) {
    if (::access(b.c_str(), X_OK) != 0) {
      std::fprintf(stderr, "contour-bridge-fleet: %s not built\n", b.c_str());
      return 2;
    }
  }
  fs::path dir = keep.empty() ? fs::temp_directory_path() /
                                    ("contour-fleet-" + std::to_string(::getpid()))
                              : fs::path(keep);
  fs::create_directories(dir);
  ::chmod(dir.c_str(), 0777);  // mosquitto drops to its own user when started as root
  const int port = free_port();
  std::ofstream(dir / "mosquitto.conf") << "listener " << port << " 127.0.0.1\nallow_anonymous true\n"
                                         << "persistence false\nmax_queued_messages 100000\n";
  const pid_t broker = spawn({mosq, "-c", (dir / "mosquitto.conf").string()}, (dir / "broker.log").string());
  for (int i = 0; i < 500 && !port_open(port); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  if (!port_open(port)) {
    std::fprintf(stderr, "contour-bridge-fleet: mosquitto did not start:\n%s\n",
                 slurp((dir / "broker.log").string()).c_str());
    stop(broker);
    return 1;
  }
  FleetSubscriber sub(port);

  std::string sim = slurp(std::string(CONTOUR_SOURCE_DIR) + "/config/sim.yaml");
  auto replace = [&](const std::string& a, const std::string& b) {
    const auto p = sim.find(a);
    if (p != std::string::npos) sim.replace(p, a.size(), b);
  };
  // The copies live in a temporary directory: sim.yaml's machine logic names its programs relative
  // to config/, so they become absolute.
  for (auto at = sim.find("{file: plc/"); at != std::string::npos; at = sim.find("{file: plc/", at + 1)) {
    sim.replace(at, 7, "{file: " + std::string(CONTOUR_SOURCE_DIR) + "/config/");
  }
  if (!rt) {
    replace("priority: 80", "priority: 0");  // 2N processes on a shared machine: no SCHED_FIFO
    replace("lock_memory: true", "lock_memory: false");
  }
  replace("directory: /tmp", "directory: " + dir.string());
  std::vector<pid_t> daemons, bridges;
  std::vector<std::string> socks, ids;
  for (int i = 0; i < machines; ++i) {
    char id[16];
    std::snprintf(id, sizeof id, "m%03d", i + 1);
    ids.emplace_back(id);
    const std::string cfg = (dir / (std::string(id) + ".yaml")).string();
    std::ofstream(cfg) << sim << "mqtt:\n  host: 127.0.0.1\n  port: " << port
                       << "\n  machine_id: " << id << "\n  position_rate_hz: " << position_rate
                       << "\n  state_rate_hz: " << state_rate << "\n  status_interval_s: 5\n";
    socks.push_back((dir / (std::string(id) + ".sock")).string());
    daemons.push_back(spawn({contourd_bin, "--config", cfg, "--socket", socks.back()},
                            (dir / (std::string(id) + ".contourd.log")).string()));
  }
  // Daemons up (their sockets answer and the machine is READY), then the bridges.
  const auto up_until = Clock::now() + std::chrono::seconds(120);
  for (int i = 0; i < machines; ++i) {
    bool ready = false;
    while (!ready && Clock::now() < up_until) {
      Ctl c;
      if (c.connect(socks[static_cast<std::size_t>(i)])) {
        const json r = c.call({{"cmd", "status"}});
        ready = r.value("ok", false) && r["result"]["state"] == "READY";
      }
      if (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    if (!ready) {
      std::fprintf(stderr, "contour-bridge-fleet: %s not READY\n", ids[static_cast<std::size_t>(i)].c_str());
    }
    if (without_bridges) continue;
    bridges.push_back(spawn({bridge_bin, "--config", (dir / (ids[static_cast<std::size_t>(i)] + ".yaml")).string(),
                             "--socket", socks[static_cast<std::size_t>(i)]},
                            (dir / (ids[static_cast<std::size_t>(i)] + ".bridge.log")).string()));
  }
  for (const auto& id : ids) {
    while (!without_bridges && !sub.has_state(id) && Clock::now() < up_until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  // The loops' timing counters before and after the runs (RT isolation: with and without bridges).
  auto loop_timing = [&] {
    json t = json::array();
    for (const auto& sk : socks) {
      Ctl c;
      json st;
      if (c.connect(sk)) st = c.call({{"cmd", "status"}});
      t.push_back(st.value("ok", false) ? st["result"]["timing"] : json::object());
    }
    return t;
  };
  const json timing0 = loop_timing();

  // Every machine runs the program `programs` times, each from the origin.
  const double cpu_broker0 = cpu_s(broker);
  double cpu_bridges0 = 0.0;
  for (pid_t b : bridges) cpu_bridges0 += cpu_s(b);
  const std::size_t rx0 = sub.take().size();
  const auto t0 = Clock::now();
  std::vector<json> results(static_cast<std::size_t>(machines * programs));
  std::vector<std::thread> drivers;
  std::atomic<int> failures{0};
  std::atomic<int> late_runs{0};
  for (int i = 0; i < machines; ++i) {
    drivers.emplace_back([&, i] {
      Ctl c;
      if (!c.connect(socks[static_cast<std::size_t>(i)])) {
        ++failures;
        return;
      }
      for (int k = 0; k < programs; ++k) {
        for (const char* ax : {"X", "Y", "Z"}) {
          c.call({{"cmd", "set-position"}, {"axis", ax}, {"position_mm", 0.0}});
        }
        const json r = c.call({{"cmd", "run"}, {"path", program}});
        std::uint64_t job = 0;
        if (r.value("ok", false)) {
          job = r["result"]["job"].get<std::uint64_t>();
        } else {
          // contourd waits 1 s for its loop to take `run`; on a starved machine (2N processes
          // on two cores, SCHED_OTHER) the loop may take it later: the loaded job then runs.
          const json st = c.call({{"cmd", "status"}});
          job = st.value("ok", false) ? st["result"].value("loaded_job", std::uint64_t{0}) : 0;
          std::fprintf(stderr, "%s: run: %s (then following job %llu)\n",
                       ids[static_cast<std::size_t>(i)].c_str(), r.dump().c_str(),
                       static_cast<unsigned long long>(job));
          ++late_runs;
          if (job == 0) {
            ++failures;
            return;
          }
        }
        const auto give_up = Clock::now() + std::chrono::seconds(300);
        while (Clock::now() < give_up) {
          const json st = c.call({{"cmd", "status"}});
          if (!st.value("ok", false)) break;
          const auto& s = st["result"];
          const std::string state = s["state"];
          if (s["finished_job"].get<std::uint64_t>() >= job && state != "RUNNING" && state != "HOLD") break;
          if (state == "FAULT" || state == "ESTOP") break;
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        const json res = c.call({{"cmd", "result"}, {"job", job}});
        if (res.value("ok", false)) results[static_cast<std::size_t>(i * programs + k)] = res["result"];
      }
    });
  }
  for (auto& t : drivers) t.join();
  const auto t_runs = Clock::now();
  const json timing1 = loop_timing();
  std::uint64_t overruns = 0, cycles = 0;
  double lateness_max_us = 0.0, lateness_p99_us = 0.0;
  for (std::size_t i = 0; i < socks.size(); ++i) {
    overruns += timing1[i].value("overruns", 0ULL) - timing0[i].value("overruns", 0ULL);
    cycles += timing1[i].value("cycles", 0ULL) - timing0[i].value("cycles", 0ULL);
    lateness_max_us = std::max(lateness_max_us, timing1[i].value("lateness_max_us", 0.0));
    lateness_p99_us = std::max(lateness_p99_us, timing1[i].value("lateness_p99_us", 0.0));
  }
  const std::size_t expected = static_cast<std::size_t>(machines * programs);
  const auto until = Clock::now() + std::chrono::seconds(60);
  while (!without_bridges && sub.jobs() < expected && Clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const auto t1 = Clock::now();
  const double cpu_broker = cpu_s(broker) - cpu_broker0;
  double cpu_bridges = 0.0;
  for (pid_t b : bridges) cpu_bridges += cpu_s(b);
  cpu_bridges -= cpu_bridges0;

  const auto rx = sub.take();
  const double window_s = std::chrono::duration<double>(t_runs - t0).count();
  std::map<std::string, std::size_t> count;
  std::map<std::string, std::vector<std::int64_t>> lat;
  std::map<std::string, std::map<std::uint64_t, json>> jobs;  // machine -> job -> summary
  for (std::size_t i = rx0; i < rx.size(); ++i) {
    const auto& r = rx[i];
    ++count[r.kind];
    if (r.latency_us >= 0) lat[r.kind].push_back(r.latency_us);
    if (r.kind == "job" && r.job.is_object()) jobs[r.machine][r.job.value("job", 0ULL)] = r.job;
  }
  // Every machine's summaries, with the figures the daemon gave its operator.
  int missing = 0, mismatched = 0;
  for (int i = 0; i < machines; ++i) {
    for (int k = 0; k < programs; ++k) {
      const json& res = results[static_cast<std::size_t>(i * programs + k)];
      const auto job = res.is_object() ? res.value("job", 0ULL) : 0ULL;
      auto& mj = jobs[ids[static_cast<std::size_t>(i)]];
      auto it = mj.find(job);
      if (without_bridges) continue;
      if (job == 0 || it == mj.end()) {
        ++missing;
        continue;
      }
      for (const char* key : {"max_contour_error_um", "rms_contour_error_um", "duration_s", "samples", "completed"}) {
        if (it->second[key] != res[key]) ++mismatched;
      }
    }
  }
  std::size_t total = 0;
  for (const auto& [k, n] : count) total += n;
  json out{{"machines", machines},
           {"programs_per_machine", programs},
           {"position_rate_hz", position_rate},
           {"window_s", window_s},
           {"messages", total},
           {"messages_per_s", static_cast<double>(total) / window_s},
           {"job_summaries_expected", expected},
           {"job_summaries_missing", missing},
           {"job_summaries_mismatched", mismatched},
           {"run_failures", failures.load()},
           {"runs_taken_late", late_runs.load()},
           {"broker_cpu_s", cpu_broker},
           {"bridges_cpu_s", cpu_bridges},
           {"drain_s", std::chrono::duration<double>(t1 - t_runs).count()},
           {"bridges", !without_bridges},
           {"loop", {{"cycles", cycles},
                     {"overruns", overruns},
                     {"lateness_p99_us_max", lateness_p99_us},
                     {"lateness_max_us", lateness_max_us}}}};
  for (const auto& [k, n] : count) {
    json t{{"messages", n}, {"per_s", static_cast<double>(n) / window_s},
           {"per_machine_per_s", static_cast<double>(n) / window_s / machines}};
    if (!lat[k].empty()) {
      t["latency_ms"] = {{"p50", percentile(lat[k], 0.5)}, {"p95", percentile(lat[k], 0.95)},
                         {"p99", percentile(lat[k], 0.99)}, {"max", percentile(lat[k], 1.0)}};
    }
    out["topics"][k] = t;
  }
  if (!as_json) {
    std::printf("fleet: %d machines x %d runs of %s, broker 127.0.0.1:%d, window %.1f s\n", machines,
                programs, fs::path(program).filename().c_str(), port, window_s);
    std::printf("%-10s %9s %9s %12s %9s %9s %9s %9s\n", "topic", "messages", "msg/s", "msg/s/machine",
                "p50 ms", "p95 ms", "p99 ms", "max ms");
    for (const auto& [k, t] : out["topics"].items()) {
      const bool l = t.contains("latency_ms");
      std::printf("%-10s %9zu %9.1f %12.2f", k.c_str(), t["messages"].get<std::size_t>(),
                  t["per_s"].get<double>(), t["per_machine_per_s"].get<double>());
      if (l) {
        std::printf(" %9.2f %9.2f %9.2f %9.2f\n", t["latency_ms"]["p50"].get<double>(),
                    t["latency_ms"]["p95"].get<double>(), t["latency_ms"]["p99"].get<double>(),
                    t["latency_ms"]["max"].get<double>());
      } else {
        std::printf("\n");
      }
    }
    std::printf("loop: %llu cycles, %llu overruns in the window; lateness p99 %.0f us, max %.0f us "
                "(worst daemon, since its start)\n",
                static_cast<unsigned long long>(cycles), static_cast<unsigned long long>(overruns),
                lateness_p99_us, lateness_max_us);
    std::printf("total %zu messages, %.1f msg/s; job summaries %zu expected, %d missing, %d with other "
                "figures; broker CPU %.2f s, bridges CPU %.2f s\n",
                total, static_cast<double>(total) / window_s, expected, missing, mismatched, cpu_broker,
                cpu_bridges);
  }
  std::printf("%s\n", out.dump().c_str());
  for (pid_t b : bridges) stop(b);
  for (pid_t d : daemons) stop(d);
  stop(broker);
  if (keep.empty()) {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  if (check && (missing > 0 || mismatched > 0 || failures.load() > 0)) return 1;
  return 0;
}
