// Issue 16, "gains that cannot make the machine oscillate": the stability check of
// control/loop_stability.hpp (through daemon/gains_check.hpp) on every path a gain set reaches the
// loop of contourd on config/sim.yaml: `gains set` (refused with the verdict's reason word for
// word, the running set unchanged), a gain the active law does not use (refused naming the law),
// SIGHUP (the control keys refused with the reason), start-up (exit 78 naming the file and axis).
// Round 1 accepted kp=50 and kp=100 and the axis limit-cycled at standstill in READY.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "config/config.hpp"
#include "daemon/gains_check.hpp"
#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
const std::string kSrc = CONTOUR_SOURCE_DIR;
using contour::test::slurp;

std::string replaced(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

std::string temp_config(const std::string& tag, const std::string& yaml) {
  const std::string p =
      (fs::temp_directory_path() / ("contourd_gains_" + tag + "_" + std::to_string(::getpid()) + ".yaml")).string();
  std::ofstream(p) << yaml;
  return p;
}

// The verdict the daemon computes for sim.yaml with X's kp replaced (same parameters as the loop).
contour::control::StabilityVerdict verdict_for_x_kp(double kp) {
  const auto cfg = contour::config::load_config_file(kSrc + "/config/sim.yaml");
  std::array<contour::control::FeedDriveParams, 3> dp{};
  int delay = 0;
  for (std::size_t i = 0; i < cfg.machine.axes.size(); ++i) {
    dp[i] = cfg.machine.axes[i].drive;
    dp[i].period_s = cfg.machine.period_s;
    delay = std::max(delay, dp[i].delay_cycles);
  }
  auto p = contour::config::make_servo_params(cfg.control, cfg.control.controller, dp,
                                              static_cast<int>(cfg.machine.axes.size()),
                                              cfg.machine.period_s, delay);
  p.axis[0].kp = kp;
  return contour::daemon::check_gains(p, cfg.machine);
}

class Daemon : public contour::test::DaemonProcess {
 public:
  explicit Daemon(const std::string& tag, const std::string& config)
      : DaemonProcess(tag, {config, {}, 1000, 500}) {
    EXPECT_TRUE(connected()) << log();
  }
};

TEST(GainsSafety, UnstableGainsSetIsRefusedWithTheVerdictAndTheRunningSetStays) {
  Daemon d("gains_set", kSrc + "/config/sim.yaml");
  ASSERT_EQ(d.state(), "READY") << d.log();
  const json before = d.ok({{"cmd", "gains"}});
  for (const double kp : {50.0, 100.0}) {
    const auto v = verdict_for_x_kp(kp);
    ASSERT_FALSE(v.stable) << kp;
    EXPECT_NE(v.reason.find("axis X"), std::string::npos) << v.reason;
    // `contourctl gains set axis.x.kp=50` sends the whole kp vector with X changed.
    const json r = d.call({{"cmd", "gains"}, {"set", {{"kp", {kp, 0.6, 0.6}}}}});
    ASSERT_FALSE(r["ok"].get<bool>()) << r.dump();
    EXPECT_EQ(r["error"].get<std::string>(), "gains rejected: " + v.reason);
  }
  const json after = d.ok({{"cmd", "gains"}});
  EXPECT_EQ(after["kp"], before["kp"]);
  EXPECT_EQ(after["generation"], before["generation"]);
  EXPECT_EQ(d.state(), "READY");
  // A stable change still goes through.
  EXPECT_TRUE(verdict_for_x_kp(0.8).stable);
  const json g = d.ok({{"cmd", "gains"}, {"set", {{"kp", {0.8, 0.6, 0.6}}}}});
  EXPECT_EQ(g["kp"][0], 0.8);
}

TEST(GainsSafety, AGainTheActiveLawDoesNotUseIsRefusedNamingTheLaw) {
  Daemon d("gains_law", kSrc + "/config/sim.yaml");
  ASSERT_EQ(d.state(), "READY") << d.log();
  json r = d.call({{"cmd", "gains"}, {"set", {{"ki_per_s", 5}}}});
  ASSERT_FALSE(r["ok"].get<bool>()) << r.dump();
  EXPECT_NE(r["error"].get<std::string>().find("gain 'ki_per_s' is not used by the active law p"),
            std::string::npos) << r.dump();
  // Coupling gains with the coupling switched off in the same request.
  r = d.call({{"cmd", "gains"}, {"set", {{"coupling", false}, {"cp", 10}}}});
  ASSERT_FALSE(r["ok"].get<bool>()) << r.dump();
  EXPECT_NE(r["error"].get<std::string>().find("gain 'cp' is not used"), std::string::npos) << r.dump();
  EXPECT_EQ(d.ok({{"cmd", "gains"}})["generation"], 0);
}

TEST(GainsSafety, SighupWithUnstableGainsIsRefusedWithTheReason) {
  const std::string orig = contour::test::sim_yaml();
  const std::string path = temp_config("hup", orig);
  {
    Daemon d("gains_hup", path);
    ASSERT_EQ(d.state(), "READY") << d.log();
    std::ofstream(path) << replaced(orig, "kp: [0.6, 0.6, 0.6]", "kp: [50, 0.6, 0.6]");
    d.signal(SIGHUP);
    // `reloads` counts from the start of the reload; last_reload is filled at its end.
    const json st = d.wait_status(
        [](const json& s) {
          return s["config"]["reloads"].get<int>() >= 1 && s["config"]["last_reload"]["cycle"].get<std::uint64_t>() > 0;
        },
        2000);
    const json& refused = st["config"]["last_reload"]["refused"];
    ASSERT_EQ(refused.size(), 1u) << st["config"].dump();
    const std::string text = refused[0].get<std::string>();
    EXPECT_EQ(text.rfind("control.kp", 0), 0u) << text;
    EXPECT_NE(text.find("gains refused: " + verdict_for_x_kp(50.0).reason), std::string::npos) << text;
    EXPECT_EQ(d.ok({{"cmd", "gains"}})["kp"], json({0.6, 0.6, 0.6}));
    EXPECT_EQ(d.state(), "READY");
  }
  fs::remove(path);
}

TEST(GainsSafety, StartUpWithUnstableGainsExits78NamingTheFileAndAxis) {
  const std::string path =
      temp_config("start", replaced(contour::test::sim_yaml(), "kp: [0.6, 0.6, 0.6]", "kp: [0.6, 100, 0.6]"));
  const fs::path dir = fs::temp_directory_path() / ("contourd_gains_start_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string cmd = std::string(CONTOUR_BINARY_DIR) + "/daemon/contourd --config " + path +
                          " --socket " + (dir / "c.sock").string() + " 2>&1";
  FILE* f = ::popen(cmd.c_str(), "r");
  ASSERT_NE(f, nullptr);
  std::string out;
  char buf[512];
  while (std::fgets(buf, sizeof(buf), f) != nullptr) out += buf;
  const int st = ::pclose(f);
  EXPECT_TRUE(WIFEXITED(st)) << out;
  EXPECT_EQ(WEXITSTATUS(st), 78) << out;
  EXPECT_NE(out.find(path + ": control: gains refused by the stability check: axis Y"), std::string::npos)
      << out;
  std::error_code ec;
  fs::remove(path, ec);
  fs::remove_all(dir, ec);
}

// Today's shipped configurations start (the same check, in process).
TEST(GainsSafety, ShippedConfigsPassTheCheck) {
  for (const char* name : {"sim.yaml", "hil.yaml", "table1.yaml"}) {
    const auto cfg = contour::config::load_config_file(kSrc + "/config/" + name);
    std::array<contour::control::FeedDriveParams, 3> dp{};
    int delay = 0;
    for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
      dp[i] = cfg.machine.axes[i].drive;
      dp[i].period_s = cfg.machine.period_s;
      delay = std::max(delay, dp[i].delay_cycles);
    }
    const auto p = contour::config::make_servo_params(cfg.control, cfg.control.controller, dp,
                                                      static_cast<int>(cfg.machine.axes.size()),
                                                      cfg.machine.period_s, delay);
    const auto v = contour::daemon::check_gains(p, cfg.machine);
    EXPECT_TRUE(v.stable) << name << ": " << v.reason;
  }
}

}  // namespace
