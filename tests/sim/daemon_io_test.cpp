// contourd (the built binary) with config/sim.yaml plus a dynamometer served on loopback by the
// simulator's DynamometerServer: the simulated E-stop pressed through the socket (`sim_gpio`)
// puts the loop in ESTOP and reset needs it released; GPIO lines in `status`; the force channel
// in `status` (fx_n/fy_n/fz_n, counters); `force on` while RUNNING, then the server stops and the
// stale-sample fallback (feed hold; stale after 1 s here, generous for a loaded VM) shows in
// `status` and the log, `force off` resumes; gains set while RUNNING take effect. Waits are bounded
// polls on the daemon's state, never timing asserts.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

// DynamometerServer lives in contour-machine-sim, which is not a library (as in
// tests/unit/drivers/modbus_dynamometer_test.cpp).
#include "tools/contour-machine-sim/dynamometer_server.cpp"
#include "tests/support/daemon_process.hpp"
#include "tests/support/sim_config.hpp"

extern char** environ;

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
namespace dm = contour::drivers::modbus;

const std::string kSrc = CONTOUR_SOURCE_DIR;

using contour::test::slurp;

// config/sim.yaml plus `extra_yaml`, written to a temporary file (the SIGHUP test rewrites it).
std::string io_config_path(const std::string& tag) {
  return (fs::temp_directory_path() /
          ("contourd_io_" + tag + "_" + std::to_string(::getpid()) + ".yaml"))
      .string();
}
std::string write_io_config(const std::string& tag, const std::string& extra_yaml) {
  const std::string p = io_config_path(tag);
  std::ofstream(p) << contour::test::sim_yaml() << "\n" << extra_yaml;
  return p;
}

// contourd as a child process with a JSON-lines client (tests/support).
class Daemon : public contour::test::DaemonProcess {
 public:
  Daemon(const std::string& tag, const std::string& extra_yaml)
      : DaemonProcess("io_" + tag, {write_io_config(tag, extra_yaml), {}, 1000, 0}),
        cfg_(io_config_path(tag)) {
    EXPECT_TRUE(connected()) << log();
    wait_for([&](const json& st) { return st["state"] == "READY"; });
  }
  ~Daemon() {
    std::error_code ec;
    fs::remove(cfg_, ec);
  }
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;
  // Polls status until pred holds (bounded: 20 s); returns the last status.
  json wait_for(const std::function<bool(const json&)>& pred) {
    json st = wait_status(pred, 2000);
    if (!pred(st)) ADD_FAILURE() << "condition not reached; last status " << st.dump() << "\n" << log();
    return st;
  }
  [[nodiscard]] const std::string& config_path() const { return cfg_; }

 private:
  std::string cfg_;
};

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) s.replace(at, from.size(), to);
  return s;
}

