// Continuous jog with a dead-man (issue 18): `jog {axis, velocity_mm_min, continuous: "+"|"-"}`
// moves the axis towards its soft limit while the connection that started it lives and keeps
// talking; a disconnect, or silence for safety.jog_deadman_ms (500 ms in config/sim.yaml's
// default), brakes it at the axis' deceleration; the soft limit ends it in any case; and
// `contourctl jog AXIS V --continuous +` interrupted (SIGINT) stops the axis. Bounded polls only.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "tests/support/daemon_process.hpp"
#include "tests/support/run_cmd.hpp"

namespace {

using nlohmann::json;
const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kCtl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl";

// A second connection to the daemon (the jogging client), JSON lines.
class LineClient {
 public:
  explicit LineClient(const std::string& sock) : fd_(contour::test::connect_unix(sock)) {}
  ~LineClient() { close(); }
  LineClient(const LineClient&) = delete;
  LineClient& operator=(const LineClient&) = delete;
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  [[nodiscard]] bool connected() const { return fd_ >= 0; }
  json call(const json& req) {
    const std::string l = req.dump() + "\n";
    if (::send(fd_, l.data(), l.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(l.size())) return {};
    for (;;) {
      const auto nl = buf_.find('\n');
      if (nl != std::string::npos) {
        const json r = json::parse(buf_.substr(0, nl));
        buf_.erase(0, nl + 1);
        return r;
      }
      char tmp[8192];
      const ssize_t n = ::recv(fd_, tmp, sizeof tmp, 0);
      if (n <= 0) return {};
      buf_.append(tmp, static_cast<std::size_t>(n));
    }
  }

 private:
  int fd_ = -1;
  std::string buf_;
};

double x_of(const json& st) { return st["act_mm"][0].get<double>(); }

json jog_plus(LineClient& c, double v_mm_min) {
  return c.call({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", v_mm_min}, {"continuous", "+"}});
}

TEST(JogDeadman, ADisconnectBrakesTheAxis) {
  contour::test::DaemonProcess d("jog_disc", {kSrc + "/config/sim.yaml", {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  const double x0 = x_of(d.ok({{"cmd", "status"}}));
  LineClient c(d.sock());
  ASSERT_TRUE(c.connected());
  const json r = jog_plus(c, 1200);  // 20 mm/s
  ASSERT_TRUE(r.value("ok", false)) << r.dump() << d.log();
  EXPECT_EQ(r["result"]["deadman_ms"], 500.0);
  EXPECT_DOUBLE_EQ(r["result"]["target_mm"].get<double>(), 200.0);  // the soft limit
  // Kept alive for 1.2 s (renewals every 100 ms): still jogging, moving.
  for (int i = 0; i < 12; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ASSERT_TRUE(c.call({{"cmd", "status"}}).value("ok", false));
  }
  const json moving = d.ok({{"cmd", "status"}});
  ASSERT_TRUE(moving["jogging"].get<bool>()) << moving.dump();
  EXPECT_GT(x_of(moving), x0 + 5.0);
  c.close();
  const json st = d.wait_status([](const json& s) { return !s["jogging"].get<bool>(); }, 300);
  EXPECT_FALSE(st["jogging"].get<bool>()) << "the jog outlived its client\n" << d.log();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const double x_end = x_of(d.ok({{"cmd", "status"}}));
  // Braked from 20 mm/s at 2000 mm/s^2 (0.1 mm) plus the loop's lag, nowhere near the limit.
  EXPECT_LT(x_end, x_of(moving) + 5.0);
  EXPECT_EQ(d.state(), "READY");
  EXPECT_NE(d.log().find("continuous jog braked: its client disconnected"), std::string::npos) << d.log();
}

TEST(JogDeadman, SilenceBrakesTheAxisAndTheLimitEndsIt) {
  contour::test::DaemonProcess d("jog_quiet", {kSrc + "/config/sim.yaml", {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  LineClient c(d.sock());
  ASSERT_TRUE(jog_plus(c, 1200).value("ok", false)) << d.log();
  // Connected but silent: braked after safety.jog_deadman_ms.
  const json st = d.wait_status([](const json& s) { return !s["jogging"].get<bool>(); }, 300);
  EXPECT_FALSE(st["jogging"].get<bool>()) << d.log();
  EXPECT_NE(d.log().find("no request from its client"), std::string::npos) << d.log();
  EXPECT_LT(x_of(st), 50.0);

  // Near the limit a renewed continuous jog ends there, and another one is refused.
  d.ok({{"cmd", "set-position"}, {"axis", "X"}, {"position_mm", 199.0}});
  ASSERT_TRUE(jog_plus(c, 600).value("ok", false)) << d.log();
  json s2;
  for (int i = 0; i < 300; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    s2 = c.call({{"cmd", "status"}})["result"];
    if (!s2["jogging"].get<bool>()) break;
  }
  EXPECT_FALSE(s2["jogging"].get<bool>());
  EXPECT_NEAR(s2["ref_mm"][0].get<double>(), 200.0, 1e-9);
  const json again = jog_plus(c, 600);
  EXPECT_FALSE(again.value("ok", true));
  EXPECT_NE(again.value("error", std::string()).find("at its soft limit"), std::string::npos) << again.dump();
  const json both = c.call({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 600}, {"continuous", "-"},
                            {"distance_mm", 1.0}});
  EXPECT_NE(both.value("error", std::string()).find("exactly one of"), std::string::npos) << both.dump();
}

TEST(JogDeadman, InterruptedContourctlStopsTheAxis) {
  contour::test::DaemonProcess d("jog_ctl", {kSrc + "/config/sim.yaml", {}, 1000, 500});
  ASSERT_EQ(d.state(), "READY") << d.log();
  std::string out;
  // contourctl renews the jog while it runs; SIGINT after 1.5 s ends it (exit 124 from timeout).
  const int rc = contour::test::run_cmd(
      "timeout -s INT 1.5 " + kCtl + " --socket " + d.sock() + " jog X 1200 --continuous +", &out);
  EXPECT_EQ(rc, 124) << out;
  EXPECT_NE(out.find("jog: X + continuously"), std::string::npos) << out;
  const json st = d.wait_status([](const json& s) { return !s["jogging"].get<bool>(); }, 300);
  EXPECT_FALSE(st["jogging"].get<bool>()) << d.log();
  EXPECT_GT(x_of(st), 1.0) << out;  // it did move while contourctl ran
  EXPECT_LT(x_of(st), 50.0);
}

}  // namespace
