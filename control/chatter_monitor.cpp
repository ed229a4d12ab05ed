#include "control/chatter_monitor.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace contour::control {

ChatterFigure command_chatter(const std::vector<std::array<double, kChatterMaxAxes>>& v_cmd_mm_s,
                              int axes) {
  ChatterMeter m(axes);
  for (const auto& v : v_cmd_mm_s) m.add(v);
  return m.figure();
}

void ChatterMeter::reset(int axes) noexcept {
  axes_ = std::clamp(axes, 1, kChatterMaxAxes);
  have_prev_ = false;
  prev_.fill(0.0);
  sum_sq_.fill(0.0);
  max_.fill(0.0);
  steps_ = 0;
}

ChatterFigure ChatterMeter::figure() const noexcept {
  ChatterFigure f;
  f.axes = axes_;
  f.steps = steps_;
  const double inv_steps = steps_ > 0 ? 1.0 / static_cast<double>(steps_) : 0.0;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    f.rms_mm_s[a] = std::sqrt(sum_sq_[a] * inv_steps);
    f.max_mm_s[a] = max_[a];
  }
  return f;
}

void ChatterMonitor::configure(const ChatterMonitorParams& p, int axes) {
  auto bad = [](const std::string& what) {
    throw std::invalid_argument("chatter monitor: " + what);
  };
  if (axes < 1 || axes > kChatterMaxAxes) bad("axes must be 1..3");
  if (!(p.period_s > 0.0) || !std::isfinite(p.period_s)) bad("period_s must be > 0");
  if (!(p.window_s >= kBlocks * p.period_s) || !std::isfinite(p.window_s)) {
    bad("window_s must be at least " + std::to_string(kBlocks) + " periods");
  }
  if (!(p.warn_chatter_mm_s > 0.0) || !(p.fault_chatter_mm_s > 0.0)) {
    bad("chatter thresholds must be > 0 mm/s");
  }
  if (!(p.warn_clamps_per_s > 0.0) || !(p.fault_clamps_per_s > 0.0)) {
    bad("clamp-rate thresholds must be > 0 per s");
  }
  if (p.warn_chatter_mm_s > p.fault_chatter_mm_s) bad("warn_chatter_mm_s above fault_chatter_mm_s");
  if (p.warn_clamps_per_s > p.fault_clamps_per_s) bad("warn_clamps_per_s above fault_clamps_per_s");
  if (!(p.warn_time_s >= 0.0) || !(p.fault_time_s >= 0.0) || !std::isfinite(p.warn_time_s) ||
      !std::isfinite(p.fault_time_s)) {
    bad("warn_time_s and fault_time_s must be >= 0");
  }
  p_ = p;
  axes_ = axes;
  const double window_cycles = p.window_s / p.period_s;
  block_cycles_ = std::max<std::int64_t>(1, std::llround(window_cycles / kBlocks));
  warn_cycles_needed_ = std::max<std::int64_t>(1, std::llround(p.warn_time_s / p.period_s));
  fault_cycles_needed_ = std::max<std::int64_t>(1, std::llround(p.fault_time_s / p.period_s));
  reset();
}

void ChatterMonitor::reset() noexcept {
  for (auto& a : ax_) a = Axis{};
  level_.fill(ChatterLevel::kOk);
  cur_n_ = 0;
  blocks_done_ = 0;
  head_ = 0;
}

std::int64_t ChatterMonitor::window_samples() const noexcept {
  return std::min<std::int64_t>(blocks_done_, kBlocks - 1) * block_cycles_ + cur_n_;
}

double ChatterMonitor::window_chatter_mm_s(int axis) const noexcept {
  const std::int64_t n = window_samples();
  if (axis < 0 || axis >= axes_ || n <= 0) return 0.0;
  const Axis& a = ax_[static_cast<std::size_t>(axis)];
  return std::sqrt((a.done_sq + a.cur_sq) / static_cast<double>(n));
}

double ChatterMonitor::window_clamps_per_s(int axis) const noexcept {
  const std::int64_t n = window_samples();
  if (axis < 0 || axis >= axes_ || n <= 0) return 0.0;
  const Axis& a = ax_[static_cast<std::size_t>(axis)];
  return static_cast<double>(a.done_clamps + a.cur_clamps) /
         (static_cast<double>(n) * p_.period_s);
}

ChatterWindowSums ChatterMonitor::window_sums() const noexcept {
  ChatterWindowSums w;
  w.samples = window_samples();
  w.period_s = p_.period_s;
  for (int i = 0; i < axes_; ++i) {
    const auto s = static_cast<std::size_t>(i);
    w.sq_mm2_s2[s] = ax_[s].done_sq + ax_[s].cur_sq;
    w.clamps[s] = ax_[s].done_clamps + ax_[s].cur_clamps;
  }
  return w;
}

void window_figures(const ChatterWindowSums& w, std::array<double, kChatterMaxAxes>& chatter_mm_s,
                    std::array<double, kChatterMaxAxes>& clamps_per_s) noexcept {
  chatter_mm_s.fill(0.0);
  clamps_per_s.fill(0.0);
  if (w.samples <= 0 || !(w.period_s > 0.0)) return;
  const double inv_n = 1.0 / static_cast<double>(w.samples);
  const double inv_s = inv_n / w.period_s;
  for (std::size_t s = 0; s < chatter_mm_s.size(); ++s) {
    chatter_mm_s[s] = std::sqrt(w.sq_mm2_s2[s] * inv_n);
    clamps_per_s[s] = static_cast<double>(w.clamps[s]) * inv_s;
  }
}