TEST(DaemonIo, SimulatedEstopThroughTheSocketAndGpioLinesInStatus) {
  Daemon d("estop", "");
  json st = d.ok({{"cmd", "status"}});
  ASSERT_TRUE(st["gpio"]["enabled"].get<bool>()) << st.dump();
  EXPECT_EQ(st["gpio"]["backend"], "sim");
  EXPECT_FALSE(st["gpio"]["lines"]["estop_tripped"].get<bool>());
  st = d.wait_for([](const json& s) { return s["gpio"]["lines"]["drive_enable"].get<bool>(); });
  EXPECT_TRUE(st["gpio"]["lines"]["drive_enable"].get<bool>());
  // Output lines cannot be driven, unknown lines are named.
  EXPECT_FALSE(d.call({{"cmd", "sim_gpio"}, {"line", "FLOOD"}, {"level", 1}})["ok"].get<bool>());
  EXPECT_FALSE(d.call({{"cmd", "sim_gpio"}, {"line", "NOPE"}, {"level", 1}})["ok"].get<bool>());
  EXPECT_FALSE(d.call({{"cmd", "sim_gpio"}, {"line", "estop"}, {"level", 7}})["ok"].get<bool>());
  // Press (active low: physical 0).
  d.ok({{"cmd", "sim_gpio"}, {"line", "ESTOP"}, {"level", 0}});
  st = d.wait_for([](const json& s) { return s["state"] == "ESTOP"; });
  EXPECT_EQ(st["cause"], "E-stop input") << st.dump();
  EXPECT_TRUE(st["gpio"]["estop_input"].get<bool>());
  st = d.wait_for([](const json& s) { return !s["gpio"]["lines"]["drive_enable"].get<bool>(); });
  const json r = d.call({{"cmd", "reset"}});
  EXPECT_FALSE(r["ok"].get<bool>());
  EXPECT_NE(r["error"].get<std::string>().find("E-stop input is still asserted"), std::string::npos)
      << r.dump();
  d.ok({{"cmd", "sim_gpio"}, {"line", "estop"}, {"level", 1}});
  d.wait_for([](const json& s) { return !s["gpio"]["lines"]["estop_asserted"].get<bool>(); });
  st = d.ok({{"cmd", "reset"}});
  EXPECT_EQ(st["state"], "READY") << st.dump();
  // No dynamometer configured: force is refused with the reason.
  const json f = d.call({{"cmd", "force"}, {"enable", true}});
  EXPECT_FALSE(f["ok"].get<bool>());
  EXPECT_NE(f["error"].get<std::string>().find("dynamometer"), std::string::npos);
}

