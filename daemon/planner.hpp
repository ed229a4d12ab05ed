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
#include <array>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "config/config.hpp"
#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"
#include "daemon/machine_data.hpp"
#include "daemon/servo_loop.hpp"

namespace contour::daemon {

// A part program as the planner reads it: a file on the daemon's host or inline text.
struct ProgramText {
  std::string name;  // file name for messages ("<inline>" for text)
  std::string path;  // read from this file when non-empty
  std::string text;  // else this inline program
  // MDI (issue 18): blocks already interpreted by the daemon's MDI interpreter; when `mdi` is
  // true, path/text are ignored and these blocks (the last one a kEnd) are the program.
  bool mdi = false;
  std::vector<control::Block> blocks{};
  // Run from line (issue 18, LinuxCNC's "run from line"): lines before start_line are interpreted
  // (modal state, offsets, tool, spindle and coolant recovered) but not executed; the run begins
  // with a tool-change pause when the tool they leave in the spindle is not the machine's, then a
  // safe approach to where line start_line begins: straight up to the clearance (the highest Z
  // so far, or where Z stands if higher), across at it as a rapid, then down to the start point
  // at the modal feed. 0 or 1: from the beginning.
  long start_line = 0;
};

class ProgramError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ProgramSummary {
  long lines = 0;
  long motion_blocks = 0;
  double length_mm = 0.0;
  // Preview (issue 18): every interpreted block (motion, dwell, tool change, holds, spindle...),
  // the extents of every programmed point (arcs chorded) in machine coordinates and in the
  // program's own (work) coordinates of each block (its G5x, G92 and tool length offsets), the
  // tools M6 loads, and, when asked for, the path in machine coordinates (decimated to at most
  // kMaxPreviewPoints).
  long blocks = 0;
  // With ProgramText::start_line: the highest machine Z of the moves before that line (-inf when
  // none): run from line's clearance.
  double clearance_z_mm = -std::numeric_limits<double>::infinity();
  std::array<double, 3> machine_min_mm{}, machine_max_mm{}, work_min_mm{}, work_max_mm{};
  bool has_motion = false;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> path_mm;
  static constexpr std::size_t kMaxPreviewPoints = 20000;
};

class ProgramPlanner {
 public:
  using SegmentSink = std::function<void(std::uint64_t job, const control::PlannedSegment&)>;

  explicit ProgramPlanner(const config::Config& cfg);
  ~ProgramPlanner();
  ProgramPlanner(const ProgramPlanner&) = delete;
  ProgramPlanner& operator=(const ProgramPlanner&) = delete;

  // Parse + soft-limit pass from start_mm. Throws ProgramError("file:line:column: message").
  ProgramSummary validate(const ProgramText& src, const Eigen::Vector3d& start_mm,
                          bool keep_path = false) const;
  // Preview: plans the whole program (the planner the run uses, on this thread's job; a job
  // being planned is aborted first, as start() does) and returns the motion's duration at 100 %
  // override: from the first command period to the end of the last segment's FIR tail. Holds
  // (M0/M1/M6), spindle waits and the operator's time are not in it. Throws ProgramError.
  double estimate_time_s(const ProgramText& src, const Eigen::Vector3d& start_mm);

  // The block delete switch (program.block_delete at start-up): read by validate() and, line by
  // line, by the planning thread (a running program sees it from the next line it reads).
  void set_block_delete(bool on) noexcept { block_delete_.store(on, std::memory_order_relaxed); }
  [[nodiscard]] bool block_delete() const noexcept { return block_delete_.load(std::memory_order_relaxed); }

  // Creates the job (interpolator configured at start_mm) and starts planning on a new thread.
  // A previous planner thread is aborted and joined first. sink (may be empty) sees every planned
  // segment (the telemetry writer's geometry for the true contour error).
  std::shared_ptr<ProgramJob> start(const ProgramText& src, const Eigen::Vector3d& start_mm,
                                    std::uint64_t job_id, SegmentSink sink);

  [[nodiscard]] std::string error() const;  // planning error of the last job ("" if none)
  // The text of a hold's message (M0/M1/M6: PlannedSegment::message_id) of the current job;
  // "" when unknown. Thread-safe.
  [[nodiscard]] std::string message(std::uint64_t job_id, int message_id) const;
  // The source line of that hold and the tool after it (M6: the tool to load); {0, 0} when
  // unknown. Thread-safe.
  struct HoldSite {
    int line = 0;
    int tool = 0;
  };
  [[nodiscard]] HoldSite message_site(std::uint64_t job_id, int message_id) const;
  void abort_and_join();

  // Waits until the job's queue holds at least half its capacity or planning finished.
  static bool wait_prefill(const ProgramJob& job, double timeout_s);

  [[nodiscard]] control::InterpolatorParams interpolator_params() const;

  // SIGHUP: the live machine limits (soft limits, axis velocity/acceleration, override maximum)
  // for the programs loaded from now on (a running program keeps the plan it has).
  void set_live(const config::Config& live);
  [[nodiscard]] config::Config config_snapshot() const;

  // Issue 18: programs start from this machine context (offsets, tools) and, when their
  // interpreter reports machine_changed(), commit what it left when planning ends, fails or is
  // aborted (a stopped program). Null: ProgramSetup from the config alone. Set before start().
  // Without it (offline runs), a config with program.var_file / tool_table is read (cfg.source
  // locates relative paths) and used read-only: nothing is written.
  void set_machine_data(MachineData* md) {
    machine_ = md;
    commit_ = md != nullptr;
  }

 private:
  void plan(std::shared_ptr<ProgramJob> job, ProgramText src, Eigen::Vector3d start_mm,
            SegmentSink sink);

  config::Config cfg_;
  std::unique_ptr<MachineData> own_machine_;  // read-only copy for offline runs
  MachineData* machine_ = nullptr;
  bool commit_ = false;
  std::thread thread_;
  std::shared_ptr<ProgramJob> job_;
  mutable std::mutex mu_;
  std::atomic<bool> block_delete_{false};
  std::string error_;
  std::uint64_t messages_job_ = 0;
  std::vector<std::string> messages_;  // of messages_job_, copied from the planner thread
  std::vector<HoldSite> message_sites_;  // the hold segment's line and tool per message
};

}  // namespace contour::daemon