ChatterReport ChatterMonitor::update(const std::array<double, kChatterMaxAxes>& v,
                                     const std::array<bool, kChatterMaxAxes>& clamped) noexcept {
  for (int i = 0; i < axes_; ++i) {
    Axis& a = ax_[static_cast<std::size_t>(i)];
    const double vi = v[static_cast<std::size_t>(i)];
    if (std::isfinite(vi)) {
      if (a.have_prev) a.cur_sq += (vi - a.prev) * (vi - a.prev);
      a.prev = vi;
      a.have_prev = true;
    } else {
      a.have_prev = false;
    }
    if (clamped[static_cast<std::size_t>(i)]) ++a.cur_clamps;
  }
  ++cur_n_;
  if (cur_n_ >= block_cycles_) {
    // Block complete: into the ring; the window sums are re-added from the ring (exact, no drift).
    for (int i = 0; i < axes_; ++i) {
      Axis& a = ax_[static_cast<std::size_t>(i)];
      a.block_sq[static_cast<std::size_t>(head_)] = a.cur_sq;
      a.block_clamps[static_cast<std::size_t>(head_)] = a.cur_clamps;
      a.cur_sq = 0.0;
      a.cur_clamps = 0;
      a.done_sq = 0.0;
      a.done_clamps = 0;
      for (int b = 0; b < kBlocks - 1; ++b) {
        a.done_sq += a.block_sq[static_cast<std::size_t>(b)];
        a.done_clamps += a.block_clamps[static_cast<std::size_t>(b)];
      }
    }
    head_ = (head_ + 1) % (kBlocks - 1);
    cur_n_ = 0;
    if (blocks_done_ < kBlocks) ++blocks_done_;
  }

  ChatterReport out;
  // Before a full window nothing is judged: the counters and levels are still as reset() left
  // them (they change only while judged, and only reset() empties the window again).
  if (blocks_done_ < kBlocks - 1) return out;
  // Judged on the window sums against thresholds scaled to the window (no square root or
  // division per cycle); the figures themselves are computed only for a report.
  const auto n = static_cast<double>(window_samples());
  const double window_s = n * p_.period_s;
  const double warn_sq = p_.warn_chatter_mm_s * p_.warn_chatter_mm_s * n;
  const double fault_sq = p_.fault_chatter_mm_s * p_.fault_chatter_mm_s * n;
  const double warn_clamps = p_.warn_clamps_per_s * window_s;
  const double fault_clamps = p_.fault_clamps_per_s * window_s;
  for (int i = 0; i < axes_; ++i) {
    const auto s = static_cast<std::size_t>(i);
    Axis& a = ax_[s];
    const double sq = a.done_sq + a.cur_sq;
    const auto clamps = static_cast<double>(a.done_clamps + a.cur_clamps);
    const bool warn = (sq > warn_sq || clamps > warn_clamps);
    // The common case, exactly: below the warning thresholds (and so below the fault ones, which
    // configure() keeps at or above them) with nothing counted and nothing raised, this cycle
    // changes nothing and reports nothing.
    if (!warn && a.warn_cycles == 0 && a.fault_cycles == 0 && level_[s] == ChatterLevel::kOk) {
      continue;
    }
    const bool fault = (sq > fault_sq || clamps > fault_clamps);
    a.warn_cycles = warn ? a.warn_cycles + 1 : 0;
    a.fault_cycles = fault ? a.fault_cycles + 1 : 0;
    bool raised = false;
    if (level_[s] != ChatterLevel::kFault && a.fault_cycles >= fault_cycles_needed_) {
      level_[s] = ChatterLevel::kFault;  // latched until reset()
      raised = true;
    } else if (level_[s] == ChatterLevel::kOk && a.warn_cycles >= warn_cycles_needed_) {
      level_[s] = ChatterLevel::kWarning;
      raised = true;
    } else if (level_[s] == ChatterLevel::kWarning && !warn) {
      level_[s] = ChatterLevel::kOk;
    }
    // Report the highest level; among equals the first axis, a rising edge first.
    const bool better = level_[s] > out.level || (raised && !out.raised && level_[s] == out.level);
    if (better && level_[s] != ChatterLevel::kOk) {
      out.level = level_[s];
      out.raised = raised;
      out.axis = i;
      const double chatter = window_chatter_mm_s(i);
      const double rate = window_clamps_per_s(i);
      const bool fault_level = level_[s] == ChatterLevel::kFault;
      const double chatter_limit = fault_level ? p_.fault_chatter_mm_s : p_.warn_chatter_mm_s;
      const double rate_limit = fault_level ? p_.fault_clamps_per_s : p_.warn_clamps_per_s;
      if (chatter > chatter_limit || !(rate > rate_limit)) {
        out.figure = ChatterFigureKind::kChatter;
        out.value = chatter;
        out.limit = chatter_limit;
      } else {
        out.figure = ChatterFigureKind::kClampRate;
        out.value = rate;
        out.limit = rate_limit;
      }
    }
  }
  return out;
}

}  // namespace contour::control
