// "The operator can always stop the machine" (issue 17), against the built contourd on the sim bus:
// - 64 silent clients plus a slow-loris writer hold the socket; a new connection's `estop` is
//   applied within 100 ms of wall time (the one wall-clock assertion the issue asks for), and the
//   daemon's log and `events` subscription name whom it evicted; `contourctl hold` gets through
//   too;
// - with a short socket.idle_timeout_s the silent and the slow-loris clients are dropped and
//   logged; socket.max_requests_per_s refuses a burst but never estop; counters in
//   status.counters.socket;
// - SIGUSR1 = E-stop and SIGUSR2 = hold (out of band), logged with the sender's pid.
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"
#include "tests/support/run_cmd.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";
// 4 x 100 mm at 3 m/min: 8 s of motion, long enough to stop mid-path.
const std::string kSquare = "G21 G90 G64 P0.02\nG01 X100 F3000\nG01 Y100\nG01 X0\nG01 Y0\nM2\n";

void send_all(int fd, const std::string& s) {
  std::size_t off = 0;
  while (off < s.size()) {
    const ssize_t n = ::send(fd, s.data() + off, s.size() - off, MSG_NOSIGNAL);
    if (n <= 0) return;
    off += static_cast<std::size_t>(n);
  }
}

// One line from fd, waiting up to max_ms in total (bound on a failure, not a timing check).
std::string read_line(int fd, int max_ms = 5000) {
  std::string out;
  const auto until = Clock::now() + std::chrono::milliseconds(max_ms);
  char ch = 0;
  while (Clock::now() < until) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) != 1) continue;
    if (::read(fd, &ch, 1) != 1) return out + "<eof>";
    if (ch == '\n') return out;
    out.push_back(ch);
  }
  return out + "<timeout>";
}

// A request on a connection of its own (the way contourctl talks), its reply.
json call_fresh(const std::string& sock, const json& req) {
  const int fd = contour::test::connect_unix(sock);
  if (fd < 0) return {{"ok", false}, {"error", "cannot connect"}};
  send_all(fd, req.dump() + "\n");
  const std::string l = read_line(fd);
  ::close(fd);
  json r = json::parse(l, nullptr, false);
  if (r.is_discarded()) return {{"ok", false}, {"error", "no reply: " + l}};
  return r;
}

json status_fresh(const std::string& sock) {
  const json r = call_fresh(sock, {{"cmd", "status"}});
  return r.value("result", json::object());
}

