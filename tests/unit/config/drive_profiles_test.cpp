// Drive profiles (issue 17): bus.profiles / bus.profile_files / bus.*.profile, validation with
// file:line, the shipped profile files equal the built-ins.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "config/config.hpp"
#include "config/drive_profiles.hpp"
#include "tests/support/temp_dir.hpp"

namespace cfg = contour::config;

namespace {

std::string errors_of(const std::string& yaml, const std::string& name = "t.yaml") {
  try {
    cfg::load_config_string(yaml, name);
  } catch (const cfg::ConfigError& e) {
    std::string all;
    for (const auto& s : e.errors()) all += s + "\n";
    return all;
  }
  return "";
}

const char* kMachine = "machine:\n  axes:\n    - {name: X, node_id: 1}\n    - {name: Y, node_id: 2}\n";

}  // namespace

TEST(DriveProfiles, ExistingConfigsGetTheGenericProfile) {
  for (const char* f : {"/config/hil.yaml", "/config/sim.yaml"}) {
    const auto c = cfg::load_config_file(std::string(CONTOUR_SOURCE_DIR) + f);
    EXPECT_EQ(c.bus.drive_defaults.profile.name, "generic") << f;
    for (const auto& n : cfg::resolve_bus_nodes(c.bus, c.machine)) {
      EXPECT_EQ(n.profile.name, "generic") << f;
      EXPECT_TRUE(n.profile.same_settings(cfg::builtin_drive_profiles().at("generic")));
    }
  }
}

TEST(DriveProfiles, ShippedProfileFilesRestateTheBuiltIns) {
  const auto builtin = cfg::builtin_drive_profiles();
  for (const char* name : {"generic", "contour-machine-sim"}) {
    const auto m = cfg::load_drive_profile_file(std::string(CONTOUR_SOURCE_DIR) + "/config/drives/" +
                                                name + ".yaml");
    ASSERT_EQ(m.count(name), 1u) << name;
    EXPECT_TRUE(m.at(name).same_settings(builtin.at(name))) << name;
  }
}

TEST(DriveProfiles, InlineProfilePerDriveAndPerNode) {
  const std::string y = std::string(kMachine) +
                        "bus:\n"
                        "  type: socketcan\n  interface: vcan0\n"
                        "  profiles:\n"
                        "    acme-x1:\n"
                        "      description: ACME X1, EDS rev 1.2\n"
                        "      skip_objects: [\"0x1006\", \"0x60C2:02\", \"0x605A\", \"0x6085\"]\n"
                        "      rpdos: 1\n      tpdos: 1\n"
                        "      rpdo_max_entries: 2\n      tpdo_max_entries: 2\n"
                        "      sdo: expedited_only\n      tpdo_sampling: after_step\n"
                        "  drives: {profile: acme-x1}\n"
                        "  nodes:\n    - {node_id: 2, profile: generic}\n";
  const auto c = cfg::load_config_string(y, "t.yaml");
  const auto nodes = cfg::resolve_bus_nodes(c.bus, c.machine);
  ASSERT_EQ(nodes.size(), 2u);
  const auto& p = nodes[0].profile;
  EXPECT_EQ(p.name, "acme-x1");
  EXPECT_EQ(p.description, "ACME X1, EDS rev 1.2");
  ASSERT_EQ(p.skip_objects.size(), 4u);
  EXPECT_EQ(p.skip_objects[0], (cfg::ProfileObject{0x1006, -1}));
  EXPECT_EQ(p.skip_objects[1], (cfg::ProfileObject{0x60C2, 2}));
  EXPECT_EQ(p.rpdos, 1);
  EXPECT_EQ(p.tpdo_max_entries, 2);
  EXPECT_EQ(p.sdo, "expedited_only");
  EXPECT_EQ(p.tpdo_sampling, "after_step");
  EXPECT_EQ(nodes[1].profile.name, "generic");
}