TEST(DaemonIo, ForceChannelStatusStaleFallbackAndLiveGainsWhileRunning) {
  dm::RegisterMap map;
  map.function = dm::RegisterFunction::kInput;
  for (std::size_t c = 0; c < 3; ++c) {
    map.channels[c].enabled = true;
    map.channels[c].address = static_cast<std::uint16_t>(2 * c);
    map.channels[c].type = dm::RegisterType::kFloat32;
    map.channels[c].order = dm::WordOrder::kAbcd;
  }
  map.status = {true, 6, 0, true};
  contour::sim::ForceModelParams model;
  model.noise_std_N = 0.0;
  contour::sim::DynamometerServer server(map, model);
  server.set_fixed_forces(std::array<double, 3>{0.8, 0.5, 0.3});  // resultant 1.0 N
  server.start("127.0.0.1", 0);
  const std::string extra =
      "dynamometer:\n"
      "  transport: tcp\n  host: 127.0.0.1\n  port: " +
      std::to_string(server.port()) +
      "\n"
      "  unit_id: 1\n  function: input\n"
      "  channels:\n"
      "    fx: {address: 0, type: float32, word_order: abcd}\n"
      "    fy: {address: 2, type: float32, word_order: abcd}\n"
      "    fz: {address: 4, type: float32, word_order: abcd}\n"
      "  status: {address: 6, valid_bit: 0}\n"
      "  poll_rate_hz: 200\n  timeout_ms: 20\n  stale_ms: 1000\n"
      "force:\n  enable: false\n  reference_N: 1.0\n  fallback: hold\n  stale_ms: 1000\n";
  Daemon d("force", extra);
  // The reader's filter (default Butterworth 10 Hz) settles on the constant forces.
  json st = d.wait_for([](const json& s) {
    return s["force"]["state"] == "ok" && std::abs(s["force"]["fx_n"].get<double>() - 0.8) < 1e-4;
  });
  EXPECT_TRUE(st["force"]["available"].get<bool>());
  EXPECT_NEAR(st["force"]["fx_n"].get<double>(), 0.8, 1e-4);
  EXPECT_NEAR(st["force"]["fy_n"].get<double>(), 0.5, 1e-4);
  EXPECT_NEAR(st["force"]["fz_n"].get<double>(), 0.3, 1e-4);
  EXPECT_GT(st["force"]["dynamometer"]["samples"].get<std::uint64_t>(), 0u);
  EXPECT_TRUE(st["force"]["dynamometer"]["connected"].get<bool>());
  // Argument errors.
  EXPECT_FALSE(d.call({{"cmd", "force"}, {"reference_N", -1}})["ok"].get<bool>());
  EXPECT_FALSE(d.call({{"cmd", "force"}, {"action", "maybe"}})["ok"].get<bool>());
  // A long cut at the design feed (4.5 mm/s): 150 mm, 33 s; force control on while RUNNING.
  d.ok({{"cmd", "load"}, {"program", "G21 G90\nM3 S3000\nG01 X150 F270\nM5\nM2\n"}});
  const auto job = d.ok({{"cmd", "run"}})["job"].get<std::uint64_t>();
  json f = d.ok({{"cmd", "force"}, {"enable", true}, {"reference_N", 1.0}});
  EXPECT_TRUE(f["enabled"].get<bool>());
  st = d.wait_for([](const json& s) { return s["force"]["active"].get<bool>(); });
  EXPECT_EQ(st["state"], "RUNNING");
  // Gains while RUNNING: accepted, active at a later cycle, the run goes on.
  const auto c0 = st["cycle"].get<std::uint64_t>();
  const json g = d.ok({{"cmd", "gains"}, {"set", {{"cp", 14}}}});
  EXPECT_EQ(g["cp"], 14.0);
  EXPECT_GT(g["active_since_cycle"].get<std::uint64_t>(), c0);
  EXPECT_EQ(d.ok({{"cmd", "status"}})["state"], "RUNNING");
  // The dynamometer goes away: stale -> fallback hold, visible in status and the log.
  server.stop();
  st = d.wait_for([](const json& s) { return s["force"]["fallback_active"].get<bool>(); });
  EXPECT_EQ(st["force"]["status"], "stale_hold") << st["force"].dump();
  EXPECT_EQ(st["force"]["feed_override"], 0.0);
  EXPECT_NE(st["force"]["state"], "ok");
  EXPECT_EQ(st["state"], "RUNNING");
  d.wait_for([](const json& s) { return s["override"].get<double>() == 0.0; });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // FIR (100 ms) drains
  const double p1 = d.ok({{"cmd", "status"}})["progress_mm"].get<double>();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(d.ok({{"cmd", "status"}})["progress_mm"].get<double>(), p1) << "feed held";
  EXPECT_NE(d.log().find("fallback stale_hold"), std::string::npos) << d.log();
  // Force off: back to the programmed feed; the program continues.
  d.ok({{"cmd", "force"}, {"enable", false}});
  d.wait_for([&](const json& s) { return s["progress_mm"].get<double>() > p1 + 1.0; });
  d.ok({{"cmd", "stop"}});
  st = d.wait_for([&](const json& s) { return s["finished_job"].get<std::uint64_t>() == job; });
  EXPECT_EQ(st["state"], "READY");
}

TEST(DaemonIo, SighupSwapsGainsAndSafetyLimitsWhileRunning) {
  Daemon d("hup", "");
  d.ok({{"cmd", "load"}, {"program", "G21 G90\nG01 X100 F600\nG01 X0\nM2\n"}});
  d.ok({{"cmd", "run"}});
  d.wait_for([](const json& s) {
    return s["state"] == "RUNNING" && s["progress_mm"].get<double>() > 1.0;
  });
  std::string yaml = slurp(d.config_path());
  yaml = replace_all(yaml, "kp: [0.6, 0.6, 0.6]", "kp: [0.55, 0.55, 0.55]");
  yaml = replace_all(yaml, "contour_error_limit_mm: 0.5", "contour_error_limit_mm: 0.45");
  std::ofstream(d.config_path()) << yaml;
  d.signal(SIGHUP);
  const json st = d.wait_for([](const json& s) {
    return s["gains_generation"].get<std::uint64_t>() >= 1 &&
           s["limits_generation"].get<std::uint64_t>() >= 1;
  });
  EXPECT_EQ(st["state"], "RUNNING") << "swapped while running";
  EXPECT_EQ(d.ok({{"cmd", "gains"}})["kp"], json({0.55, 0.55, 0.55}));
  EXPECT_NE(d.log().find("SIGHUP: safety limits staged"), std::string::npos) << d.log();
  d.ok({{"cmd", "stop"}});
}

}  // namespace

