// HIL: a CiA 401 I/O module on the CAN bus, bound to the soft PLC (issue 20), with contourd
// driving contour-machine-sim over vcan0 in lockstep. Both are child processes:
//   contour-machine-sim --config config/hil.yaml --can vcan0 --io-module 5:2:1:1:1 --io-input
//   5:2:16 contourd --config <tmp>/c.yaml = config/hil.yaml (load ceiling raised, see below) + a
//   plc:
//            section binding node 5's 0x6000:01/:02, 0x6200:01, 0x6401:01, 0x6411:01
// The simulated module loops its outputs to its inputs (0x6000:01 = 0x6200:01, 0x6401:01 =
// 0x6411:01) and has 0x6000:02 pinned to 0x10: a PLC output written by the program reaches the
// module (its summary) and comes back as an input; the pinned input reaches the PLC (`io`). A
// module that stops sending its TPDO (--drop-tpdo 5:SYNC) faults the machine naming node 5.
// Waits are bounded polls (heavy steal time here); no wall-clock assertion.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "tests/hil/canopen_hil_support.hpp"
#include "tests/support/daemon_process.hpp"

namespace {

using nlohmann::json;
namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::string kSrc = CONTOUR_SOURCE_DIR;

std::size_t replace_all(std::string& s, const std::string& from, const std::string& to) {
  std::size_t n = 0;
  for (auto at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size())) {
    s.replace(at, from.size(), to);
    ++n;
  }
  return n;
}

class Files {
 public:
  // `ceiling`: bus.load_ceiling_percent. config/hil.yaml (three axes and a spindle) is at 77 %
  // worst case of its 80 % ceiling; the module's TPDO (4 bytes) and RPDO (3 bytes) add 18 %
  // (95 + 85 bits a 1 ms cycle at 1 Mbit/s). vcan has no bit rate: 100 % lets it run.
  explicit Files(const std::string& tag, int ceiling = 100)
      : dir(fs::temp_directory_path() / ("cia401_hil_" + tag + "_" + std::to_string(::getpid()))) {
    fs::create_directories(dir);
    std::ofstream(dir / "io401.st")
        << "PROGRAM io401\n  clamp := TRUE;\n  valve_pos := 12.5;\nEND_PROGRAM\n";
    std::string hil = contour::test::slurp(kSrc + "/config/hil.yaml");
    EXPECT_EQ(hil.find("\nplc:"), std::string::npos) << "config/hil.yaml has a plc: section now";
    EXPECT_EQ(replace_all(hil, "load_ceiling_percent: 80",
                          "load_ceiling_percent: " + std::to_string(ceiling)),
              1U);
    std::ofstream(dir / "c.yaml")
        << hil << "\nplc:\n  programs: [{file: " << (dir / "io401.st").string() << "}]\n"
        << "  signals:\n"
           "    - {name: clamp, cia401: {node: 5, digital_output: 1, bit: 2}}\n"
           "    - {name: clamp_fb, cia401: {node: 5, digital_input: 1, bit: 2}}\n"
           "    - {name: part_present, cia401: {node: 5, digital_input: 2, bit: 4}}\n"
           "    - {name: valve_pos, type: REAL, cia401: {node: 5, analog_output: 1, scale: 0.5}}\n"
           "    - {name: valve_fb, type: REAL, cia401: {node: 5, analog_input: 1, scale: 0.5}}\n";
  }
  ~Files() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  [[nodiscard]] std::string config() const { return (dir / "c.yaml").string(); }
  fs::path dir;
};

json signal(const json& io, const std::string& name) {
  for (const auto& s : io["signals"])
    if (s["name"] == name) return s;
  ADD_FAILURE() << "no signal " << name << " in " << io.dump();
  return json::object();
}

json last_json_line(const std::string& out) {
  std::string last;
  std::size_t at = 0;
  while (at < out.size()) {
    const auto nl = out.find('\n', at);
    const std::string l = out.substr(at, nl == std::string::npos ? std::string::npos : nl - at);
    if (!l.empty()) last = l;
    if (nl == std::string::npos) break;
    at = nl + 1;
  }
  return json::parse(last, nullptr, false);
}

json module_of(const json& summary, int node) {
  for (const auto& n : summary["nodes"])
    if (n["node_id"] == node) return n;
  ADD_FAILURE() << "no node " << node << " in " << summary.dump();
  return json::object();
}

