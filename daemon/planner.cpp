#include "daemon/planner.hpp"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <limits>
#include <set>
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

ProgramPlanner::ProgramPlanner(const config::Config& cfg) : cfg_(cfg), block_delete_(cfg.program.block_delete) {
  if (!cfg.program.var_file.empty() || !cfg.program.tool_table.empty()) {
    try {
      own_machine_ = std::make_unique<MachineData>(
          cfg.program, resolve_config_path(cfg.source, cfg.program.var_file),
          resolve_config_path(cfg.source, cfg.program.tool_table));
    } catch (const MachineDataError& e) {
      throw ProgramError(e.what());
    }
    machine_ = own_machine_.get();
  }
}

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

ProgramSummary ProgramPlanner::validate(const ProgramText& src, const Eigen::Vector3d& start_mm,
                                        bool keep_path) const {
  const config::Config cfg = config_snapshot();
  control::ProgramSetup setup = config::to_program_setup(cfg.program, cfg.interpolator);
  setup.start_mm = start_mm;
  setup.block_delete = block_delete();
  if (machine_ != nullptr) setup.machine = machine_->snapshot();
  std::vector<Eigen::Vector3d> pts;
  ProgramSummary sum;
  const double chord = cfg.interpolator.tolerance_um * 1e-3 * cfg.interpolator.arc_chord_fraction;
  sum.machine_min_mm.fill(std::numeric_limits<double>::infinity());
  sum.work_min_mm.fill(std::numeric_limits<double>::infinity());
  sum.machine_max_mm.fill(-std::numeric_limits<double>::infinity());
  sum.work_max_mm.fill(-std::numeric_limits<double>::infinity());
  std::set<int> tools;
  auto extend = [&](const control::Block& b, const Eigen::Vector3d& p) {
    const Eigen::Vector3d w = control::work_coordinates(b, p);
    for (std::size_t i = 0; i < 3; ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      sum.machine_min_mm[i] = std::min(sum.machine_min_mm[i], p[k]);
      sum.machine_max_mm[i] = std::max(sum.machine_max_mm[i], p[k]);
      sum.work_min_mm[i] = std::min(sum.work_min_mm[i], w[k]);
      sum.work_max_mm[i] = std::max(sum.work_max_mm[i], w[k]);
    }
    if (keep_path) sum.path_mm.push_back(p);
  };
  auto check = [&](const control::Block& b) {
    ++sum.blocks;
    if (b.kind == control::BlockKind::kToolChange) tools.insert(b.tool);
    if (b.kind != control::BlockKind::kMotion) return;
    ++sum.motion_blocks;
    if (!src.mdi && sum.lines < src.start_line) {
      sum.clearance_z_mm = std::max({sum.clearance_z_mm, b.seg.start.z(), b.seg.end.z()});
    }
    pts.clear();
    control::chord_points(b.seg, std::max(chord, 1e-4), pts);
    Eigen::Vector3d prev = b.seg.start;
    if (!sum.has_motion) extend(b, b.seg.start);
    sum.has_motion = true;
    for (const auto& p : pts) {
      sum.length_mm += (p - prev).norm();
      prev = p;
      extend(b, p);
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
  };
  auto finish = [&]() {
    sum.tools.assign(tools.begin(), tools.end());
    if (sum.path_mm.size() > ProgramSummary::kMaxPreviewPoints) {
      // Uniform decimation, first and last point kept.
      std::vector<Eigen::Vector3d> d;
      const std::size_t n = sum.path_mm.size(), m = ProgramSummary::kMaxPreviewPoints;
      for (std::size_t i = 0; i < m; ++i) d.push_back(sum.path_mm[i * (n - 1) / (m - 1)]);
      sum.path_mm.swap(d);
    }
  };
  if (src.mdi) {
    sum.lines = 1;
    for (const auto& b : src.blocks) check(b);
    finish();
    return sum;
  }
  auto in = open_source(src);
  control::GcodeParser parser(setup, src.name);
  std::vector<control::Block> blocks;
  std::string text;
  try {
    while (!parser.ended()) {
      if (std::getline(*in, text)) {
        ++sum.lines;
        parser.parse_line(text, blocks);
      } else {
        parser.finish(blocks);
      }
      for (const auto& b : blocks) check(b);
      blocks.clear();
    }
  } catch (const control::GcodeError& e) {
    throw ProgramError(e.what());
  }
  finish();
  return sum;
}

double ProgramPlanner::estimate_time_s(const ProgramText& src, const Eigen::Vector3d& start_mm) {
  const control::InterpolatorParams ip = interpolator_params();
  // The sink runs on the planner thread; read after the join below.
  auto end_cycle = std::make_shared<double>(0.0);
  auto job = start(src, start_mm, 0, [end_cycle](std::uint64_t, const control::PlannedSegment& s) {
    if (s.kind != control::SegmentKind::kMotion) return;
    *end_cycle = std::max(*end_cycle, static_cast<double>(s.start_cycle) + s.start_offset_cycles +
                                          control::segment_duration(s));
  });
  // Nobody drains this job's queue but us.
  SegmentRecord rec;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!(job->planner_done.load(std::memory_order_acquire) && job->queue.size() == 0)) {
    if (job->planner_failed.load(std::memory_order_acquire)) {
      abort_and_join();
      throw ProgramError(error());
    }
    if (std::chrono::steady_clock::now() > until) {
      abort_and_join();
      throw ProgramError(src.name + ": preview: planning took more than 120 s");
    }
    if (!job->queue.pop(rec)) std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  abort_and_join();
  const int tail = (ip.fir_taps - 1) + std::max(0, ip.fir2_taps - 1);
  return (*end_cycle + (*end_cycle > 0.0 ? tail : 0)) * ip.period_s;
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
    messages_job_ = job_id;
    messages_.clear();
    message_sites_.clear();
  }
  thread_ = std::thread([this, job, src, start_mm, sink]() { plan(job, src, start_mm, sink); });
  return job;
}

