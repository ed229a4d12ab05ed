// Run from line (issue 18, LinuxCNC's "run from line"): the lines before the start line set the
// modal state only; the run begins with a tool-change pause when they changed the tool, and a
// safe approach (up to the clearance, across as a rapid, down at the modal feed) to where the
// start line begins.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>
#include <vector>

#include "daemon/planner.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

// Plans src from start_mm and returns every planned segment in order.
std::vector<control::PlannedSegment> plan_all(ProgramPlanner& p, const ProgramText& src,
                                              const Eigen::Vector3d& start_mm) {
  std::vector<control::PlannedSegment> segs;
  auto job = p.start(src, start_mm, 1, [&segs](std::uint64_t, const control::PlannedSegment& s) {
    segs.push_back(s);
  });
  SegmentRecord rec;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!(job->planner_done.load() && job->queue.size() == 0) && !job->planner_failed.load() &&
         std::chrono::steady_clock::now() < until) {
    if (!job->queue.pop(rec)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  EXPECT_TRUE(job->planner_done.load()) << p.error();
  return segs;
}

std::vector<control::PlannedSegment> motion(const std::vector<control::PlannedSegment>& s) {
  std::vector<control::PlannedSegment> m;
  for (const auto& x : s) {
    if (x.kind == control::SegmentKind::kMotion && x.length_mm > 1e-9) m.push_back(x);
  }
  return m;
}

const char* kProgram =
    "G21 G90 G54\n"       // 1
    "T2 M6\n"             // 2
    "G43 H2\n"            // 3  (tool 2: 12.5 mm in config/sim.yaml)
    "M3 S3000\n"          // 4
    "G0 X0 Y0 Z10\n"      // 5  machine Z 22.5: the clearance
    "G1 Z-1 F300\n"       // 6
    "G1 X20 F600\n"       // 7
    "G1 Y20\n"            // 8  <- start here
    "G0 Z10\n"            // 9
    "G0 X40\n"            // 10
    "G1 Z-2 F200\n"       // 11
    "G1 X50\n"            // 12
    "M5\n"                // 13
    "M2\n";               // 14

void expect_point(const Eigen::Vector3d& got, const Eigen::Vector3d& want, const char* what) {
  EXPECT_LT((got - want).norm(), 1e-9) << what << ": " << got.transpose() << " want " << want.transpose();
}

TEST(RunFromLine, SkippedLinesSetTheStateAndASafeApproachLeadsToTheStartLine) {
  const auto cfg = test_rig::sim_config();
  ProgramPlanner p(cfg);
  ProgramText src{"<test>", "", kProgram};
  src.start_line = 8;
  const Eigen::Vector3d start(5.0, 5.0, 0.0);
  const auto segs = plan_all(p, src, start);
  ASSERT_FALSE(segs.empty());
  // The skipped lines loaded tool 2 (the machine has none): its pause comes first.
  EXPECT_EQ(segs.front().kind, control::SegmentKind::kToolChange);
  EXPECT_EQ(segs.front().tool, 2);
  const auto m = motion(segs);
  ASSERT_GE(m.size(), 8u);
  // Up from where the machine stands to the clearance, across, down at the program's feed.
  expect_point(m[0].start_mm, start, "approach start");
  expect_point(m[0].end_mm, {5, 5, 22.5}, "up");
  EXPECT_TRUE(m[0].rapid);
  expect_point(m[1].end_mm, {20, 0, 22.5}, "across");
  EXPECT_TRUE(m[1].rapid);
  expect_point(m[2].end_mm, {20, 0, 11.5}, "down to line 8's start (Z -1 + 12.5)");
  EXPECT_FALSE(m[2].rapid);
  EXPECT_DOUBLE_EQ(m[2].feed_mm_min, 600.0);
  // Then line 8 itself, with the recovered modal state (spindle on at 3000 rpm, tool 2).
  EXPECT_EQ(m[3].line, 8);
  expect_point(m[3].end_mm, {20, 20, 11.5}, "line 8");
  EXPECT_EQ(m[3].spindle, control::SpindleDir::kCw);
  EXPECT_EQ(m[3].spindle_rpm, 3000.0);
  EXPECT_EQ(m[3].tool, 2);
  for (const auto& s : m) EXPECT_TRUE(s.line >= 8) << "a skipped line ran: " << s.line;
  expect_point(m.back().end_mm, {50, 20, 10.5}, "program end (Z -2 + 12.5)");
  // A spindle start before the first feed move: the approach's plunge waits for the spindle.
  bool sync_before_plunge = false;
  for (const auto& s : segs) {
    if (s.kind == control::SegmentKind::kSpindleSync) sync_before_plunge = true;
    if (s.kind == control::SegmentKind::kMotion && !s.rapid && s.length_mm > 0) break;
  }
  EXPECT_TRUE(sync_before_plunge);
}

TEST(RunFromLine, FromTheFirstLineIsTheWholeProgram) {
  const auto cfg = test_rig::sim_config();
  ProgramPlanner p(cfg);
  ProgramText whole{"<test>", "", kProgram};
  ProgramText one{"<test>", "", kProgram};
  one.start_line = 1;
  const auto a = motion(plan_all(p, whole, Eigen::Vector3d::Zero()));
  const auto b = motion(plan_all(p, one, Eigen::Vector3d::Zero()));
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) expect_point(b[i].end_mm, a[i].end_mm, "same path");
}

}  // namespace
}  // namespace contour::daemon
