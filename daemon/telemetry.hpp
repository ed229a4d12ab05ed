#pragma once
// Telemetry writer (non-RT thread): drains the loop's SPSC telemetry ring, writes CSV while
// recording, forwards samples to a stream callback (socket subscribers), and keeps per-program
// run statistics:
//   max/RMS TRUE contour error = distance from the measured tool position to the planned path
//   (the PlannedSegments the planner hands over: lines and arc chords within
//   arc_chord_fraction * tolerance of the programmed arcs; exact for G01 programs), searched over
//   the segments within +-10 mm of path progress of the reference; plus the model's |eps|.
// Statistics are taken over the samples the ring delivered (decimation applies); dropped samples
// are counted (SpscRing::dropped) and reported with the run. Samples past the end point along the
// last segment (after the reference arrived) are along-path overshoot, reported separately.
#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <deque>
#include <fstream>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "control/fir_interpolator.hpp"
#include "daemon/servo_loop.hpp"

namespace contour::daemon {

struct RunStats {
  std::uint64_t job = 0;
  std::uint64_t samples = 0;
  std::uint64_t first_cycle = 0;
  std::uint64_t last_cycle = 0;
  double max_contour_error_um = 0.0;   // true distance to the planned path
  double sum_sq_um2 = 0.0;
  double max_model_error_um = 0.0;     // |eps| of the RT model
  double max_following_error_um = 0.0;
  double end_overshoot_um = 0.0;       // past the end point along the path (excluded above)
  [[nodiscard]] double rms_contour_error_um() const;
  [[nodiscard]] double duration_s(double period_s) const;
};

class TelemetryWriter {
 public:
  using Stream = std::function<void(const TelemetrySample&)>;

  TelemetryWriter(SpscRing<TelemetrySample>& ring, double period_s);
  ~TelemetryWriter();
  TelemetryWriter(const TelemetryWriter&) = delete;
  TelemetryWriter& operator=(const TelemetryWriter&) = delete;

  void start();  // writer thread (drains every 2 ms)
  void stop();   // drains what is left, closes the CSV
  // Synchronous drain on the caller's thread (in-process tests; not with start()).
  void drain();

  // Geometry of a program (called from the planner thread).
  void begin_job(std::uint64_t job);
  void add_segment(std::uint64_t job, const control::PlannedSegment& s);

  // CSV recording (throws std::runtime_error when the file cannot be opened).
  void start_recording(const std::string& path);
  std::string stop_recording();  // returns the path ("" if not recording)
  [[nodiscard]] bool recording() const;

  void set_stream(Stream s, int every_n);

  [[nodiscard]] RunStats stats(std::uint64_t job) const;  // zeros when unknown
  [[nodiscard]] std::uint64_t last_cycle() const noexcept {
    return last_cycle_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t dropped() const noexcept { return ring_.dropped(); }
  [[nodiscard]] std::uint64_t written() const noexcept { return written_.load(); }

 private:
  struct Geo {
    Eigen::Vector3d a, b;
    double s0, s1;
  };
  void consume(const TelemetrySample& s);
  double true_distance(const Eigen::Vector3d& p, double progress_mm, const Eigen::Vector3d& ref,
                       bool* beyond_end);

  SpscRing<TelemetrySample>& ring_;
  double period_s_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  mutable std::mutex mu_;  // geometry, stats, csv, stream (non-RT threads only)
  std::uint64_t geo_job_ = 0;
  std::deque<Geo> geo_;
  RunStats current_{};
  RunStats last_{};
  std::ofstream csv_;
  std::string csv_path_;
  Stream stream_;
  int stream_every_ = 10;
  std::atomic<std::uint64_t> last_cycle_{0};
  std::atomic<std::uint64_t> written_{0};
};

}  // namespace contour::daemon
