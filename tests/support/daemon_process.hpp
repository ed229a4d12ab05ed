#pragma once
// Test support for the tests that run the real contourd: a Unix-socket connect, file slurp, and
// DaemonProcess = contourd as a child process (stderr = its log file, stdout = /dev/null) with a
// JSON-lines client on its command socket. Header-only; sim and hil tests include it.
//
// Every wait here is a bounded poll: a bound on a failure, never a timing assertion.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

extern char** environ;

namespace contour::test {

inline std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Connected AF_UNIX stream socket, or -1.
inline int connect_unix(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  sockaddr_un a{};
  a.sun_family = AF_UNIX;
  std::strncpy(a.sun_path, path.c_str(), sizeof(a.sun_path) - 1);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

inline const std::string& contourd_binary() {
  static const std::string bin = std::string(CONTOUR_BINARY_DIR) + "/daemon/contourd";
  return bin;
}

class DaemonProcess {
 public:
  using json = nlohmann::json;
  struct Options {
    std::string config;                   // --config
    std::vector<std::string> extra_args;  // after --config/--socket
    int connect_polls = 1000;             // x 10 ms for the socket to appear
    int ready_polls = 500;                // x 10 ms for state READY (0: do not wait)
  };

  // Runs `contourd --config <config> --socket <dir>/c.sock` in a fresh temporary directory.
  DaemonProcess(const std::string& tag, Options opt) {
    namespace fs = std::filesystem;
    dir_ = fs::temp_directory_path() /
           ("contourd_test_" + tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(seq()++));
    fs::create_directories(dir_);
    sock_ = (dir_ / "c.sock").string();
    log_ = (dir_ / "d.log").string();
    std::vector<std::string> args{contourd_binary(), "--config", opt.config, "--socket", sock_};
    args.insert(args.end(), opt.extra_args.begin(), opt.extra_args.end());
    std::vector<char*> argv;
    for (auto& s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    // The daemon's state directory (program.var_file of config/sim.yaml: ${STATE_DIRECTORY}) is
    // this test's own directory: no test sees offsets another test or a developer left behind.
    std::vector<std::string> env_s;
    for (char** e = environ; *e != nullptr; ++e) {
      if (std::string_view(*e).rfind("STATE_DIRECTORY=", 0) != 0) env_s.emplace_back(*e);
    }
    env_s.push_back("STATE_DIRECTORY=" + dir_.string());
    std::vector<char*> envp;
    for (auto& e : env_s) envp.push_back(e.data());
    envp.push_back(nullptr);
    const int rc = posix_spawn(&pid_, contourd_binary().c_str(), &fa, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&fa);
    EXPECT_EQ(rc, 0) << "cannot start " << contourd_binary();
    if (rc != 0) {
      pid_ = -1;
      return;
    }
    for (int i = 0; i < opt.connect_polls && fd_ < 0; ++i) {
      int st = 0;
      if (::waitpid(pid_, &st, WNOHANG) == pid_) {  // exited during start-up: see log()
        exited_ = true;
        break;
      }
      fd_ = connect_unix(sock_);
      if (fd_ < 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (fd_ < 0) return;
    for (int i = 0; i < opt.ready_polls && state() != "READY"; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;

  // SIGTERM (controlled stop), then SIGKILL if it has not exited within 10 s.
  ~DaemonProcess() {
    if (fd_ >= 0) ::close(fd_);
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGTERM);
      int st = 0;
      for (int i = 0; i < 1000 && ::waitpid(pid_, &st, WNOHANG) == 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  [[nodiscard]] bool connected() const { return fd_ >= 0; }

  // One request, its reply (subscription events in between are skipped).
  json call(const json& req) {
    const std::string l = req.dump() + "\n";
    if (::send(fd_, l.data(), l.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(l.size())) {
      return json{{"ok", false}, {"error", "send failed"}};
    }
    for (;;) {
      const auto nl = buf_.find('\n');
      if (nl != std::string::npos) {
        json r = json::parse(buf_.substr(0, nl));
        buf_.erase(0, nl + 1);
        if (r.contains("event")) continue;
        return r;
      }
      char tmp[8192];
      const ssize_t n = ::recv(fd_, tmp, sizeof(tmp), 0);
      if (n <= 0) return json{{"ok", false}, {"error", "connection closed"}};
      buf_.append(tmp, static_cast<std::size_t>(n));
    }
  }
  // call() that must succeed (a test failure with the daemon's log otherwise); the result.
  json ok(const json& req) {
    json r = call(req);
    EXPECT_TRUE(r.value("ok", false)) << req.dump() << " -> " << r.dump() << "\n" << log();
    return r.value("result", json::object());
  }
  std::string state() {
    const json r = call({{"cmd", "status"}});
    return r.value("ok", false) ? r["result"]["state"].get<std::string>() : "?";
  }
  // Polls status until pred(status) holds or max_polls x 10 ms; returns the last status.
  template <typename P>
  json wait_status(P pred, int max_polls = 6000) {
    json st;
    for (int i = 0; i < max_polls; ++i) {
      st = ok({{"cmd", "status"}});
      if (pred(st)) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return st;
  }
  // Waits until `job` has finished and the machine is neither RUNNING nor HOLD; its result.
  json wait_finished(std::uint64_t job, int max_polls = 12000) {
    wait_status(
        [&](const json& st) {
          return st.value("finished_job", std::uint64_t{0}) >= job && st["state"] != "RUNNING" &&
                 st["state"] != "HOLD";
        },
        max_polls);
    return ok({{"cmd", "result"}, {"job", job}});
  }
  int terminate_and_wait(int sig) {
    ::kill(pid_, sig);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    exited_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  void signal(int sig) const { ::kill(pid_, sig); }
  [[nodiscard]] pid_t pid() const { return pid_; }
  [[nodiscard]] const std::string& sock() const { return sock_; }
  [[nodiscard]] const std::filesystem::path& dir() const { return dir_; }
  [[nodiscard]] std::string log() const { return slurp(log_); }

 private:
  static int& seq() {
    static int n = 0;
    return n;
  }
  std::filesystem::path dir_;
  std::string sock_, log_, buf_;
  pid_t pid_ = -1;
  int fd_ = -1;
  bool exited_ = false;
};

}  // namespace contour::test
