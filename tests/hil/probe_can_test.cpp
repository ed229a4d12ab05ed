// `contourd --probe can` against contour-machine-sim on vcan0 (run under tools/with-vcan):
// nodes 1..4 of config/hil.yaml found with their NMT state and identity, and the probe leaves the
// drives as it found them (no NMT command, no SYNC, no PDO, no write to a CiA 402 object; the one
// write it may make, the heartbeat producer time 0x1017, is put back).
#include <sys/wait.h>

#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "tests/hil/canopen_hil_support.hpp"
#include "tools/contour-machine-sim/sim_drive.hpp"

using nlohmann::json;

namespace {

struct ProbeRun {
  int exit = -1;
  std::vector<json> lines;
};

ProbeRun probe(const std::string& extra = "") {
  const std::string cmd =
      std::string(CONTOUR_BINARY_DIR "/daemon/contourd --config " CONTOUR_SOURCE_DIR
                                     "/config/hil.yaml --probe can ") +
      extra;
  ProbeRun r;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return r;
  std::string out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int st = ::pclose(p);
  r.exit = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) {
    json j = json::parse(line, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << "not a JSON line: " << line;
    if (!j.is_discarded()) r.lines.push_back(std::move(j));
  }
  return r;
}

std::string hex8(std::uint32_t v) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08X", v);
  return b;
}

}  // namespace

TEST(ProbeCan, FindsNodesOneToFourWithNmtStateAndIdentityAndChangesNothing) {
  contour::test::Observer obs;
  ASSERT_TRUE(obs.ok()) << "vcan0 missing: run under tools/with-vcan";
  contour::test::MachineSim sim;
  ASSERT_TRUE(sim.ready()) << "contour-machine-sim did not start";

  const ProbeRun r = probe();
  ASSERT_EQ(r.exit, 0);
  const contour::sim::SimDriveSetup defaults;  // the identity the simulator serves
  const std::map<int, std::string> names = {{1, "X"}, {2, "Y"}, {3, "Z"}, {4, "spindle"}};
  std::map<int, json> by_node;
  for (const auto& j : r.lines)
    if (!j.contains("summary")) by_node[j["node_id"].get<int>()] = j;
  ASSERT_EQ(by_node.size(), 4u);
  for (const auto& [id, name] : names) {
    ASSERT_TRUE(by_node.count(id)) << "node " << id;
    const json& j = by_node[id];
    SCOPED_TRACE(j.dump());
    EXPECT_EQ(j["name"], name);
    EXPECT_EQ(j["configured"], true);
    EXPECT_EQ(j["found"], true);
    // The simulator powers on into pre-operational and nobody has started it.
    EXPECT_EQ(j["nmt"], "pre-operational");
    EXPECT_EQ(j["device_type"], hex8(0x00020192));  // CiA 402 servo drive
    EXPECT_EQ(j["vendor_id"], hex8(defaults.vendor_id));
    EXPECT_EQ(j["product_code"], hex8(defaults.product_code));
    EXPECT_EQ(j["revision"], hex8(defaults.revision));
    EXPECT_EQ(j["serial"], hex8(0x1000u + static_cast<std::uint32_t>(id)));
    EXPECT_TRUE(j.contains("statusword"));
    EXPECT_NE(j["cia402_state"], "operation enabled");
    EXPECT_TRUE(j["errors"].empty());
  }
  const json& sum = r.lines.back();
  EXPECT_EQ(sum["summary"], true);
  EXPECT_EQ(sum["answered"], 4);
  EXPECT_EQ(sum["exit"], 0);

  // What the probe put on the bus, seen by an independent socket.
  std::map<int, std::vector<std::uint32_t>> hb_writes;
  for (const auto& f : obs.take()) {
    const canid_t id = f.id & CAN_SFF_MASK;
    EXPECT_NE(id, 0x000u) << "an NMT command";
    EXPECT_NE(id, 0x080u) << "a SYNC";
    EXPECT_FALSE(id >= 0x200 && id < 0x580) << "an RPDO: 0x" << std::hex << id;
    if (id > 0x600 && id < 0x680 && f.dlc == 8 && (f.data[0] & 0xE0) == 0x20) {  // download
      const int node = static_cast<int>(id - 0x600);
      const unsigned index = f.data[1] | (f.data[2] << 8);
      ASSERT_EQ(index, 0x1017u) << "the probe wrote object 0x" << std::hex << index;
      hb_writes[node].push_back(static_cast<std::uint32_t>(f.data[4] | (f.data[5] << 8)));
    }
  }
  // Each node's heartbeat producer ends where it was (0 in the simulator's object dictionary).
  for (const auto& [node, w] : hb_writes) {
    ASSERT_FALSE(w.empty());
    EXPECT_EQ(w.back(), 0u) << "node " << node;
  }
}

TEST(ProbeCan, ScanFindsTheSameNodesAndAMissingNodeIsReported) {
  contour::test::Observer obs;
  ASSERT_TRUE(obs.ok()) << "vcan0 missing: run under tools/with-vcan";
  {
    // Without the simulator nothing answers: every configured node is reported missing.
    const ProbeRun r = probe();
    EXPECT_EQ(r.exit, 69);
    for (const auto& j : r.lines) {
      if (j.contains("summary")) continue;
      EXPECT_EQ(j["found"], false) << j.dump();
      EXPECT_FALSE(j["errors"].empty()) << j.dump();
    }
  }
  contour::test::MachineSim sim;
  ASSERT_TRUE(sim.ready()) << "contour-machine-sim did not start";
  const ProbeRun r = probe("--scan");
  EXPECT_EQ(r.exit, 0);
  std::vector<int> found;
  for (const auto& j : r.lines)
    if (!j.contains("summary") && j["found"] == true) found.push_back(j["node_id"].get<int>());
  EXPECT_EQ(found, (std::vector<int>{1, 2, 3, 4}));
}
