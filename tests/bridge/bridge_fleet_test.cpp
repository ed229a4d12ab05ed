// Fleet scale in one machine (issue 22): 20 contourd instances on the simulated machine, each with
// its own socket, machine_id and contour-bridge, against one mosquitto broker; each runs Table 2;
// one subscriber must see every machine's job summary with the figures its daemon reported.
// Messages per second and publish -> receive latency are printed (the benchmark's numbers, never
// asserted: tools/contour-bridge/README.md "Fleet benchmark").
#include <gtest/gtest.h>

#include "tests/bridge/bridge_support.hpp"

namespace {

using namespace contour::test::bridge;
using nlohmann::json;
using std::chrono::seconds;

TEST(BridgeFleet, TwentyMachinesOneSubscriberSeesEveryJobSummary) {
  require_mosquitto();
  TempDir dir("fleet");
  Child fleet({bin("tools/contour-bridge/contour-bridge-fleet"), "--machines", "20", "--programs",
               "1", "--check"},
              dir / "fleet.out", dir / "fleet.err");
  const int rc = fleet.wait(seconds(500));
  std::printf("%s", fleet.out().c_str());
  ASSERT_NE(rc, -1) << "contour-bridge-fleet did not finish";
  ASSERT_EQ(rc, 0) << fleet.out() << fleet.err();
  std::istringstream in(fleet.out());
  std::string line, last;
  while (std::getline(in, line)) {
    if (!line.empty()) last = line;
  }
  const json r = json::parse(last);
  EXPECT_EQ(r["machines"], 20);
  EXPECT_EQ(r["job_summaries_expected"], 20);
  EXPECT_EQ(r["job_summaries_missing"], 0);
  EXPECT_EQ(r["job_summaries_mismatched"], 0);
  EXPECT_EQ(r["run_failures"], 0);
  EXPECT_EQ(r["topics"]["job"]["messages"].get<int>(), 20) << "one summary per run, no duplicates";
}

}  // namespace
