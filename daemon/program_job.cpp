#include "daemon/program_job.hpp"

namespace contour::daemon {

SegmentRecord to_record(const control::PlannedSegment& s) noexcept {
  SegmentRecord r;
  r.kind = s.kind;
  r.start_cycle = s.start_cycle;
  r.samples = s.samples;
  for (int i = 0; i < 3; ++i) {
    r.start_mm[static_cast<std::size_t>(i)] = s.start_mm[i];
    r.end_mm[static_cast<std::size_t>(i)] = s.end_mm[i];
  }
  r.length_mm = s.length_mm;
  r.path_start_mm = s.path_start_mm;
  r.feed_mm_min = s.feed_mm_min;
  r.line = s.line;
  r.spindle = s.spindle;
  r.spindle_rpm = s.spindle_rpm;
  r.mist = s.mist;
  r.flood = s.flood;
  r.tool = s.tool;
  r.message_id = s.message_id;
  r.start_offset_cycles = s.start_offset_cycles;
  r.duration_cycles = s.duration_cycles;
  r.speed_mm_min = s.speed_mm_min;
  r.rapid = s.rapid;
  r.user_m = s.user_m;
  r.user_p = s.user_p;
  r.user_q = s.user_q;
  return r;
}

void from_record(const SegmentRecord& r, control::PlannedSegment& s) noexcept {
  s.kind = r.kind;
  s.start_cycle = r.start_cycle;
  s.samples = r.samples;
  for (int i = 0; i < 3; ++i) {
    s.start_mm[i] = r.start_mm[static_cast<std::size_t>(i)];
    s.end_mm[i] = r.end_mm[static_cast<std::size_t>(i)];
  }
  s.length_mm = r.length_mm;
  s.path_start_mm = r.path_start_mm;
  s.feed_mm_min = r.feed_mm_min;
  s.line = r.line;
  s.spindle = r.spindle;
  s.spindle_rpm = r.spindle_rpm;
  s.mist = r.mist;
  s.flood = r.flood;
  s.tool = r.tool;
  s.message_id = r.message_id;
  s.start_offset_cycles = r.start_offset_cycles;
  s.duration_cycles = r.duration_cycles;
  s.speed_mm_min = r.speed_mm_min;
  s.rapid = r.rapid;
  s.user_m = r.user_m;
  s.user_p = r.user_p;
  s.user_q = r.user_q;
}

}  // namespace contour::daemon
