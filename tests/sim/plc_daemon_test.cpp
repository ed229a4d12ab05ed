// contourd (the built binary) with config/sim.yaml: the soft PLC's example machine logic on
// the built-in simulated machine, through the socket (issue 20). A program runs; the door is
// opened (forced: the sim bus allows forcing) -> HOLD with the PLC's requests in `status.plc`;
// `resume` is refused while it is open and accepted once it is closed; the program completes.
// `io` lists the image with the forced flag, `plc_status` the programs' scan times; NC signals
// cannot be forced; without a plc: section `io` is refused. Waits are bounded polls.
#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/daemon_process.hpp"
#include "tests/support/run_cmd.hpp"
#include "tests/support/sim_config.hpp"

namespace {

using nlohmann::json;
const std::string kSrc = CONTOUR_SOURCE_DIR;

contour::test::DaemonProcess::Options with_config(const std::string& rel) {
  contour::test::DaemonProcess::Options o;
  o.config = kSrc + rel;
  return o;
}

json signal(const json& io, const std::string& name) {
  for (const auto& s : io["signals"]) {
    if (s["name"] == name) return s;
  }
  return json::object();
}

TEST(PlcDaemon, DoorInterlockHoldsAndResumesAProgramThroughTheSocket) {
  contour::test::DaemonProcess d("plc", with_config("/config/sim.yaml"));
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();

  json io = d.ok({{"cmd", "io"}});
  EXPECT_TRUE(io["forcing_allowed"].get<bool>());
  EXPECT_EQ(signal(io, "door_closed")["value"], true);
  EXPECT_EQ(signal(io, "door_closed")["source"], "sim door_closed");

  const json load = d.ok({{"cmd", "load"}, {"program", "G1 X30 F300\nM2\n"}, {"name", "door.ngc"}});
  const std::uint64_t job = load["job"].get<std::uint64_t>();
  d.ok({{"cmd", "run"}});
  d.wait_status([](const json& st) { return st["state"] == "RUNNING"; }, 500);

  const json forced = d.ok({{"cmd", "io"}, {"action", "force"}, {"name", "door_closed"}, {"value", false}});
  EXPECT_EQ(forced["forced"], true);
  json st = d.wait_status([](const json& s) { return s["state"] == "HOLD"; }, 500);
  ASSERT_EQ(st["state"], "HOLD") << d.log();
  EXPECT_EQ(st["plc"]["requests"]["feed_hold"], true);
  EXPECT_EQ(st["plc"]["requests"]["inhibit_start"], true);
  EXPECT_EQ(st["plc"]["cause"]["action"], "feed_hold_req");
  EXPECT_EQ(signal(d.ok({{"cmd", "io"}}), "door_closed")["forced"], true);

  const json refused = d.call({{"cmd", "resume"}});
  st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["state"], "HOLD") << refused.dump();

  d.ok({{"cmd", "io"}, {"action", "unforce"}, {"name", "door_closed"}});
  d.wait_status([](const json& s) { return s["plc"]["requests"]["feed_hold"] == false; }, 500);
  d.ok({{"cmd", "resume"}});
  const json res = d.wait_finished(job);
  EXPECT_TRUE(res.value("completed", false)) << res.dump() << "\n" << d.log();

  const json ps = d.ok({{"cmd", "plc_status"}});
  EXPECT_EQ(ps["present"], true);
  ASSERT_EQ(ps["programs"].size(), 5U);
  EXPECT_EQ(ps["programs"][0]["name"], "interlocks");
  EXPECT_GT(ps["programs"][0]["runs"].get<std::uint64_t>(), 100U);

  const json nc = d.call({{"cmd", "io"}, {"action", "force"}, {"name", "NC.feed_hold_req"}, {"value", true}});
  EXPECT_FALSE(nc.value("ok", true));
  EXPECT_NE(nc.value("error", std::string()).find("only plc.signals"), std::string::npos) << nc.dump();
}

