// HIL: the real contourd (`--config config/hil.yaml`, bus.type socketcan, lockstep) driving
// contour-machine-sim over vcan0, both as child processes, controlled through the command socket.
//  - Table 2 gives the figures of the offline run of the same config (daemon/offline_run: the
//    daemon's loop code on SimBus, the plant code contour-sim uses, which with bus.type socketcan
//    models the drives' integer units: counts/s targets, count positions), within 1e-6 mm.
//  - A drive fault mid-run: state FAULT, every axis stopped, the EMCY text in the daemon log.
//  - Heartbeat loss of one node: state FAULT (cause heartbeat lost), the node named in the log.
// No wall-clock assertions: the drives step once per SYNC and the master waits for every TPDO
// (bus.lockstep), so late cycles do not change the numbers.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "config/config.hpp"
#include "daemon/offline_run.hpp"
#include "tests/hil/canopen_hil_support.hpp"
#include "tests/support/daemon_process.hpp"

extern char** environ;

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const std::string kSrc = CONTOUR_SOURCE_DIR;
const std::string kHil = kSrc + "/config/hil.yaml";
const std::string kTable2 = kSrc + "/config/programs/table2.ngc";

// contourd on config/hil.yaml as a child process with a JSON-lines client (tests/support). Start-up
// includes the CANopen bring-up (NMT reset, boot-up wait, SDO configuration): allow the slow VM
// 60 s to open its socket; this bounds a failure, it is not a timing assertion.
class Daemon : public contour::test::DaemonProcess {
 public:
  explicit Daemon(const std::string& tag)
      : DaemonProcess("hil_" + tag, {kHil, {}, 6000, 3000}) {}
};

}  // namespace

TEST(DaemonCanopen, Table2OverVcanGivesTheOfflineFigures) {
  const auto cfg = contour::config::load_config_file(kHil);
  ASSERT_EQ(cfg.bus.type, "socketcan");
  const auto off = contour::daemon::run_offline(cfg, {"table2.ngc", kTable2, ""});
  // Non-fatal: the comparison below is meaningful for a run that faults too (same cycle).
  EXPECT_TRUE(off.finished_ok) << "offline run ended " << off.state << " (" << off.cause
                               << ", axis " << off.fault_axis << ": " << off.fault_value << " / "
                               << off.fault_limit << ") after " << off.cycles << " cycles";

  contour::test::MachineSim sim;
  ASSERT_TRUE(sim.ready()) << sim.stop();
  Daemon d("t2");
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  const json load = d.ok({{"cmd", "load"}, {"path", kTable2}});
  EXPECT_EQ(load["motion_blocks"], 20);
  const json run = d.ok({{"cmd", "run"}});
  const json res = d.wait_finished(run["job"].get<std::uint64_t>());
  const json st = d.ok({{"cmd", "status"}});
  const double hil_max = res["max_contour_error_um"].get<double>();
  const double hil_rms = res["rms_contour_error_um"].get<double>();
  std::printf(
      "[figure] Table 2 over vcan (contourd + contour-machine-sim): max %.9f um, rms %.9f um, "
      "%s s, %llu samples, missed TPDOs %llu\n",
      hil_max, hil_rms, res["duration_s"].dump().c_str(),
      static_cast<unsigned long long>(res["samples"].get<std::uint64_t>()),
      static_cast<unsigned long long>(st["missed_tpdos"].get<std::uint64_t>()));
  std::printf(
      "[figure] offline run (CAN quantisation):            max %.9f um, rms %.9f um, %.3f s\n",
      off.stats.max_contour_error_um, off.stats.rms_contour_error_um(), off.duration_s);
  {
    // For scale: the same config on the ideal in-process bus (velocity as a double, position
    // quantised to blu_um) - the effect of the drives' integer units, which the offline model
    // above includes.
    auto ideal_cfg = cfg;
    ideal_cfg.bus.type = "sim";
    ideal_cfg.bus_lockstep = false;
    const auto ideal = contour::daemon::run_offline(ideal_cfg, {"table2.ngc", kTable2, ""});
    std::printf(
        "[figure] same config, ideal in-process bus:        max %.9f um, rms %.9f um (%s)\n",
        ideal.stats.max_contour_error_um, ideal.stats.rms_contour_error_um(), ideal.state.c_str());
  }
  std::printf("[figure] |HIL - offline|: max %.3g um, rms %.3g um\n",
              std::abs(hil_max - off.stats.max_contour_error_um),
              std::abs(hil_rms - off.stats.rms_contour_error_um()));
  EXPECT_EQ(res["state"], off.state) << res.dump() << "\n" << d.log();
  EXPECT_EQ(res["completed"].get<bool>(), off.finished_ok) << res.dump();
  EXPECT_EQ(st["missed_tpdos"].get<std::uint64_t>(), 0u);
  // Issue 7: within 1e-6 mm = 1e-3 um.
  EXPECT_NEAR(hil_max, off.stats.max_contour_error_um, 1e-3);
  EXPECT_NEAR(hil_rms, off.stats.rms_contour_error_um(), 1e-3);
  EXPECT_EQ(res["samples"].get<std::uint64_t>(), off.stats.samples);
  EXPECT_GT(hil_max, 0.1);  // the run really moved (Table 2: some um of contour error)
  {
    // The same comparison against the `contour-sim run` binary (issue 7: "the same contour-error
    // figures as contour-sim with the same config"): its last stdout line is one JSON object.
    const std::string cmd = std::string(CONTOUR_BINARY_DIR) + "/tools/contour-sim run --config " +
                            kHil + " --program " + kTable2 + " 2>&1";
    FILE* p = ::popen(cmd.c_str(), "r");
    ASSERT_NE(p, nullptr);
    std::string out, last;
    char buf[4096];
    while (std::fgets(buf, sizeof(buf), p) != nullptr) out += buf;
    const int rc = ::pclose(p);
    std::istringstream lines(out);
    for (std::string l; std::getline(lines, l);)
      if (!l.empty()) last = l;
    EXPECT_EQ(rc, 0) << out;
    const json cs = json::parse(last, nullptr, false);
    ASSERT_TRUE(cs.is_object()) << out;
    std::printf("[figure] contour-sim run --config config/hil.yaml: max %.9f um, rms %.9f um\n",
                cs["max_contour_error_um"].get<double>(), cs["rms_contour_error_um"].get<double>());
    EXPECT_NEAR(hil_max, cs["max_contour_error_um"].get<double>(), 1e-3) << out;
    EXPECT_NEAR(hil_rms, cs["rms_contour_error_um"].get<double>(), 1e-3) << out;
    EXPECT_EQ(res["samples"].get<std::uint64_t>(), cs["samples"].get<std::uint64_t>()) << out;
  }
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
  const std::string summary = sim.stop();
  EXPECT_EQ(summary.find("operation enabled"), std::string::npos) << summary;  // drives disabled
}

