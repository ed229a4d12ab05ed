// The planner's segments cross to the loop as SegmentRecords (daemon/program_job.hpp): every field
// the interpolator or the loop reads must survive the round trip. Before this test the fractional
// start offset and duration of the look-ahead planner, the planned speed, the rapid flag and the
// user M-code's number and words were dropped (the loop then ran whole-period blocks that the
// planner had not verified, and could not hand M100..M199 to the machine logic).
#include <gtest/gtest.h>

#include "daemon/program_job.hpp"

namespace contour::daemon {
namespace {

TEST(SegmentRecord, EveryFieldTheLoopReadsSurvivesTheRoundTrip) {
  control::PlannedSegment s;
  s.kind = control::SegmentKind::kUserMcode;
  s.start_cycle = 1234;
  s.samples = 17;
  s.start_offset_cycles = 0.375;
  s.duration_cycles = 16.25;
  s.start_mm = {1.0, -2.0, 3.5};
  s.end_mm = {4.0, 5.0, -6.25};
  s.length_mm = 7.5;
  s.path_start_mm = 99.0;
  s.feed_mm_min = 1500.0;
  s.speed_mm_min = 1234.5;
  s.line = 42;
  s.rapid = true;
  s.spindle = control::SpindleDir::kCcw;
  s.spindle_rpm = 8000.0;
  s.mist = true;
  s.flood = true;
  s.tool = 7;
  s.message_id = 3;
  s.user_m = 123;
  s.user_p = 2.5;
  s.user_q = -1.0;

  control::PlannedSegment back;
  from_record(to_record(s), back);
  EXPECT_EQ(back.kind, s.kind);
  EXPECT_EQ(back.start_cycle, s.start_cycle);
  EXPECT_EQ(back.samples, s.samples);
  EXPECT_EQ(back.start_offset_cycles, s.start_offset_cycles);
  EXPECT_EQ(back.duration_cycles, s.duration_cycles);
  EXPECT_EQ(back.start_mm, s.start_mm);
  EXPECT_EQ(back.end_mm, s.end_mm);
  EXPECT_EQ(back.length_mm, s.length_mm);
  EXPECT_EQ(back.path_start_mm, s.path_start_mm);
  EXPECT_EQ(back.feed_mm_min, s.feed_mm_min);
  EXPECT_EQ(back.speed_mm_min, s.speed_mm_min);
  EXPECT_EQ(back.line, s.line);
  EXPECT_EQ(back.rapid, s.rapid);
  EXPECT_EQ(back.spindle, s.spindle);
  EXPECT_EQ(back.spindle_rpm, s.spindle_rpm);
  EXPECT_EQ(back.mist, s.mist);
  EXPECT_EQ(back.flood, s.flood);
  EXPECT_EQ(back.tool, s.tool);
  EXPECT_EQ(back.message_id, s.message_id);
  EXPECT_EQ(back.user_m, s.user_m);
  EXPECT_EQ(back.user_p, s.user_p);
  EXPECT_EQ(back.user_q, s.user_q);
  // The interpolator's timing of the segment is the planner's, to the bit.
  EXPECT_EQ(control::segment_duration(back), control::segment_duration(s));
}

}  // namespace
}  // namespace contour::daemon
