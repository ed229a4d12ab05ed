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
//
// The telemetry subscription (issue 21): set_batch_stream() hands EVERY sample the ring delivers
// (telemetry.decimation is the only decimation before it, and it is the loop's own, configured
// one) to the stream in order, with the true contour error the writer computed for it, in batches
// of up to `batch_samples` samples or kMaxBatchAge of wall time, whichever comes first. No hidden
// decimation: a subscriber that wants fewer samples asks the command server for it (per client).
// encode_stream_sample() is the wire form of one sample (its fields are documented there).
#include <Eigen/Core>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <fstream>
#include <functional>
#include <limits>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "control/fir_interpolator.hpp"
#include "daemon/command_server.hpp"
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

// One sample as the telemetry subscription carries it: the loop's sample and what the writer
// computed for it outside the RT loop.
struct StreamSample {
  TelemetrySample s;
  // Distance from the measured position to the planned path (um); NaN outside a program, for a
  // sample past the program's end point (along-path overshoot) or without geometry.
  double true_contour_error_um = std::numeric_limits<double>::quiet_NaN();
};

// The wire form of one sample: one compact JSON object (no newline), numbers in shortest
// round-trip form, NaN as null. Fields (units in the names):
//   cycle        loop cycle number (consecutive samples differ by telemetry.decimation)
//   t_s          cycle * loop period
//   state        machine state name (READY, RUNNING, HOLD, ...)
//   job, line    program job number (0: none) and its source line
//   in_program   RUNNING/HOLD with a program attached
//   progress_mm  path progress of the reference
//   ref_mm[3]    reference position; act_mm[3] measured position; cmd_mm_s[3] velocity commands
//   eps_um[3]    the RT model's contour-error vector; model_error_um its norm
//   true_error_um  distance to the planned path (StreamSample::true_contour_error_um), or null
//   override     feed override applied by the interpolator (1 = 100 %)
//   force_n, force_override, spindle_rpm   force channel and spindle command
//   recording    a CSV record is being written
//   lateness_us  wake-up lateness of this cycle: present once TelemetrySample carries it
[[nodiscard]] std::string encode_stream_sample(const StreamSample& s);

// A batch from TelemetryWriter::set_batch_stream as a chunk for CommandServer::publish_stream:
// each sample encoded once (shared by every subscriber), sequence number = cycle;
// ring_dropped = TelemetryWriter::dropped() (the subscriber sees it as "source_dropped").
[[nodiscard]] std::shared_ptr<const StreamChunk> make_stream_chunk(
    std::span<const StreamSample> batch, std::uint64_t ring_dropped);

class TelemetryWriter {
 public:
  using Stream = std::function<void(const TelemetrySample&)>;
  // Every sample, in order, in batches (writer thread, no writer lock held; must not block).
  using BatchStream = std::function<void(std::span<const StreamSample>)>;
  static constexpr std::size_t kDefaultBatchSamples = 20;  // 20 ms at 1 kHz
  static constexpr std::chrono::milliseconds kMaxBatchAge{20};

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

  // Legacy per-sample callback: every `every_n`-th cycle (the subscription uses the batch stream).
  void set_stream(Stream s, int every_n);
  // Every sample the ring delivers, batched (see the header comment). Set before start(); an
  // empty function turns it off. batch_samples >= 1.
  void set_batch_stream(BatchStream s, std::size_t batch_samples = kDefaultBatchSamples);

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
  void flush_batch(bool force);  // writer thread; calls batch_stream_ without mu_
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
  BatchStream batch_stream_;            // guarded by mu_ (called without it)
  std::size_t batch_samples_ = kDefaultBatchSamples;
  std::vector<StreamSample> batch_;     // filled by consume() under mu_
  std::vector<StreamSample> out_batch_; // handed to batch_stream_ (drain thread only)
  std::chrono::steady_clock::time_point batch_started_{};
  bool batch_full_ = false;
  std::atomic<std::uint64_t> last_cycle_{0};
  std::atomic<std::uint64_t> written_{0};
};

}  // namespace contour::daemon