// config/sim.yaml as shipped: M6 runs the example machine logic's carousel sequence
// (config/plc/toolchanger.st; tool T lives in pocket T) instead of pausing for the operator. The
// program runs to completion without a `resume`, never in HOLD, and the carousel stands at
// pocket 3 with the drawbar clamped on tool 3, which status reports in the spindle.
TEST(PlcDaemon, SimYamlRunsM6OnTheCarouselWithoutAPause) {
  contour::test::DaemonProcess d("carousel", with_config("/config/sim.yaml"));
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  EXPECT_NE(signal(d.ok({{"cmd", "io"}}), "carousel_pocket")["value"], 3) << "the carousel must have to turn";
  const json r = d.ok({{"cmd", "run"},
                       {"program", "G21 G90 G17\nG0 X5 Y5\nT3 M6\nG1 X10 F600\nM2\n"},
                       {"name", "carousel.ngc"}});
  ASSERT_TRUE(r.contains("job")) << r.dump();
  const auto job = r["job"].get<std::uint64_t>();
  bool held = false;
  json st = d.wait_status(
      [&](const json& s) {
        held = held || s["state"] == "HOLD" || s.contains("tool_change");
        return s["state"] == "READY" && s.value("tool", -1) == 3;
      },
      6000);
  EXPECT_EQ(st["state"], "READY") << st.dump() << "\n" << d.log();
  EXPECT_FALSE(held) << "M6 paused for the operator although the machine logic runs the carousel";
  const json res = d.wait_finished(job);
  EXPECT_TRUE(res.value("completed", false)) << res.dump() << "\n" << d.log();
  EXPECT_EQ(d.ok({{"cmd", "status"}})["tool"], 3);
  const json io = d.ok({{"cmd", "io"}});
  EXPECT_EQ(signal(io, "carousel_pocket")["value"], 3) << io.dump();
  EXPECT_EQ(signal(io, "carousel_in_position")["value"], true);
  EXPECT_EQ(signal(io, "drawbar_clamped")["value"], true);
}

// `contourctl io --watch`: the image again every --interval, each after a "cycle N" line whose
// cycle advances; --json gives one object per line.
TEST(PlcDaemon, IoWatchRedrawsTheImage) {
  contour::test::DaemonProcess d("iowatch", with_config("/config/sim.yaml"));
  ASSERT_TRUE(d.connected()) << d.log();
  const std::string ctl = std::string(CONTOUR_BINARY_DIR) + "/tools/contourctl --socket " + d.sock();
  std::string out;
  ASSERT_EQ(contour::test::run_cmd(ctl + " io --watch --count 3 --interval 0.05", &out), 0) << out;
  std::vector<unsigned long long> cycles;
  std::size_t headers = 0, doors = 0;
  std::istringstream in(out);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("cycle ", 0) == 0) cycles.push_back(std::stoull(line.substr(6)));
    if (line.rfind("NAME ", 0) == 0) ++headers;
    if (line.rfind("door_closed ", 0) == 0) ++doors;
  }
  ASSERT_EQ(cycles.size(), 3U) << out;
  EXPECT_EQ(headers, 3U) << out;
  EXPECT_EQ(doors, 3U) << out;
  EXPECT_LT(cycles[0], cycles[2]) << out;
  out.clear();  // run_cmd appends
  ASSERT_EQ(contour::test::run_cmd(ctl + " --json io --watch --count 2 --interval 0.05", &out), 0) << out;
  std::istringstream js(out);
  int objects = 0;
  for (std::string line; std::getline(js, line);) {
    if (line.empty()) continue;
    const json j = json::parse(line, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << line;
    EXPECT_TRUE(j.contains("signals")) << line;
    ++objects;
  }
  EXPECT_EQ(objects, 2) << out;
}

TEST(PlcDaemon, WithoutAPlcSectionIoIsRefused) {
  contour::test::DaemonProcess::Options o;
  o.config = contour::test::write_sim_yaml(
      (std::filesystem::temp_directory_path() / ("contour_noplc_" + std::to_string(::getpid()) + ".yaml")).string(),
      contour::test::SimPlc::kNone);
  contour::test::DaemonProcess d("noplc", o);
  ASSERT_TRUE(d.connected()) << d.log();
  const json r = d.call({{"cmd", "io"}});
  EXPECT_FALSE(r.value("ok", true));
  EXPECT_NE(r.value("error", std::string()).find("no soft PLC"), std::string::npos) << r.dump();
  EXPECT_EQ(d.ok({{"cmd", "plc_status"}})["present"], false);
  EXPECT_EQ(d.ok({{"cmd", "status"}})["plc"]["present"], false);
}

