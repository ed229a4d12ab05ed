#pragma once
// Planner thread (issue 9 "Program execution"): reads a program line by line, GcodeParser +
// BlendPlanner (look-ahead, blend overlaps), and pushes the planned segments into the job's
// bounded SPSC queue that the RT loop drains into its Interpolator. Memory is bounded for any
// program length (parser O(1), planner window bounded, queue fixed).
//
// Loading is two passes: validate() parses the whole program once (no planning) and checks every
// programmed point (arcs chorded) against the soft limits, so syntax and limit errors are
// reported with file:line:column BEFORE any motion; then start() plans while the program runs.
// Not RT: allocates, may throw (ProgramError), sleeps when the queue is full.
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "config/config.hpp"
#include "control/fir_interpolator.hpp"
#include "daemon/servo_loop.hpp"

namespace contour::daemon {

// A part program as the planner reads it: a file on the daemon's host or inline text.
struct ProgramText {
  std::string name;  // file name for messages ("<inline>" for text)
  std::string path;  // read from this file when non-empty
  std::string text;  // else this inline program
};

class ProgramError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ProgramSummary {
  long lines = 0;
  long motion_blocks = 0;
  double length_mm = 0.0;
};

class ProgramPlanner {
 public:
  using SegmentSink = std::function<void(std::uint64_t job, const control::PlannedSegment&)>;

  explicit ProgramPlanner(const config::Config& cfg);
  ~ProgramPlanner();
  ProgramPlanner(const ProgramPlanner&) = delete;
  ProgramPlanner& operator=(const ProgramPlanner&) = delete;

  // Parse + soft-limit pass from start_mm. Throws ProgramError("file:line:column: message").
  ProgramSummary validate(const ProgramText& src, const Eigen::Vector3d& start_mm) const;

  // Creates the job (interpolator configured at start_mm) and starts planning on a new thread.
  // A previous planner thread is aborted and joined first. sink (may be empty) sees every planned
  // segment (the telemetry writer's geometry for the true contour error).
  std::shared_ptr<ProgramJob> start(const ProgramText& src, const Eigen::Vector3d& start_mm,
                                    std::uint64_t job_id, SegmentSink sink);

  [[nodiscard]] std::string error() const;  // planning error of the last job ("" if none)
  void abort_and_join();

  // Waits until the job's queue holds at least half its capacity or planning finished.
  static bool wait_prefill(const ProgramJob& job, double timeout_s);

  [[nodiscard]] control::InterpolatorParams interpolator_params() const;

  // SIGHUP: the live machine limits (soft limits, axis velocity/acceleration, override maximum)
  // for the programs loaded from now on (a running program keeps the plan it has).
  void set_live(const config::Config& live);
  [[nodiscard]] config::Config config_snapshot() const;

 private:
  void plan(std::shared_ptr<ProgramJob> job, ProgramText src, Eigen::Vector3d start_mm,
            SegmentSink sink);

  config::Config cfg_;
  std::thread thread_;
  std::shared_ptr<ProgramJob> job_;
  mutable std::mutex mu_;
  std::string error_;
};

}  // namespace contour::daemon
