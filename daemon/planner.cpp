#include "daemon/planner.hpp"

#include <chrono>
#include <fstream>
#include <sstream>

#include "config/interpolator_config.hpp"
#include "config/program_config.hpp"
#include "control/blend_planner.hpp"
#include "control/gcode.hpp"
#include "control/path.hpp"

namespace contour::daemon {

namespace {

std::unique_ptr<std::istream> open_source(const ProgramText& src) {
  if (!src.path.empty()) {
    auto f = std::make_unique<std::ifstream>(src.path);
    if (!*f) throw ProgramError(src.path + ": cannot open program file");
    return f;
  }
  return std::make_unique<std::istringstream>(src.text);
}

control::PlannerParams planner_params(const config::Config& cfg) {
  control::PlannerParams pp;
  pp.period_s = cfg.machine.period_s;
  pp.fir_taps = std::max(1, config::fir_taps(cfg.interpolator.fir_ms, pp.period_s));
  pp.fir2_taps = config::fir_taps(cfg.interpolator.fir2_ms, pp.period_s);
  pp.floor_rounding = cfg.interpolator.floor_rounding;
  pp.method = cfg.interpolator.method;
  pp.arc_chord_fraction = cfg.interpolator.arc_chord_fraction;
  pp.default_tolerance_mm = cfg.interpolator.tolerance_um * 1e-3;
  for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
    pp.max_velocity_mm_min[static_cast<int>(i)] = cfg.machine.axes[i].max_velocity_mm_min;
    pp.max_accel_mm_s2[static_cast<int>(i)] = cfg.machine.axes[i].max_accel_mm_s2;
  }
  return pp;
}

}  // namespace

ProgramPlanner::ProgramPlanner(const config::Config& cfg) : cfg_(cfg) {}

ProgramPlanner::~ProgramPlanner() { abort_and_join(); }

config::Config ProgramPlanner::config_snapshot() const {
  std::lock_guard lk(mu_);
  return cfg_;
}

void ProgramPlanner::set_live(const config::Config& live) {
  std::lock_guard lk(mu_);
  for (std::size_t i = 0; i < cfg_.machine.axes.size() && i < live.machine.axes.size(); ++i) {
    auto& a = cfg_.machine.axes[i];
    const auto& b = live.machine.axes[i];
    a.min_mm = b.min_mm;
    a.max_mm = b.max_mm;
    a.max_velocity_mm_min = b.max_velocity_mm_min;
    a.max_accel_mm_s2 = b.max_accel_mm_s2;
  }
  cfg_.interpolator.feed_override_max_percent = live.interpolator.feed_override_max_percent;
}

control::InterpolatorParams ProgramPlanner::interpolator_params() const {
  const config::Config cfg = config_snapshot();
  control::InterpolatorParams ip;
  const auto pp = planner_params(cfg);
  ip.fir_taps = pp.fir_taps;
  ip.fir2_taps = pp.fir2_taps;
  ip.period_s = cfg.machine.period_s;
  ip.override_max = cfg.interpolator.feed_override_max_percent / 100.0;
  ip.optional_stop = cfg.interpolator.optional_stop;
  ip.capacity = static_cast<std::size_t>(cfg.interpolator.queue_capacity);
  return ip;
}

