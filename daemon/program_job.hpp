#pragma once
// A part program handed from the planner thread to the servo loop: the interpolator (configured
// off-RT) and the planner's bounded segment queue of plain SegmentRecords.
#include <array>
#include <atomic>
#include <cstdint>

#include "control/fir_interpolator.hpp"
#include "daemon/spsc_ring.hpp"

namespace contour::daemon {

// PlannedSegment holds Eigen vectors (not trivially copyable): the planner -> loop queue carries
// this plain record and the loop converts it back (no allocation).
struct SegmentRecord {
  control::SegmentKind kind = control::SegmentKind::kMotion;
  std::int64_t start_cycle = 0;
  std::int64_t samples = 0;
  std::array<double, 3> start_mm{};
  std::array<double, 3> end_mm{};
  double length_mm = 0.0;
  double path_start_mm = 0.0;
  double feed_mm_min = 0.0;
  int line = 0;
  control::SpindleDir spindle = control::SpindleDir::kOff;
  double spindle_rpm = 0.0;
  bool mist = false;
  bool flood = false;
  int tool = 0;
  int message_id = -1;
  // Every field of PlannedSegment crosses: the fractional timing of the look-ahead planner, the
  // planned speed and the rapid flag, and a user M-code's number and words.
  double start_offset_cycles = 0.0;
  double duration_cycles = 0.0;
  double speed_mm_min = 0.0;
  bool rapid = false;
  int user_m = 0;
  double user_p = -1.0;
  double user_q = -1.0;
};
SegmentRecord to_record(const control::PlannedSegment& s) noexcept;
void from_record(const SegmentRecord& r, control::PlannedSegment& s) noexcept;

// A program handed to the loop: an interpolator configured off-RT and the planner's bounded
// segment queue. Owned by the non-RT side; the loop holds a raw pointer between attach and
// the acknowledgement (LoopStatus::attached_job / released_job).
struct ProgramJob {
  ProgramJob(std::uint64_t job_id, const control::InterpolatorParams& ip,
             const Eigen::Vector3d& start_mm, std::size_t queue_capacity)
      : id(job_id), queue(queue_capacity) {
    interp.configure(ip, start_mm);
  }
  std::uint64_t id = 0;
  control::Interpolator interp;
  SpscRing<SegmentRecord> queue;
  std::atomic<bool> planner_done{false};    // every segment has been pushed
  std::atomic<bool> planner_failed{false};  // planning error: the loop stops the program
  std::atomic<bool> abort{false};           // set by the loop/daemon: planner stops
};

}  // namespace contour::daemon