ProgramPlanner::HoldSite ProgramPlanner::message_site(std::uint64_t job_id, int message_id) const {
  std::lock_guard lk(mu_);
  if (job_id != messages_job_ || message_id < 0 ||
      static_cast<std::size_t>(message_id) >= message_sites_.size()) {
    return {};
  }
  return message_sites_[static_cast<std::size_t>(message_id)];
}

std::string ProgramPlanner::message(std::uint64_t job_id, int message_id) const {
  std::lock_guard lk(mu_);
  if (job_id != messages_job_ || message_id < 0 ||
      static_cast<std::size_t>(message_id) >= messages_.size()) {
    return {};
  }
  return messages_[static_cast<std::size_t>(message_id)];
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
  std::unique_ptr<control::GcodeParser> parser;
  // What the program changed (G10, G92, G28.1, M6 ...) is the machine's from now on, also when
  // planning fails or the program is stopped: the interpreter has executed those lines.
  auto commit_machine = [&]() {
    if (!commit_ || machine_ == nullptr || parser == nullptr || !parser->machine_changed()) return;
    try {
      machine_->commit(parser->machine(), parser->modal_state().tool_offset_mm);
    } catch (const std::exception& e) {
      std::lock_guard lk(mu_);
      if (error_.empty()) error_ = e.what();
    }
  };
  try {
    control::ProgramSetup setup = config::to_program_setup(cfg.program, cfg.interpolator);
    setup.start_mm = start_mm;
    setup.block_delete = block_delete();
    if (machine_ != nullptr) setup.machine = machine_->snapshot();
    if (!src.mdi && src.start_line > 1) setup.run_from_line = static_cast<int>(src.start_line);
    std::unique_ptr<std::istream> in;
    if (!src.mdi) {
      in = open_source(src);
      parser = std::make_unique<control::GcodeParser>(setup, src.name);
    }
    control::BlendPlanner planner(planner_params(cfg), start_mm);
    std::vector<control::Block> blocks;
    std::string text;
    control::PlannedSegment seg;
    std::size_t n_messages = 0;  // planner messages copied into messages_
    bool mdi_pushed = false;
    auto aborted = [&] { return job->abort.load(std::memory_order_acquire); };
    // Run from line: the parser interprets the lines before the start line without emitting
    // them (ProgramSetup::run_from_line); at the first block it emits, resume_state() is the
    // state there. The clearance: the highest Z before it (a validate() pass).
    bool approach_due = !src.mdi && src.start_line > 1;
    const double clearance_z_mm = approach_due ? validate(src, start_mm).clearance_z_mm : 0.0;
    auto approach = [&](const control::Block& first) {
      const control::ModalState rs = parser->resume_state().value_or(parser->modal_state());
      const Eigen::Vector3d at = rs.position_mm;  // where line start_line begins
      const double feed = rs.feed_mm_min;
      auto move = [&](const Eigen::Vector3d& from, const Eigen::Vector3d& to, bool rapid) {
        if ((to - from).norm() < 1e-9) return;
        control::Block m = first;  // the modal state of the first executed block
        m.kind = control::BlockKind::kMotion;
        m.seg = control::PathSegment::line(from, to);
        m.rapid = rapid || !(feed > 0.0);
        m.feed_mm_min = m.rapid ? setup.rapid_mm_min : feed;
        m.blend = control::BlendMode::kExactStop;
        m.message.clear();
        m.user_m = 0;
        planner.push(m);
      };
      // A tool the skipped lines changed to (M6) that is not in the spindle: its pause first.
      const int tool_before = setup.machine ? setup.machine->tool_in_spindle : 0;
      if (rs.tool != tool_before && rs.tool > 0) {
        control::Block tc = first;
        tc.kind = control::BlockKind::kToolChange;
        tc.seg = control::PathSegment::line(start_mm, start_mm);
        tc.tool = rs.tool;
        tc.message = "run from line " + std::to_string(src.start_line) + ": insert tool " +
                     std::to_string(rs.tool) + ", then resume";
        planner.push(tc);
      }
      const double z_safe = std::max({clearance_z_mm, start_mm.z(), at.z()});
      const Eigen::Vector3d up(start_mm.x(), start_mm.y(), z_safe);
      const Eigen::Vector3d over(at.x(), at.y(), z_safe);
      move(start_mm, up, true);
      move(up, over, true);
      move(over, at, false);
    };
    while (!aborted()) {
      if (planner.messages().size() > n_messages) {
        std::lock_guard lk(mu_);
        if (messages_job_ == job->id) {
          for (; n_messages < planner.messages().size(); ++n_messages) {
            messages_.push_back(planner.messages()[n_messages]);
            message_sites_.push_back({});
          }
        }
      }
      while (planner.pop(seg)) {
        if (sink) sink(job->id, seg);
        if (seg.message_id >= 0) {
          std::lock_guard lk(mu_);
          const auto m = static_cast<std::size_t>(seg.message_id);
          if (messages_job_ == job->id && m < message_sites_.size()) message_sites_[m] = {seg.line, seg.tool};
        }
        // Wait for room: the queue's push() would count a full ring as a drop.
        while (job->queue.size() >= job->queue.capacity()) {
          if (aborted()) {
            commit_machine();
            return;
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(2));
        }
        job->queue.push(to_record(seg));
      }
      if (planner.ended()) break;
      if (src.mdi) {
        if (mdi_pushed) break;
        for (const auto& b : src.blocks) planner.push(b);  // ends with a kEnd block (the daemon's)
        mdi_pushed = true;
        continue;
      }
      if (std::getline(*in, text)) {
        parser->set_block_delete(block_delete());
        parser->parse_line(text, blocks);
      } else {
        parser->finish(blocks);
      }
      for (const auto& b : blocks) {
        if (approach_due) {
          approach_due = false;
          approach(b);
        }
        planner.push(b);
      }
      blocks.clear();
    }
    commit_machine();
    job->planner_done.store(true, std::memory_order_release);
  } catch (const std::exception& e) {
    commit_machine();
    {
      std::lock_guard lk(mu_);
      error_ = e.what();
    }
    job->planner_failed.store(true, std::memory_order_release);
  }
}

}  // namespace contour::daemon
