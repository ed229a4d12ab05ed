// The command table (daemon/command_table.hpp): unique names, schema validation with the
// protocol's error texts, and daemon/PROTOCOL.md generated from it.
#include <gtest/gtest.h>

#include <fstream>
#include <set>
#include <sstream>

#include "daemon/command_protocol.hpp"
#include "daemon/command_table.hpp"

namespace contour::daemon {
namespace {

using nlohmann::json;

std::string error_of(const std::string& cmd, const json& req) {
  const CommandSpec* spec = find_command(cmd);
  if (spec == nullptr) return "no such command";
  try {
    validate_request(*spec, req, [](Bound b, const json&) -> std::pair<double, double> {
      return b == Bound::kJogVelocity ? std::pair{0.001, 3000.0} : std::pair{0.0, 150.0};
    });
  } catch (const CommandError& e) {
    return e.what();
  }
  return "";
}

TEST(CommandTable, NamesAreUniqueAndEveryCommandIsDocumented) {
  std::set<std::string_view> names;
  for (const CommandSpec& c : command_table()) {
    EXPECT_TRUE(names.insert(c.name).second) << c.name;
    EXPECT_FALSE(c.summary.empty()) << c.name;
    EXPECT_FALSE(c.states_text.empty()) << c.name;
    EXPECT_EQ(find_command(c.name), &c);
  }
  EXPECT_EQ(find_command("frobnicate"), nullptr);
  for (const char* n : {"status", "load", "run", "hold", "resume", "stop", "estop", "reset", "jog",
                        "gains", "override", "record", "subscribe", "force", "shutdown"}) {
    EXPECT_NE(find_command(n), nullptr) << n;
  }
}

TEST(CommandTable, SafetyCommandsAreEstopHoldAndStop) {
  std::set<std::string_view> safety;
  for (const CommandSpec& c : command_table()) {
    if (c.safety) safety.insert(c.name);
  }
  EXPECT_EQ(safety, (std::set<std::string_view>{"estop", "hold", "stop"}));
  EXPECT_TRUE(is_safety_command("estop"));
  EXPECT_FALSE(is_safety_command("run"));
  EXPECT_FALSE(is_safety_command("nope"));
}

TEST(CommandTable, RefusesWithTheProtocolsTexts) {
  EXPECT_EQ(error_of("status", {{"cmd", "status"}, {"id", 1}}), "");
  EXPECT_EQ(error_of("status", {{"cmd", "status"}, {"verbose", true}}), "unknown argument 'verbose'");
  EXPECT_EQ(error_of("jog", {{"axis", "X"}, {"distance_mm", 1}}), "missing argument 'velocity_mm_min'");
  EXPECT_EQ(error_of("jog", {{"axis", "X"}, {"velocity_mm_min", "fast"}, {"distance_mm", 1}}),
            "argument 'velocity_mm_min' must be a number");
  EXPECT_EQ(error_of("jog", {{"axis", "X"}, {"velocity_mm_min", 5000}, {"distance_mm", 1}}),
            "argument 'velocity_mm_min' = 5000.000000 out of range [0.001000, 3000.000000]");
  EXPECT_EQ(error_of("jog", {{"axis", true}, {"velocity_mm_min", 50}, {"distance_mm", 1}}),
            "argument 'axis' must be an axis name or index");
  EXPECT_EQ(error_of("jog", {{"axis", "X"}, {"velocity_mm_min", 50}, {"distance_mm", 2e4}}),
            "argument 'distance_mm' = 20000.000000 out of range [-10000.000000, 10000.000000]");
  EXPECT_EQ(error_of("record", {{"action", "pause"}}), "argument 'action' must be \"start\" or \"stop\"");
  EXPECT_EQ(error_of("subscribe", {{"topic", "x"}}), "argument 'topic' must be \"telemetry\" or \"events\"");
  EXPECT_EQ(error_of("result", {{"job", -1}}), "argument 'job' must be a job number");
  EXPECT_EQ(error_of("sim_gpio", {{"line", "estop"}, {"level", 2}}),
            "argument 'level' must be 0 or 1 (physical level)");
  EXPECT_EQ(error_of("sim_gpio", {{"line", "estop"}, {"level", true}}), "");
  EXPECT_EQ(error_of("force", {{"enable", "yes"}}), "argument 'enable' must be true or false");
  EXPECT_EQ(error_of("override", {{"percent", 151}}),
            "argument 'percent' = 151.000000 out of range [0.000000, 150.000000]");
}

TEST(CommandTable, GatedCommandsNameTheStateTheyAreRefusedIn) {
  const CommandSpec& hold = *find_command("hold");
  EXPECT_NO_THROW(check_state(hold, MachineState::kRunning));
  try {
    check_state(hold, MachineState::kReady);
    FAIL() << "hold in READY must be refused";
  } catch (const CommandError& e) {
    EXPECT_STREQ(e.what(), "hold is not allowed in state READY");
  }
  // Not gated: the handler decides (its messages say more).
  EXPECT_NO_THROW(check_state(*find_command("stop"), MachineState::kDisabled));
}

TEST(CommandTable, ProtocolDocumentIsGeneratedFromTheTable) {
  std::ifstream in(std::string(CONTOUR_SOURCE_DIR) + "/daemon/PROTOCOL.md");
  ASSERT_TRUE(in) << "daemon/PROTOCOL.md missing: contourd --protocol > daemon/PROTOCOL.md";
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_EQ(ss.str(), protocol_markdown())
      << "daemon/PROTOCOL.md is out of date: regenerate with `contourd --protocol > daemon/PROTOCOL.md`";
  for (const CommandSpec& c : command_table()) {
    EXPECT_NE(ss.str().find("`" + std::string(c.name) + "`"), std::string::npos) << c.name;
  }
}

}  // namespace
}  // namespace contour::daemon
