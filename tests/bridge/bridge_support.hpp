#pragma once
// Test support for contour-bridge's tests with the real engines: a mosquitto broker started by the
// test on a free loopback port (never a system broker), contour-bridge and contourctl as child
// processes, and an MQTT subscriber (libmosquitto, its own network thread) that records every
// message with its arrival time. Every wait is a bounded poll: a bound on failure, never a
// timing assertion.
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <mosquitto.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"
#include "tools/contour-bridge/payloads.hpp"

extern char** environ;

namespace contour::test::bridge {

using nlohmann::json;
using contour::test::slurp;

// DaemonProcess options for a config file.
inline DaemonProcess::Options daemon_options(const std::string& config) {
  DaemonProcess::Options o;
  o.config = config;
  return o;
}

// The broker binary (Debian installs it in /usr/sbin, not on a normal user's PATH).
inline std::string mosquitto_binary() {
  for (const char* p : {"/usr/sbin/mosquitto", "/usr/bin/mosquitto", "/usr/local/sbin/mosquitto"}) {
    if (::access(p, X_OK) == 0) return p;
  }
  return {};
}

// Exit 77 with the reason when the broker is missing: ctest reports the test as skipped.
inline void require_mosquitto() {
  if (mosquitto_binary().empty()) {
    std::printf("SKIPPED: the mosquitto broker is not installed (Debian package mosquitto; "
                "tools/deps.sh installs it from tools/deps.d/bridge.list)\n");
    std::fflush(stdout);
    std::_Exit(77);
  }
}

inline std::string bin(const std::string& rel) { return std::string(CONTOUR_BINARY_DIR) + "/" + rel; }

// A TCP port on 127.0.0.1 that was free a moment ago.
inline int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

inline bool port_open(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

template <typename P>
bool wait_until(P pred, std::chrono::milliseconds bound, std::chrono::milliseconds step = std::chrono::milliseconds(20)) {
  const auto until = std::chrono::steady_clock::now() + bound;
  while (std::chrono::steady_clock::now() < until) {
    if (pred()) return true;
    std::this_thread::sleep_for(step);
  }
  return pred();
}

// A child process with stdout and stderr into files.
class Child {
 public:
  Child() = default;
  Child(const std::vector<std::string>& args, const std::string& out, const std::string& err)
      : out_(out), err_(err) {
    std::vector<std::string> a = args;
    std::vector<char*> argv;
    for (auto& s : a) argv.push_back(s.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int rc = posix_spawn(&pid_, a[0].c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) pid_ = -1;
  }
  Child(Child&& o) noexcept { *this = std::move(o); }
  Child& operator=(Child&& o) noexcept {
    std::swap(pid_, o.pid_);
    std::swap(out_, o.out_);
    std::swap(err_, o.err_);
    std::swap(status_, o.status_);
    return *this;
  }
  ~Child() { stop(SIGTERM); }

  [[nodiscard]] pid_t pid() const { return pid_; }
  [[nodiscard]] bool running() {
    if (pid_ <= 0) return false;
    int st = 0;
    if (::waitpid(pid_, &st, WNOHANG) == pid_) {
      status_ = st;
      pid_ = -pid_;
      return false;
    }
    return true;
  }
  // Exit code (128 + signal when killed), waiting at most `bound`; -1 when still running.
  int wait(std::chrono::milliseconds bound) {
    if (!wait_until([&] { return !running(); }, bound, std::chrono::milliseconds(10))) return -1;
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : 128 + WTERMSIG(status_);
  }
  void signal(int sig) const {
    if (pid_ > 0) ::kill(pid_, sig);
  }
  // sig, then SIGKILL after 10 s.
  int stop(int sig) {
    if (pid_ <= 0) return pid_ == 0 ? -1 : (WIFEXITED(status_) ? WEXITSTATUS(status_) : 128 + WTERMSIG(status_));
    ::kill(pid_, sig);
    int rc = wait(std::chrono::seconds(10));
    if (rc < 0) {
      ::kill(pid_, SIGKILL);
      rc = wait(std::chrono::seconds(10));
    }
    return rc;
  }
  [[nodiscard]] std::string out() const { return slurp(out_); }
  [[nodiscard]] std::string err() const { return slurp(err_); }

 private:
  pid_t pid_ = -1;
  std::string out_, err_;
  int status_ = 0;
};

// mosquitto on 127.0.0.1:<port> with the given extra configuration lines.
class Broker {
 public:
  Broker(const std::filesystem::path& dir, int port, std::string extra = "")
      : dir_(dir), port_(port), extra_(std::move(extra)) {
    start();
  }
  void start() {
    const auto conf = dir_ / "mosquitto.conf";
    std::ofstream(conf) << "listener " << port_ << " 127.0.0.1\n"
                        << (extra_.find("allow_anonymous") == std::string::npos ? "allow_anonymous true\n" : "")
                        << (extra_.find("persistence") == std::string::npos ? "persistence false\n" : "")
                        << extra_;
    child_ = Child({mosquitto_binary(), "-c", conf.string()}, (dir_ / "broker.out").string(),
                   (dir_ / "broker.log").string());
    const bool up = wait_until([&] { return port_open(port_) || !child_.running(); },
                               std::chrono::seconds(10));
    EXPECT_TRUE(up && child_.running()) << "mosquitto did not start:\n" << log();
  }
  void kill(int sig) { child_.stop(sig); }
  [[nodiscard]] int port() const { return port_; }
  [[nodiscard]] std::string log() const { return slurp((dir_ / "broker.log").string()); }

 private:
  std::filesystem::path dir_;
  int port_;
  std::string extra_;
  Child child_;
};

struct Message {
  std::string topic;
  std::string payload;
  bool retained = false;
  std::int64_t recv_us = 0;
};

// An MQTT subscriber with its own network thread (libmosquitto loop_start); it reconnects by
// itself after a broker restart.
class Subscriber {
 public:
  struct Options {
    std::string client_id;
    bool clean_session = true;
    int qos = 1;
    std::string username, password, ca_file, cert_file, key_file;
  };

  Subscriber(int port, std::vector<std::string> topics, Options opt)
      : topics_(std::move(topics)), opt_(std::move(opt)) {
    mosquitto_lib_init();
    m_ = mosquitto_new(opt_.client_id.empty() ? nullptr : opt_.client_id.c_str(),
                       opt_.clean_session, this);
    mosquitto_connect_callback_set(m_, &Subscriber::on_connect);
    mosquitto_message_callback_set(m_, &Subscriber::on_message);
    mosquitto_subscribe_callback_set(m_, &Subscriber::on_subscribe);
    mosquitto_reconnect_delay_set(m_, 1, 1, false);
    if (!opt_.username.empty()) {
      mosquitto_username_pw_set(m_, opt_.username.c_str(), opt_.password.c_str());
    }
    if (!opt_.ca_file.empty()) {
      mosquitto_tls_set(m_, opt_.ca_file.c_str(), nullptr,
                        opt_.cert_file.empty() ? nullptr : opt_.cert_file.c_str(),
                        opt_.key_file.empty() ? nullptr : opt_.key_file.c_str(), nullptr);
    }
    mosquitto_connect_async(m_, "127.0.0.1", port, 10);
    mosquitto_loop_start(m_);
  }
  ~Subscriber() {
    mosquitto_disconnect(m_);
    mosquitto_loop_stop(m_, true);
    mosquitto_destroy(m_);
  }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;

  // Waits until subscribed (SUBACK) at least `n` times (a reconnect subscribes again).
  bool wait_subscribed(int n = 1, std::chrono::milliseconds bound = std::chrono::seconds(20)) {
    std::unique_lock lk(mu_);
    return cv_.wait_for(lk, bound, [&] { return subacks_ >= n; });
  }
  std::vector<Message> messages() {
    std::lock_guard lk(mu_);
    return msgs_;
  }
  std::vector<Message> on(const std::string& topic) {
    std::vector<Message> v;
    for (auto& m : messages()) {
      if (m.topic == topic) v.push_back(m);
    }
    return v;
  }
  // Waits until pred(messages) holds.
  bool wait_for(const std::function<bool(const std::vector<Message>&)>& pred,
                std::chrono::milliseconds bound) {
    std::unique_lock lk(mu_);
    return cv_.wait_for(lk, bound, [&] { return pred(msgs_); });
  }
  bool wait_topic(const std::string& topic, std::chrono::milliseconds bound,
                  const std::function<bool(const json&)>& pred = nullptr) {
    return wait_for(
        [&](const std::vector<Message>& v) {
          for (const auto& m : v) {
            if (m.topic != topic) continue;
            if (!pred) return true;
            const json j = json::parse(m.payload, nullptr, false);
            if (!j.is_discarded() && pred(j)) return true;
          }
          return false;
        },
        bound);
  }
  void publish(const std::string& topic, const std::string& payload, int qos = 1) {
    mosquitto_publish(m_, nullptr, topic.c_str(), static_cast<int>(payload.size()), payload.data(),
                      qos, false);
  }
  int connects() {
    std::lock_guard lk(mu_);
    return connects_;
  }

 private:
  static void on_connect(mosquitto* m, void* self, int rc) {
    auto* s = static_cast<Subscriber*>(self);
    if (rc != 0) return;
    {
      std::lock_guard lk(s->mu_);
      ++s->connects_;
    }
    for (const auto& t : s->topics_) mosquitto_subscribe(m, nullptr, t.c_str(), s->opt_.qos);
  }
  static void on_subscribe(mosquitto*, void* self, int, int, const int*) {
    auto* s = static_cast<Subscriber*>(self);
    std::lock_guard lk(s->mu_);
    ++s->subacks_;
    s->cv_.notify_all();
  }
  static void on_message(mosquitto*, void* self, const mosquitto_message* m) {
    auto* s = static_cast<Subscriber*>(self);
    Message msg;
    msg.recv_us = contour::bridge::now_us();
    msg.topic = m->topic;
    msg.payload.assign(static_cast<const char*>(m->payload), static_cast<std::size_t>(m->payloadlen));
    msg.retained = m->retain;
    std::lock_guard lk(s->mu_);
    s->msgs_.push_back(std::move(msg));
    s->cv_.notify_all();
  }

  std::vector<std::string> topics_;
  Options opt_;
  mosquitto* m_ = nullptr;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<Message> msgs_;
  int subacks_ = 0;
  int connects_ = 0;
};

// A scratch directory removed at the end of the test.
class TempDir {
 public:
  explicit TempDir(const std::string& tag) {
    static int n = 0;
    path_ = std::filesystem::temp_directory_path() /
            ("bridge_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
    std::filesystem::create_directories(path_);
    // Started as root, mosquitto runs as user `mosquitto`: it must be able to write its
    // persistence file here and read the test's certificates.
    ::chmod(path_.c_str(), 0777);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] std::string operator/(const std::string& f) const { return (path_ / f).string(); }

 private:
  std::filesystem::path path_;
};

// config/sim.yaml as a non-root developer or CI runs it (SCHED_OTHER, no memory lock: the sim bus
// is in lockstep with the loop, its figures do not depend on timing), plus `extra` sections.
inline std::string sim_config(const std::string& extra) {
  std::string y = contour::test::sim_yaml();
  auto replace = [&](const std::string& a, const std::string& b) {
    const auto p = y.find(a);
    if (p != std::string::npos) y.replace(p, a.size(), b);
  };
  replace("priority: 80", "priority: 0");
  replace("lock_memory: true", "lock_memory: false");
  return y + extra;
}

inline std::string write_file(const std::string& path, const std::string& text, mode_t mode = 0644) {
  std::ofstream(path) << text;
  ::chmod(path.c_str(), mode);
  return path;
}

// `contourctl --json run PROGRAM --wait` on `sock`: the JSON object it prints last.
inline json contourctl_run_wait(const std::string& sock, const std::string& program,
                                const std::string& dir, const std::string& tag) {
  Child c({bin("tools/contourctl"), "--socket", sock, "--json", "run", program, "--wait",
           "--timeout", "120", "--quiet"},
          dir + "/ctl_" + tag + ".out", dir + "/ctl_" + tag + ".err");
  const int rc = c.wait(std::chrono::seconds(150));
  EXPECT_EQ(rc, 0) << c.err();
  std::istringstream in(c.out());
  std::string line, last;
  while (std::getline(in, line)) {
    if (!line.empty()) last = line;
  }
  json j = json::parse(last, nullptr, false);
  EXPECT_FALSE(j.is_discarded()) << "contourctl printed: " << c.out();
  return j;
}

}  // namespace contour::test::bridge