// Polls status (fresh connections) until pred holds, up to max_polls x 10 ms.
template <typename P>
json wait_fresh(const std::string& sock, P pred, int max_polls = 1000) {
  json st;
  for (int i = 0; i < max_polls; ++i) {
    st = status_fresh(sock);
    if (!st.empty() && pred(st)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return st;
}

using contour::test::run_cmd;

// sim.yaml with extra `socket:` keys, in the test's own directory.
std::string sim_config_with_socket(const std::string& tag, const std::string& keys) {
  std::string text = contour::test::sim_yaml();
  const std::size_t at = text.find("\nsocket:\n");
  EXPECT_NE(at, std::string::npos);
  text.insert(at + 9, keys);
  const fs::path p = fs::temp_directory_path() /
                     ("contourd_sock_" + tag + "_" + std::to_string(::getpid()) + ".yaml");
  std::ofstream(p) << text;
  return p.string();
}

// A client that sends an unfinished request one byte at a time until told to stop (or closed).
class SlowLoris {
 public:
  explicit SlowLoris(const std::string& sock) : fd_(contour::test::connect_unix(sock)) {
    thread_ = std::thread([this] {
      const std::string partial = R"({"cmd":"status","pad":")";
      for (std::size_t k = 0; !stop_; ++k) {
        const char c = k < partial.size() ? partial[k] : 'x';
        if (::send(fd_, &c, 1, MSG_NOSIGNAL) != 1) {
          closed_ = true;
          return;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    });
  }
  ~SlowLoris() {
    stop_ = true;
    thread_.join();
    if (fd_ >= 0) ::close(fd_);
  }
  SlowLoris(const SlowLoris&) = delete;
  SlowLoris& operator=(const SlowLoris&) = delete;
  [[nodiscard]] bool connected() const { return fd_ >= 0; }
  [[nodiscard]] bool closed() const { return closed_; }

 private:
  int fd_;
  std::atomic<bool> stop_{false}, closed_{false};
  std::thread thread_;
};

std::vector<int> silent_clients(const std::string& sock, int n) {
  std::vector<int> v;
  for (int i = 0; i < n; ++i) {
    const int fd = contour::test::connect_unix(sock);
    EXPECT_GE(fd, 0) << "silent client " << i;
    if (fd >= 0) v.push_back(fd);
  }
  return v;
}

TEST(SocketLockout, SilentClientsAndASlowLorisCannotKeepEstopOut) {
  contour::test::DaemonProcess d("lockout", {kSrc + "/config/sim.yaml", {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  // For comparison (printed, not asserted): the same estop on a quiet socket.
  d.ok({{"cmd", "run"}, {"program", kSquare}, {"name", "square.ngc"}});
  {
    const auto q0 = Clock::now();
    const json q = call_fresh(d.sock(), {{"cmd", "estop"}});
    const double quiet_ms = std::chrono::duration<double, std::milli>(Clock::now() - q0).count();
    ASSERT_EQ(q["ok"], true) << q.dump();
    std::printf("estop on a quiet socket: %.1f ms\n", quiet_ms);
    d.ok({{"cmd", "reset"}});
  }
  d.ok({{"cmd", "load"}, {"program", kSquare}, {"name", "square.ngc"}});
  d.ok({{"cmd", "run"}});
  // An events subscriber on its own connection: it sees what the server did to whom.
  const int ev = contour::test::connect_unix(d.sock());
  ASSERT_GE(ev, 0);
  send_all(ev, R"({"cmd":"subscribe","topic":"events"})" "\n");
  ASSERT_EQ(json::parse(read_line(ev))["ok"], true);

  SlowLoris loris(d.sock());
  ASSERT_TRUE(loris.connected());
  std::vector<int> silent = silent_clients(d.sock(), 64);
  ASSERT_EQ(silent.size(), 64u);

  // `estop` the way contourctl sends it: connect, one line, wait for the reply.
  const auto t0 = Clock::now();
  const int fd = contour::test::connect_unix(d.sock());
  ASSERT_GE(fd, 0);
  send_all(fd, R"({"id":1,"cmd":"estop"})" "\n");
  const std::string line = read_line(fd);
  const double estop_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  ::close(fd);
  const json r = json::parse(line, nullptr, false);
  ASSERT_TRUE(r.is_object()) << line << "\n" << d.log();
  ASSERT_EQ(r["ok"], true) << line;
  EXPECT_EQ(r["result"]["state"], "ESTOP");  // the reply comes once the loop is in ESTOP
  std::printf("estop under 64 silent clients + slow loris: applied and answered in %.1f ms\n",
              estop_ms);
  EXPECT_LT(estop_ms, 100.0) << "issue 17: estop within 100 ms of wall time";

  // The subscriber saw evictions naming the clients (this process's pid) and the rule.
  bool seen = false;
  for (int i = 0; i < 200 && !seen; ++i) {
    const std::string l = read_line(ev, 50);
    if (l.find("<timeout>") != std::string::npos) continue;
    const json e = json::parse(l, nullptr, false);
    if (e.is_object() && e.value("event", "") == "socket" &&
        e.value("action", "") == "evicted_idle") {
      EXPECT_EQ(e["client"]["pid"], ::getpid()) << l;
      EXPECT_NE(e["text"].get<std::string>().find("table full"), std::string::npos) << l;
      seen = true;
    }
  }
  EXPECT_TRUE(seen) << "no eviction event\n" << d.log();
  const std::string log = d.log();
  EXPECT_NE(log.find("evicted client"), std::string::npos) << log;
  EXPECT_NE(log.find("(pid " + std::to_string(::getpid())), std::string::npos) << log;
  EXPECT_NE(log.find("E-STOP from socket client pid " + std::to_string(::getpid())),
            std::string::npos)
      << log;
  const json st = status_fresh(d.sock());
  ASSERT_FALSE(st.empty());
  EXPECT_EQ(st["state"], "ESTOP");
  const json& sc = st["counters"]["socket"];
  EXPECT_GE(sc["evicted_idle"].get<std::uint64_t>(), 50u) << sc.dump();
  EXPECT_LE(sc["clients"].get<std::uint64_t>(), 16u) << sc.dump();

  // `contourctl hold` gets through a fresh lockout as well.
  ASSERT_EQ(call_fresh(d.sock(), {{"cmd", "reset"}})["ok"], true);
  ASSERT_EQ(call_fresh(d.sock(), {{"cmd", "run"}, {"program", kSquare}, {"name", "sq2.ngc"}})["ok"],
            true);
  for (int s : silent) ::close(s);
  silent = silent_clients(d.sock(), 64);
  std::string out;
  const auto h0 = Clock::now();
  const int rc = run_cmd(kCtl + " --socket " + d.sock() + " hold", &out);
  const double hold_ms = std::chrono::duration<double, std::milli>(Clock::now() - h0).count();
  EXPECT_EQ(rc, 0) << out;
  std::printf("contourctl hold under 64 silent clients + slow loris: %.1f ms (process included)\n",
              hold_ms);
  EXPECT_EQ(status_fresh(d.sock())["state"], "HOLD");
  out.clear();
  EXPECT_EQ(run_cmd(kCtl + " --socket " + d.sock() + " stop", &out), 0) << out;
  for (int s : silent) ::close(s);
  ::close(ev);
}

TEST(SocketLockout, IdleAndSlowLorisClientsAreDroppedAndARequestBurstIsRateLimited) {
  const std::string cfg =
      sim_config_with_socket("idle", "  idle_timeout_s: 0.5\n  max_requests_per_s: 20\n");
  contour::test::DaemonProcess d("idle", {cfg, {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const int silent = contour::test::connect_unix(d.sock());
  ASSERT_GE(silent, 0);
  {
    SlowLoris loris(d.sock());
    ASSERT_TRUE(loris.connected());
    bool silent_closed = false;
    for (int i = 0; i < 1000 && !(silent_closed && loris.closed()); ++i) {  // bounded: 10 s
      pollfd p{silent, POLLIN, 0};
      if (!silent_closed && ::poll(&p, 1, 0) == 1) {
        char b;
        silent_closed = ::recv(silent, &b, 1, MSG_DONTWAIT) <= 0;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_TRUE(silent_closed) << d.log();
    EXPECT_TRUE(loris.closed()) << d.log();
  }
  ::close(silent);
  std::string log = d.log();
  EXPECT_NE(log.find("no complete request"), std::string::npos) << log;
  EXPECT_NE(log.find("unfinished line"), std::string::npos) << log;  // the slow loris
  EXPECT_NE(log.find("socket.idle_timeout_s 0.5 s"), std::string::npos) << log;

  // A burst of 60 requests: the ones over 20/s are refused; estop at its end is not.
  const int fd = contour::test::connect_unix(d.sock());
  ASSERT_GE(fd, 0);
  std::string burst;
  for (int i = 0; i < 60; ++i) {
    burst += R"({"id":)" + std::to_string(i) + R"(,"cmd":"status"})" "\n";
  }
  burst += R"({"id":"e","cmd":"estop"})" "\n";
  send_all(fd, burst);
  int limited = 0;
  json last;
  for (int i = 0; i < 61; ++i) {
    const std::string l = read_line(fd);
    last = json::parse(l, nullptr, false);
    ASSERT_TRUE(last.is_object()) << i << ": " << l;
    if (!last.value("ok", false)) {
      EXPECT_NE(last["error"].get<std::string>().find("rate limited"), std::string::npos) << l;
      ++limited;
    }
  }
  ::close(fd);
  EXPECT_EQ(last["id"], "e");
  EXPECT_EQ(last["ok"], true) << last.dump();
  EXPECT_EQ(last["result"]["state"], "ESTOP");
  EXPECT_GE(limited, 20);
  const json st = status_fresh(d.sock());
  const json& sc = st["counters"]["socket"];
  EXPECT_GE(sc["rate_limited"].get<std::uint64_t>(), static_cast<std::uint64_t>(limited));
  EXPECT_GE(sc["dropped_idle"].get<std::uint64_t>(), 2u) << sc.dump();
  EXPECT_EQ(sc["dropped_clients"].get<std::uint64_t>(),
            sc["dropped_idle"].get<std::uint64_t>() + sc["evicted_idle"].get<std::uint64_t>() +
                sc["oversize_buffer"].get<std::uint64_t>());
  log = d.log();
  EXPECT_NE(log.find("rate limited client"), std::string::npos) << log;
  std::error_code ec;
  fs::remove(cfg, ec);
}

TEST(SocketLockout, SigusrOneIsEstopAndSigusrTwoIsHold) {
  contour::test::DaemonProcess d("sigusr", {kSrc + "/config/sim.yaml", {}, 1000, 500});
  ASSERT_TRUE(d.connected()) << d.log();
  const std::string me = "from pid " + std::to_string(::getpid());
  // SIGUSR2 with nothing running: logged, ignored.
  d.signal(SIGUSR2);
  for (int i = 0; i < 500 && d.log().find("ignored: nothing running") == std::string::npos; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_NE(d.log().find("hold by SIGUSR2 " + me), std::string::npos) << d.log();
  EXPECT_EQ(d.state(), "READY");

  d.ok({{"cmd", "load"}, {"program", kSquare}, {"name", "square.ngc"}});
  d.ok({{"cmd", "run"}});
  d.signal(SIGUSR2);
  json st = d.wait_status([](const json& s) { return s["state"] == "HOLD"; }, 500);
  EXPECT_EQ(st["state"], "HOLD") << d.log();
  d.ok({{"cmd", "resume"}});
  st = d.wait_status([](const json& s) { return s["state"] == "RUNNING"; }, 500);
  ASSERT_EQ(st["state"], "RUNNING");
  d.signal(SIGUSR1);
  st = d.wait_status([](const json& s) { return s["state"] == "ESTOP"; }, 500);
  EXPECT_EQ(st["state"], "ESTOP") << d.log();
  EXPECT_NE(st["cause"].get<std::string>().find("E-stop"), std::string::npos) << st.dump();
  const std::string log = d.log();
  EXPECT_NE(log.find("E-STOP by SIGUSR1 " + me), std::string::npos) << log;
  // Still serving, and reset works as after a socket estop.
  d.ok({{"cmd", "reset"}});
  EXPECT_EQ(d.state(), "READY");
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
}

}  // namespace