TEST(Cia401Hil, ProgramOutputsReachTheModuleAndItsInputsReachThePlc) {
  {
    // The module's frames count in the start-up's bus-load estimate: at hil.yaml's 80 % ceiling
    // there is no room for them, and contourd says so before it starts the nodes.
    Files f80("ceiling", 80);
    contour::test::DaemonProcess d("cia401_ceiling", {f80.config(), {}, 3000, 0});
    EXPECT_FALSE(d.connected()) << d.log();
    EXPECT_NE(d.log().find("exceeds the ceiling of 80.0 %"), std::string::npos) << d.log();
  }
  Files files("io");
  contour::test::MachineSim sim({"--io-module", "5:2:1:1:1", "--io-input", "5:2:16"},
                                files.config());
  ASSERT_TRUE(sim.ready()) << sim.poll_output();
  EXPECT_NE(sim.poll_output().find("5(io5)"), std::string::npos) << sim.poll_output();
  contour::test::DaemonProcess d("cia401", {files.config(), {}, 6000, 3000});
  ASSERT_TRUE(d.connected()) << d.log();
  ASSERT_EQ(d.state(), "READY") << d.log();
  EXPECT_NE(d.log().find("node 5 (I/O module): CiA 401 I/O module"), std::string::npos) << d.log();

  // Bounded poll: the program's outputs go out in the RPDO, the module loops them back in its
  // TPDO, the next scan sees them.
  json io;
  for (int i = 0; i < 3000; ++i) {
    io = d.ok({{"cmd", "io"}});
    if (signal(io, "clamp_fb")["value"] == true && signal(io, "valve_fb")["value"] == 12.5) break;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_EQ(signal(io, "clamp")["value"], true) << io.dump();
  EXPECT_EQ(signal(io, "clamp_fb")["value"], true) << io.dump();
  EXPECT_EQ(signal(io, "valve_fb")["value"], 12.5) << io.dump();
  EXPECT_EQ(signal(io, "part_present")["value"], true) << io.dump();  // 0x6000:02 = 0x10: bit 4
  EXPECT_EQ(signal(io, "part_present")["source"].get<std::string>().find("cia401 node 5 0x6000:02"),
            0U)
      << io.dump();
  EXPECT_EQ(d.ok({{"cmd", "status"}})["state"], "READY");

  // The field: the module's own objects (the simulator's summary, taken while contourd still
  // drives it: its stop() sends the outputs as 0).
  const json summary = last_json_line(sim.stop());
  ASSERT_TRUE(summary.is_object()) << sim.poll_output();
  const json m = module_of(summary, 5);
  EXPECT_EQ(m["io"]["0x6200"], json::array({4})) << m.dump();   // bit 2
  EXPECT_EQ(m["io"]["0x6411"], json::array({25})) << m.dump();  // 12.5 / scale 0.5
  EXPECT_EQ(m["io"]["0x6000"], json::array({4, 16})) << m.dump();
  EXPECT_EQ(m["io"]["0x6401"], json::array({25})) << m.dump();
  EXPECT_EQ(m["nmt"], "operational") << m.dump();
}

TEST(Cia401Hil, AModuleThatStopsSendingItsTpdoFaultsTheMachineNamingTheNode) {
  Files files("drop");
  // From SYNC 3000 on (3 s of lockstep after NMT start) the module sends no TPDO; its heartbeat
  // goes on, so the cause is the missing inputs, not a lost node.
  contour::test::MachineSim sim({"--io-module", "5:2:1:1:1", "--drop-tpdo", "5:3000"},
                                files.config());
  ASSERT_TRUE(sim.ready()) << sim.poll_output();
  contour::test::DaemonProcess d("cia401_drop", {files.config(), {}, 6000, 0});
  ASSERT_TRUE(d.connected()) << d.log();
  const json st = d.wait_status([](const json& s) { return s["state"] == "FAULT"; });
  ASSERT_EQ(st["state"], "FAULT") << st.dump() << "\n" << d.log();
  EXPECT_EQ(st["cause"], "I/O module fault") << st.dump();
  EXPECT_EQ(st["fault"].value("axis", 0), 5) << "the node-id: " << st.dump();
  EXPECT_EQ(st["fault"].value("node", 0), 5) << "fault.node names the module: " << st.dump();
  // The log names the node, in the FAULT line and the master's event.
  std::string log;
  for (int i = 0; i < 500; ++i) {
    log = d.log();
    if (log.find("node 5 (I/O module): 3 TPDOs missed in a row") != std::string::npos) break;
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_NE(log.find("FAULT I/O module fault node 5: 3 missed TPDOs in a row"), std::string::npos)
      << log;
  EXPECT_NE(log.find("node 5 (I/O module): 3 TPDOs missed in a row"), std::string::npos) << log;
}

}  // namespace