namespace {

bool any_starts(const json& list, const std::string& prefix) {
  for (const auto& e : list)
    if (e.get<std::string>().rfind(prefix, 0) == 0) return true;
  return false;
}

}  // namespace

// Issue 16: after a reload every changed key is applied at a cycle boundary (and enforced at once)
// or refused naming it; a soft limit moved inside the axis' position is refused.
TEST(DaemonIo, SighupAppliesOrRefusesEveryChangedKeyAndEnforcesNewSoftLimitsAtOnce) {
  Daemon d("hup2", "");
  std::string yaml = slurp(d.config_path());
  const std::string orig = yaml;
  // X: max_mm 200 -> 50 (the first axis' line), a restart-only key, a live safety key.
  yaml.replace(yaml.find("max_mm: 200"), std::string("max_mm: 200").size(), "max_mm: 50");
  yaml = replace_all(yaml, "fir_ms: 100", "fir_ms: 80");
  std::ofstream(d.config_path()) << yaml;
  d.signal(SIGHUP);
  json st = d.wait_for([](const json& s) { return s["config"]["reloads"].get<int>() >= 1; });
  const json& last = st["config"]["last_reload"];
  EXPECT_TRUE(any_starts(last["applied"], "machine.axes[0].max_mm: 200 -> 50")) << last.dump();
  EXPECT_TRUE(any_starts(last["refused"], "interpolator.fir_ms: 100 -> 80: needs restart")) << last.dump();
  EXPECT_EQ(st["config"]["pending_restart"], json({"interpolator.fir_ms"}));
  st = d.wait_for([](const json& s) { return s["soft_limits_mm"]["max"][0].get<double>() == 50.0; });
  // The old code logged "staged" and then let a jog go to X 103.
  const json j = d.call({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 3000}, {"distance_mm", 103}});
  EXPECT_FALSE(j["ok"].get<bool>()) << j.dump();
  EXPECT_NE(j.value("error", "").find("outside the soft limits of X [-200.000000, 50.000000]"),
            std::string::npos) << j.dump();
  // Jog to X 40, then a limit at 30 would put X outside it: refused while X stands there.
  d.ok({{"cmd", "jog"}, {"axis", "X"}, {"velocity_mm_min", 3000}, {"distance_mm", 40}});
  d.wait_for([](const json& s) { return !s["jogging"].get<bool>() && s["act_mm"][0].get<double>() > 39.9; });
  yaml = replace_all(yaml, "max_mm: 50", "max_mm: 30");
  std::ofstream(d.config_path()) << yaml;
  d.signal(SIGHUP);
  st = d.wait_for([](const json& s) { return s["config"]["reloads"].get<int>() >= 2; });
  EXPECT_TRUE(any_starts(st["config"]["last_reload"]["refused"], "machine.axes[0].max_mm: 50 -> 30: refused: axis X is at"))
      << st["config"].dump();
  EXPECT_EQ(st["soft_limits_mm"]["max"][0].get<double>(), 50.0);
  // Back to the original file: fir_ms is no longer pending.
  std::ofstream(d.config_path()) << orig;
  d.signal(SIGHUP);
  st = d.wait_for([](const json& s) { return s["config"]["reloads"].get<int>() >= 3; });
  EXPECT_TRUE(st["config"]["pending_restart"].empty()) << st["config"].dump();
  EXPECT_EQ(st["soft_limits_mm"]["max"][0].get<double>(), 200.0);
}