// A machine-logic fault at power-up (here a program that requests a fault until `ok` is set, like
// an I/O coupler that does not answer yet): contourd stays up in FAULT with the cause in status,
// instead of exiting "drives did not enable" (which made systemd restart it in a loop and hid the
// cause). reset is refused while the cause remains and brings the machine to READY once it is gone.
TEST(PlcDaemon, AFaultAtStartUpLeavesTheDaemonUpInFaultUntilReset) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("contour_startfault_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::ofstream(dir / "f.st") << "PROGRAM f\n  NC.fault_req := NOT ok;\n  NC.fault_code := 7;\nEND_PROGRAM\n";
  contour::test::DaemonProcess::Options o;
  o.config = contour::test::write_sim_yaml(
      (dir / "startfault.yaml").string(), contour::test::SimPlc::kNone,
      "plc:\n  programs: [{file: " + (dir / "f.st").string() + "}]\n  signals:\n    - {name: ok}\n");
  o.ready_polls = 0;
  contour::test::DaemonProcess d("startfault", o);
  ASSERT_TRUE(d.connected()) << d.log();
  // The daemon gives the drives 5 s to enable; then it says it started in FAULT and stays up.
  std::string log;
  for (int i = 0; i < 3000 && log.find("started in FAULT") == std::string::npos; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    log = d.log();
  }
  ASSERT_NE(log.find("started in FAULT (cause machine logic fault)"), std::string::npos) << log;
  EXPECT_EQ(log.find("did not enable"), std::string::npos) << log;
  json st = d.ok({{"cmd", "status"}});
  EXPECT_EQ(st["state"], "FAULT") << st.dump();
  EXPECT_EQ(st["cause"], "machine logic fault") << st.dump();
  const json refused = d.call({{"cmd", "reset"}});
  EXPECT_FALSE(refused.value("ok", true)) << refused.dump();
  EXPECT_EQ(d.state(), "FAULT");
  // The cause goes: reset enables the drives.
  d.ok({{"cmd", "io"}, {"action", "force"}, {"name", "ok"}, {"value", true}});
  d.ok({{"cmd", "reset"}});
  st = d.wait_status([](const json& s) { return s["state"] == "READY"; });
  EXPECT_EQ(st["state"], "READY") << st.dump() << "\n" << d.log();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace

// An overtravel switch of the example machine logic faults its axis: status.fault names the axis
// by index and by name. A reset while the switch is still actuated is answered with the loop's
// verdict (refused, naming what is missing, once its 250-cycle window has closed); released, the
// next reset brings READY.
TEST(PlcDaemon, AnOvertravelFaultNamesTheAxisAndTheResetReplyIsTheLoopsVerdict) {
  contour::test::DaemonProcess d("overtravel", with_config("/config/sim.yaml"));
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  d.ok({{"cmd", "io"}, {"action", "force"}, {"name", "limit_y_pos"}, {"value", true}});
  json st = d.wait_status([](const json& s) { return s["state"] == "FAULT"; });
  ASSERT_EQ(st["state"], "FAULT") << st.dump() << "\n" << d.log();
  EXPECT_EQ(st["fault"].value("axis", -1), 1) << st.dump();
  EXPECT_EQ(st["fault"].value("axis_name", ""), "Y") << st.dump();
  EXPECT_FALSE(st["fault"].contains("node")) << st.dump();

  const auto c0 = st["cycle"].get<std::uint64_t>();
  const json refused = d.call({{"cmd", "reset"}});
  EXPECT_FALSE(refused.value("ok", true)) << refused.dump();
  EXPECT_EQ(refused.value("error", "").rfind("reset refused: ", 0), 0u) << refused.dump();
  st = d.ok({{"cmd", "status"}});
  EXPECT_GE(st["cycle"].get<std::uint64_t>(), c0 + 250) << "answered before the loop's window closed";
  EXPECT_EQ(st["state"], "FAULT") << st.dump();

  d.ok({{"cmd", "io"}, {"action", "unforce"}, {"name", "limit_y_pos"}});
  d.ok({{"cmd", "reset"}});
  st = d.wait_status([](const json& s) { return s["state"] == "READY"; });
  EXPECT_EQ(st["state"], "READY") << st.dump() << "\n" << d.log();
  EXPECT_EQ(d.terminate_and_wait(SIGTERM), 0) << d.log();
}
