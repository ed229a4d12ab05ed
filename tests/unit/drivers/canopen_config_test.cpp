// The `bus:` section and its adapter to the master (config/bus_config, master_from_config.hpp).
#include <gtest/gtest.h>

#include "daemon/canopen_master_config.hpp"

namespace co = contour::drivers::canopen;
namespace cfg = contour::config;

TEST(BusConfig, HilYamlGivesThreeAxesAndASpindleWithTheLeanestMapping) {
  const auto c = cfg::load_config_file(CONTOUR_SOURCE_DIR "/config/hil.yaml");
  EXPECT_EQ(c.bus.type, "socketcan");
  EXPECT_EQ(c.bus.interface, "vcan0");
  const auto m = contour::daemon::master_config_from(c);
  ASSERT_EQ(m.nodes.size(), 4u);
  EXPECT_EQ(m.period_us, 1000u);
  EXPECT_EQ(m.bitrate, 1000000u);
  for (int i = 0; i < 3; ++i) {
    const auto& n = m.nodes[static_cast<std::size_t>(i)];
    EXPECT_EQ(n.node_id, i + 1);
    EXPECT_EQ(n.mode, co::DriveMode::kCsv);
    EXPECT_EQ(n.sync_every, 1);
    ASSERT_EQ(n.rpdo.count, 2u);
    EXPECT_EQ(n.rpdo.entries[1].mapping_word(), 0x60FF0020u);
    EXPECT_EQ(n.tpdo.entries[1].mapping_word(), 0x60640020u);
  }
  EXPECT_EQ(m.nodes[3].name, "spindle");
  EXPECT_EQ(m.nodes[3].node_id, 4);
  EXPECT_EQ(m.nodes[3].sync_every, 10);
  EXPECT_EQ(m.nodes[3].tpdo.entries[1].index, 0x606C);
}

TEST(BusConfig, BadEntriesAreErrorsWithFileLineAndKey) {
  const std::string y =
      "machine:\n  axes:\n    - {name: X, node_id: 1}\n"
      "bus:\n  type: socketcan\n  interface: vcan0\n  drives:\n    rpdo: [\"0x6040\", \"0x9999\"]\n"
      "    mode: cxx\n";
  try {
    cfg::load_config_string(y, "t.yaml");
    FAIL();
  } catch (const cfg::ConfigError& e) {
    std::string all;
    for (const auto& s : e.errors()) all += s + "\n";
    EXPECT_NE(all.find("t.yaml:8:"), std::string::npos) << all;
    EXPECT_NE(all.find("bus.drives.rpdo[1]"), std::string::npos) << all;
    EXPECT_NE(all.find("bus.drives.mode"), std::string::npos) << all;
  }
}

TEST(BusConfig, CspSwitchesTheDefaultRpdoToTargetPosition) {
  const std::string y =
      "machine:\n  axes:\n    - {name: X, node_id: 1}\n    - {name: Y, node_id: 2}\n"
      "bus:\n  nodes:\n    - {node_id: 2, mode: csp, identity: {vendor_id: 0x1234}}\n";
  const auto c = cfg::load_config_string(y, "t.yaml");
  const auto m = contour::daemon::master_config_from(c);
  ASSERT_EQ(m.nodes.size(), 2u);
  EXPECT_EQ(m.nodes[0].mode, co::DriveMode::kCsv);
  EXPECT_EQ(m.nodes[1].mode, co::DriveMode::kCsp);
  EXPECT_EQ(m.nodes[1].rpdo.entries[1].index, 0x607A);
  ASSERT_TRUE(m.nodes[1].vendor_id.has_value());
  EXPECT_EQ(*m.nodes[1].vendor_id, 0x1234u);
}

TEST(BusConfig, LockstepIsForSimulatedCanopenDrivesOnly) {
  EXPECT_TRUE(cfg::load_config_file(CONTOUR_SOURCE_DIR "/config/hil.yaml").bus_lockstep);
  EXPECT_FALSE(cfg::load_config_string("machine:\n  axes:\n    - {name: X, node_id: 1}\n"
                                       "bus:\n  type: socketcan\n  interface: vcan0\n")
                   .bus_lockstep);
  try {
    cfg::load_config_string(
        "machine:\n  axes:\n    - {name: X}\nbus:\n  type: sim\n  lockstep: true\n", "l.yaml");
    FAIL() << "lockstep accepted with type sim";
  } catch (const cfg::ConfigError& e) {
    std::string all;
    for (const auto& m : e.errors()) all += m + "\n";
    EXPECT_NE(all.find("l.yaml:6"), std::string::npos) << all;
    EXPECT_NE(all.find("bus.lockstep"), std::string::npos) << all;
  }
  try {
    cfg::load_config_string(
        "machine:\n  axes:\n    - {name: X, node_id: 1}\nbus:\n  type: socketcan\n"
        "  interface: vcan0\n  lockstep: maybe\n",
        "m.yaml");
    FAIL() << "lockstep: maybe accepted";
  } catch (const cfg::ConfigError& e) {
    std::string all;
    for (const auto& m : e.errors()) all += m + "\n";
    EXPECT_NE(all.find("bus.lockstep"), std::string::npos) << all;
  }
}