ProgramSummary ProgramPlanner::validate(const ProgramText& src,
                                        const Eigen::Vector3d& start_mm) const {
  const config::Config cfg = config_snapshot();
  control::ProgramSetup setup = config::to_program_setup(cfg.program, cfg.interpolator);
  setup.start_mm = start_mm;
  auto in = open_source(src);
  control::GcodeParser parser(setup, src.name);
  std::vector<control::Block> blocks;
  std::vector<Eigen::Vector3d> pts;
  std::string text;
  ProgramSummary sum;
  const double chord = cfg.interpolator.tolerance_um * 1e-3 * cfg.interpolator.arc_chord_fraction;
  try {
    while (!parser.ended()) {
      if (std::getline(*in, text)) {
        ++sum.lines;
        parser.parse_line(text, blocks);
      } else {
        parser.finish(blocks);
      }
      for (const auto& b : blocks) {
        if (b.kind != control::BlockKind::kMotion) continue;
        ++sum.motion_blocks;
        pts.clear();
        control::chord_points(b.seg, std::max(chord, 1e-4), pts);
        Eigen::Vector3d prev = b.seg.start;
        for (const auto& p : pts) {
          sum.length_mm += (p - prev).norm();
          prev = p;
          for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
            const auto& ax = cfg.machine.axes[i];
            const double x = p[static_cast<Eigen::Index>(i)];
            if (x < ax.min_mm - 1e-9 || x > ax.max_mm + 1e-9) {
              std::ostringstream m;
              m << src.name << ':' << b.line << ":1: soft limit: " << ax.name << " would reach "
                << x << " mm, outside [" << ax.min_mm << ", " << ax.max_mm << "] mm";
              throw ProgramError(m.str());
            }
          }
        }
      }
      blocks.clear();
    }
  } catch (const control::GcodeError& e) {
    throw ProgramError(e.what());
  }
  return sum;
}

std::shared_ptr<ProgramJob> ProgramPlanner::start(const ProgramText& src,
                                                  const Eigen::Vector3d& start_mm,
                                                  std::uint64_t job_id, SegmentSink sink) {
  abort_and_join();
  auto job = std::make_shared<ProgramJob>(job_id, interpolator_params(), start_mm,
                                          static_cast<std::size_t>(1024));
  {
    std::lock_guard lk(mu_);
    error_.clear();
    job_ = job;
  }
  thread_ = std::thread([this, job, src, start_mm, sink]() { plan(job, src, start_mm, sink); });
  return job;
}

void ProgramPlanner::abort_and_join() {
  std::shared_ptr<ProgramJob> j;
  {
    std::lock_guard lk(mu_);
    j = job_;
  }
  if (j) j->abort.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

std::string ProgramPlanner::error() const {
  std::lock_guard lk(mu_);
  return error_;
}

bool ProgramPlanner::wait_prefill(const ProgramJob& job, double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < until) {
    if (job.planner_done.load(std::memory_order_acquire) ||
        job.planner_failed.load(std::memory_order_acquire) ||
        job.queue.size() >= job.queue.capacity() / 2) {
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

void ProgramPlanner::plan(std::shared_ptr<ProgramJob> job, ProgramText src,
                          Eigen::Vector3d start_mm, SegmentSink sink) {
  const config::Config cfg = config_snapshot();
  try {
    control::ProgramSetup setup = config::to_program_setup(cfg.program, cfg.interpolator);
    setup.start_mm = start_mm;
    auto in = open_source(src);
    control::GcodeParser parser(setup, src.name);
    control::BlendPlanner planner(planner_params(cfg), start_mm);
    std::vector<control::Block> blocks;
    std::string text;
    control::PlannedSegment seg;
    auto aborted = [&] { return job->abort.load(std::memory_order_acquire); };
    while (!aborted()) {
      while (planner.pop(seg)) {
        if (sink) sink(job->id, seg);
        // Wait for room: the queue's push() would count a full ring as a drop.
        while (job->queue.size() >= job->queue.capacity()) {
          if (aborted()) return;
          std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
        job->queue.push(to_record(seg));
      }
      if (planner.ended()) break;
      if (std::getline(*in, text)) {
        parser.parse_line(text, blocks);
      } else {
        parser.finish(blocks);
      }
      for (const auto& b : blocks) planner.push(b);
      blocks.clear();
    }
    job->planner_done.store(true, std::memory_order_release);
  } catch (const std::exception& e) {
    {
      std::lock_guard lk(mu_);
      error_ = e.what();
    }
    job->planner_failed.store(true, std::memory_order_release);
  }
}

}  // namespace contour::daemon
