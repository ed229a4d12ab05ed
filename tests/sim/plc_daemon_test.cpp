// contourd (the built binary) with config/sim_plc.yaml: the soft PLC's example machine logic on
// the built-in simulated machine, through the socket (issue 20). A program runs; the door is
// opened (forced: the sim bus allows forcing) -> HOLD with the PLC's requests in `status.plc`;
// `resume` is refused while it is open and accepted once it is closed; the program completes.
// `io` lists the image with the forced flag, `plc_status` the programs' scan times; NC signals
// cannot be forced; without a plc: section `io` is refused. Waits are bounded polls.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tests/support/daemon_process.hpp"

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
  contour::test::DaemonProcess d("plc", with_config("/config/sim_plc.yaml"));
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

TEST(PlcDaemon, WithoutAPlcSectionIoIsRefused) {
  contour::test::DaemonProcess d("noplc", with_config("/config/sim.yaml"));
  ASSERT_TRUE(d.connected()) << d.log();
  const json r = d.call({{"cmd", "io"}});
  EXPECT_FALSE(r.value("ok", true));
  EXPECT_NE(r.value("error", std::string()).find("no soft PLC"), std::string::npos) << r.dump();
  EXPECT_EQ(d.ok({{"cmd", "plc_status"}})["present"], false);
  EXPECT_EQ(d.ok({{"cmd", "status"}})["plc"]["present"], false);
}

}  // namespace