TEST(DaemonCanopen, DriveFaultMidRunStopsEveryAxisAndLogsTheEmcy) {
  // Node 2 (Y) faults 500 SYNCs after it starts moving: mid-path of Table 2.
  contour::test::MachineSim sim({"--fault-after-motion", "2:500:0x2310"});
  ASSERT_TRUE(sim.ready()) << sim.stop();
  Daemon d("fault");
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  d.ok({{"cmd", "load"}, {"path", kTable2}});
  const auto job = d.ok({{"cmd", "run"}})["job"].get<std::uint64_t>();
  json st = d.wait_status([](const json& s) { return s["state"] == "FAULT"; });
  ASSERT_EQ(st["state"], "FAULT") << st.dump() << "\n" << d.log();
  EXPECT_EQ(st["cause"], "drive fault") << st.dump();
  // Controlled stop: the commands ramp to zero (safety.stop_decel_mm_s2), the drives are
  // disabled and the axes coast out through their velocity lag (tau 30 ms). After 500 more
  // cycles (17 tau) nothing may move any more: two status samples 300 cycles apart agree.
  st = d.wait_status([](const json& s) {
    for (const auto& v : s["cmd_mm_s"])
      if (v.get<double>() != 0.0) return false;
    return true;
  });
  const auto c0 = st["cycle"].get<std::uint64_t>();
  const json a =
      d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() > c0 + 500; });
  const auto c1 = a["cycle"].get<std::uint64_t>();
  const json b =
      d.wait_status([&](const json& s) { return s["cycle"].get<std::uint64_t>() > c1 + 300; });
  EXPECT_EQ(b["state"], "FAULT");
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(b["cmd_mm_s"][i].get<double>(), 0.0) << b.dump();
    EXPECT_NEAR(b["act_mm"][i].get<double>(), a["act_mm"][i].get<double>(), 1e-9)
        << "axis " << i << " still moving";
    EXPECT_GT(std::abs(b["act_mm"][i].get<double>()), 0.1) << "axis " << i << " never moved";
  }
  EXPECT_FALSE(b["drives_enabled"].get<bool>()) << b.dump();
  const json res = d.ok({{"cmd", "result"}, {"job", job}});
  EXPECT_FALSE(res["completed"].get<bool>());
  EXPECT_FALSE(res["faults"].empty()) << res.dump();
  // The event thread of the bus logs within 20 ms; poll the log file a bounded number of times.
  std::string log;
  for (int i = 0; i < 500; ++i) {
    log = d.log();
    if (log.find("0x2310") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_NE(log.find("EMCY node 2 (Y): 0x2310 continuous over-current"), std::string::npos) << log;
  EXPECT_NE(log.find("node 2 (Y): drive fault"), std::string::npos) << log;
  // The EMCY text is also in the job's fault list (the bus's event thread files it).
  const std::string faults = d.ok({{"cmd", "result"}, {"job", job}})["faults"].dump();
  EXPECT_NE(faults.find("0x2310"), std::string::npos) << faults;
  // Operator reset: the loop acknowledges the bus faults, the master sends the CiA 402
  // fault-reset edge, the (one-shot) drive fault clears and the drives are enabled again.
  d.ok({{"cmd", "reset"}});
  st = d.wait_status([](const json& s) { return s["state"] == "READY"; });
  EXPECT_EQ(st["state"], "READY") << st.dump() << "\n" << d.log();
  EXPECT_TRUE(st["drives_enabled"].get<bool>()) << st.dump();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
  const std::string summary = sim.stop();
  EXPECT_EQ(summary.find("operation enabled"), std::string::npos) << summary;
}

TEST(DaemonCanopen, HeartbeatLossOfOneNodeIsAFaultNamingTheNode) {
  // Node 3 (Z) stops its heartbeat 1000 SYNCs after NMT start.
  contour::test::MachineSim sim({"--stop-heartbeat", "3:1000"});
  ASSERT_TRUE(sim.ready()) << sim.stop();
  Daemon d("hb");
  ASSERT_TRUE(d.connected()) << d.log();
  const json st = d.wait_status([](const json& s) { return s["state"] == "FAULT"; });
  ASSERT_EQ(st["state"], "FAULT") << st.dump() << "\n" << d.log();
  EXPECT_EQ(st["cause"], "heartbeat lost") << st.dump();
  std::string log;
  for (int i = 0; i < 500; ++i) {
    log = d.log();
    if (log.find("node 3 (Z): heartbeat lost") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_NE(log.find("node 3 (Z): heartbeat lost (no heartbeat for 200 ms)"), std::string::npos)
      << log;
  // Issue 16: the node is still silent, so `reset` is refused naming the node and the missing
  // heartbeat (acknowledging used to re-arm the heartbeat timer: the reset succeeded and the
  // machine faulted again one consumer timeout later).
  const json r = d.call({{"cmd", "reset"}});
  EXPECT_FALSE(r.value("ok", true)) << r.dump();
  const std::string err = r.value("error", "");
  EXPECT_NE(err.find("no heartbeat from node 3"), std::string::npos) << err;
  std::this_thread::sleep_for(std::chrono::milliseconds(400));  // > heartbeat_timeout_ms
  EXPECT_EQ(d.state(), "FAULT");
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
}

TEST(DaemonCanopen, FeedMoveWaitsForTheCanSpindleAtSpeed) {
  // M3 S3000: the spindle node (4, velocity fed back in 0x606C every 10th SYNC) ramps at
  // spindle.rate_rpm_s (6000 rpm/s) and follows with the simulated drive's lag (sim_tau_s 0.2 s);
  // the G01 starts only when the reported speed is within max(50 rpm, 2 %) of 3000 rpm.
  const auto cfg = contour::config::load_config_file(kHil);
  ASSERT_EQ(cfg.spindle.type, "canopen");
  contour::test::MachineSim sim;
  ASSERT_TRUE(sim.ready()) << sim.stop();
  Daemon d("spindle");
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  d.ok({{"cmd", "load"}, {"program", "G21 G90\nM3 S3000\nG01 X5 F600\nM5\nM2\n"}});
  const auto job = d.ok({{"cmd", "run"}})["job"].get<std::uint64_t>();
  // While waiting: RUNNING, the path at its start, the spindle accelerating.
  const json w = d.wait_status([](const json& s) { return s["spindle"]["waiting"].get<bool>(); });
  EXPECT_TRUE(w["spindle"]["waiting"].get<bool>()) << w.dump();
  EXPECT_EQ(w["state"], "RUNNING");
  EXPECT_EQ(w["ref_mm"][0].get<double>(), 0.0);
  EXPECT_LT(w["spindle"]["actual_rpm"].get<double>(), 3000.0 - 60.0);
  const json res = d.wait_finished(job);
  EXPECT_TRUE(res["completed"].get<bool>()) << res.dump() << "\n" << d.log();
  const json st = d.ok({{"cmd", "status"}});
  const double wait_s = st["spindle"]["last_wait_s"].get<double>();
  // Closed form as in the unit test: ramp Tr = 0.5 s, lag at its end R tau (1 - e^(-Tr/tau)),
  // decaying with tau to the 60 rpm band. The CAN spindle's RPDO/TPDO every 10th SYNC adds up to
  // ~2 x 10 ms.
  const double tau = 0.2, R = 6000.0, Tr = 0.5;
  const double expected_s = Tr + tau * std::log(R * tau * (1.0 - std::exp(-Tr / tau)) / 60.0);
  std::printf("[figure] CAN spindle 0 -> 3000 rpm: feed waited %.3f s (closed form %.3f s)\n",
              wait_s, expected_s);
  EXPECT_EQ(st["spindle"]["waits"].get<std::uint64_t>(), 1u);
  EXPECT_TRUE(st["spindle"]["feedback"].get<bool>());
  EXPECT_GE(wait_s, expected_s - 0.005);
  EXPECT_LE(wait_s, expected_s + 0.030);
  EXPECT_NE(d.log().find("spindle at speed"), std::string::npos) << d.log();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
  sim.stop();
}