TEST(DriveProfiles, ProfileFilesAreRelativeToTheConfigFile) {
  const std::string dir = contour::test::process_temp_dir();
  {
    std::ofstream f(dir + "/acme.yaml");
    f << "acme:\n  rpdos: 1\n  tpdos: 1\n";
  }
  const std::string y = std::string(kMachine) + "bus:\n  profile_files: [acme.yaml]\n"
                                                "  drives: {profile: acme}\n";
  const auto c = cfg::load_config_string(y, dir + "/t.yaml");
  EXPECT_EQ(c.bus.drive_defaults.profile.name, "acme");
  EXPECT_EQ(c.bus.drive_defaults.profile.rpdos, 1);
  {
    std::ofstream f(dir + "/bad.yaml");
    f << "acme:\n  rpdos: 1\n  colour: red\n";
  }
  const std::string bad = std::string(kMachine) + "bus:\n  profile_files: [bad.yaml]\n";
  const auto e = errors_of(bad, dir + "/t.yaml");
  EXPECT_NE(e.find("t.yaml:6:19: bus.profile_files[0]: " + dir + "/bad.yaml:3:3: acme.colour: "
                   "unknown key"),
            std::string::npos)
      << e;
  EXPECT_NE(errors_of(std::string(kMachine) + "bus:\n  profile_files: [nope.yaml]\n", dir + "/t.yaml")
                .find("nope.yaml: cannot open file"),
            std::string::npos);
}

TEST(DriveProfiles, BadProfilesAreErrorsWithFileLineAndKey) {
  const std::string y = std::string(kMachine) +
                        "bus:\n"
                        "  profiles:\n"
                        "    acme:\n"
                        "      rpdos: 5\n"                        // line 8
                        "      sdo: sometimes\n"                  // line 9
                        "      skip_objects: [\"0x6060\", \"x\"]\n"  // line 10
                        "      tpdo_sampling: later\n"            // line 11
                        "      colour: red\n"                     // line 12
                        "    generic: {rpdos: 1}\n"               // line 13
                        "  drives: {profile: acme-x9}\n";         // line 14
  const auto e = errors_of(y);
  EXPECT_NE(e.find("t.yaml:8:14: bus.profiles.acme.rpdos:"), std::string::npos) << e;
  EXPECT_NE(e.find("t.yaml:9:12: bus.profiles.acme.sdo:"), std::string::npos) << e;
  EXPECT_NE(e.find("t.yaml:10:22: bus.profiles.acme.skip_objects[0]: object 0x6060 cannot be "
                   "skipped"),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("t.yaml:10:32: bus.profiles.acme.skip_objects[1]: expected"), std::string::npos) << e;
  EXPECT_NE(e.find("t.yaml:11:22: bus.profiles.acme.tpdo_sampling:"), std::string::npos) << e;
  EXPECT_NE(e.find("t.yaml:12:7: bus.profiles.acme.colour: unknown key"), std::string::npos) << e;
  EXPECT_NE(e.find("t.yaml:13:5: bus.profiles.generic: 'generic' is a built-in profile and cannot "
                   "be changed"),
            std::string::npos)
      << e;
  EXPECT_NE(e.find("t.yaml:14:21: bus.drives.profile: unknown drive profile 'acme-x9' (known: "
                   "acme, contour-machine-sim, generic"),
            std::string::npos)
      << e;
}

TEST(DriveProfiles, MappingThatDoesNotFitTheDrivesPdoIsAnError) {
  const std::string y = std::string(kMachine) +
                        "bus:\n"
                        "  profiles:\n"
                        "    small: {tpdo_max_entries: 2}\n"
                        "  drives:\n"
                        "    profile: small\n"
                        "    tpdo: [\"0x6041\", \"0x6064\", \"0x6061\"]\n";  // line 10
  const auto e = errors_of(y);
  EXPECT_NE(e.find("t.yaml:10:11: bus.drives.tpdo: tpdo maps 3 objects, drive profile 'small' "
                   "allows 2 per PDO (tpdo_max_entries)"),
            std::string::npos)
      << e;
  // Inherited mapping, node changes the profile: the error is at the node's profile key.
  const std::string y2 = std::string(kMachine) +
                         "bus:\n"
                         "  profiles:\n"
                         "    small: {tpdo_max_entries: 1}\n"
                         "  nodes:\n"
                         "    - {node_id: 2, profile: small}\n";  // line 9
  const auto e2 = errors_of(y2);
  EXPECT_NE(e2.find("t.yaml:9:29: bus.nodes[0].profile: tpdo maps 2 objects"), std::string::npos)
      << e2;
}
