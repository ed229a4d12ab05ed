#pragma once
// Command chatter: the cycle-to-cycle change of each axis' velocity command, |v(k) - v(k-1)|
// (mm/s), as the figure of merit for what the controller asks of a drive (issue 16). A real drive
// turns a stepping velocity target into current ripple, noise and heat.
//
//   command_chatter()  pure function over a recorded series (run results, tests, offline tools)
//   ChatterMeter       the same figure accumulated cycle by cycle (status: since the last reset)
//   ChatterMonitor     run-time limit-cycle / chatter detector: per axis, over a sliding window,
//                      the RMS command change and the rate of clamped cycles (the daemon's
//                      velocity and acceleration clamps); above a warning threshold for a
//                      warning time -> warning, above a fault threshold for a fault time -> fault,
//                      naming the axis and the figure.
//
// Units: mm/s for velocities and their changes, s for times, clamped cycles per second.
// RT: ChatterMeter::add and ChatterMonitor::update are noexcept, allocation-free, O(axes)
// (fixed arrays; the window is kBlocks blocks of whole cycles). Budget: < 0.1 us per cycle.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

namespace contour::control {

inline constexpr int kChatterMaxAxes = 3;

struct ChatterFigure {
  int axes = 0;
  std::array<double, kChatterMaxAxes> rms_mm_s{};  // RMS of v(k) - v(k-1)
  std::array<double, kChatterMaxAxes> max_mm_s{};  // largest |v(k) - v(k-1)|
  std::int64_t steps = 0;                          // number of differences taken
};

// Over a series of velocity commands (one entry per cycle, axes 1..3 used). Fewer than two
// samples give steps = 0 and zero figures. Non-finite samples are skipped (with their
// neighbouring differences). Pure.
ChatterFigure command_chatter(const std::vector<std::array<double, kChatterMaxAxes>>& v_cmd_mm_s,
                              int axes);

class ChatterMeter {
 public:
  explicit ChatterMeter(int axes = kChatterMaxAxes) noexcept { reset(axes); }
  void reset(int axes) noexcept;
  void reset() noexcept { reset(axes_); }
  // One cycle's velocity commands (mm/s). Non-finite values break the series (not counted).
  void add(const std::array<double, kChatterMaxAxes>& v_cmd_mm_s) noexcept;
  [[nodiscard]] ChatterFigure figure() const noexcept;

 private:
  int axes_ = kChatterMaxAxes;
  bool have_prev_ = false;
  std::array<double, kChatterMaxAxes> prev_{};
  std::array<double, kChatterMaxAxes> sum_sq_{};
  std::array<double, kChatterMaxAxes> max_{};
  std::int64_t steps_ = 0;
};

// Inline: the daemon adds one sample per cycle (issue 15: the cycle's cost).
inline void ChatterMeter::add(const std::array<double, kChatterMaxAxes>& v) noexcept {
  bool finite = true;
  for (int i = 0; i < axes_; ++i) finite = finite && std::isfinite(v[static_cast<std::size_t>(i)]);
  if (!finite) {
    have_prev_ = false;
    return;
  }
  if (have_prev_) {
    for (int i = 0; i < axes_; ++i) {
      const auto a = static_cast<std::size_t>(i);
      const double d = v[a] - prev_[a];
      sum_sq_[a] += d * d;
      max_[a] = std::max(max_[a], std::abs(d));
    }
    ++steps_;
  }
  prev_ = v;
  have_prev_ = true;
}

// Detector parameters. Defaults (control/CHATTER.md has the measured figures behind them):
// through the daemon on Table 2 with the default derivative filter a 0.1 s window peaks at
// 11.6 mm/s at a corner and stays above 5 mm/s for at most 104 ms (never warns); the limit cycles
// of issue 16 run at 24-76 mm/s RMS and 557-971 clamped cycles per second, indefinitely; the
// round-1 law (filter off) moves at 14-25 mm/s: warning, never a fault.
struct ChatterMonitorParams {
  double period_s = 0.001;
  double window_s = 0.1;                  // sliding window (kBlocks blocks)
  double warn_chatter_mm_s = 5.0;         // RMS |dv| over the window
  double warn_clamps_per_s = 50.0;        // clamped cycles per second over the window
  double warn_time_s = 0.25;              // continuously above a warning threshold this long
  double fault_chatter_mm_s = 40.0;
  double fault_clamps_per_s = 300.0;
  double fault_time_s = 0.5;
};

// The watchdog's raw window (what update() judges on): cheap to copy every cycle into a
// published status; the figures (a square root and a division per axis) are derived by the
// reader with window_figures() below.
struct ChatterWindowSums {
  std::array<double, kChatterMaxAxes> sq_mm2_s2{};  // sum of (v(k) - v(k-1))^2 over the window
  std::array<std::int64_t, kChatterMaxAxes> clamps{};
  std::int64_t samples = 0;
  double period_s = 0.001;
};
// RMS |dv| (mm/s) and clamped cycles per second of each axis (0 for an empty window).
void window_figures(const ChatterWindowSums& s, std::array<double, kChatterMaxAxes>& chatter_mm_s,
                    std::array<double, kChatterMaxAxes>& clamps_per_s) noexcept;

enum class ChatterLevel : std::uint8_t { kOk = 0, kWarning, kFault };
enum class ChatterFigureKind : std::uint8_t { kNone = 0, kChatter, kClampRate };

// The result of one cycle. `raised` is true in the cycle the level of `axis` rose (warning, or
// fault: latched until reset()); report events on it. `value` and `limit` are the figure and
// the threshold it crossed (mm/s for kChatter, clamped cycles per second for kClampRate).
struct ChatterReport {
  ChatterLevel level = ChatterLevel::kOk;  // highest level over the axes
  bool raised = false;
  int axis = -1;
  ChatterFigureKind figure = ChatterFigureKind::kNone;
  double value = 0.0;
  double limit = 0.0;
};

class ChatterMonitor {
 public:
  static constexpr int kBlocks = 10;

  ChatterMonitor() { configure(ChatterMonitorParams{}, kChatterMaxAxes); }
  // Setup; throws std::invalid_argument naming the field: period_s > 0, window_s >= kBlocks
  // periods, thresholds > 0, times >= 0, warning thresholds <= fault thresholds, axes 1..3.
  void configure(const ChatterMonitorParams& p, int axes);
  // Empties the window and clears the levels (after a reset, a gains change, a state change
  // that restarts the controller).
  void reset() noexcept;

  // One cycle: the velocity commands written to the drives (mm/s) and, per axis, whether the
  // caller clamped this cycle's command (velocity or acceleration clamp). Judged once a full
  // window has been seen. RT: noexcept, no allocation.
  ChatterReport update(const std::array<double, kChatterMaxAxes>& v_cmd_mm_s,
                       const std::array<bool, kChatterMaxAxes>& clamped) noexcept;

  // Current window figures of one axis (0 before the first difference).
  [[nodiscard]] double window_chatter_mm_s(int axis) const noexcept;
  [[nodiscard]] double window_clamps_per_s(int axis) const noexcept;
  // The window's sums (zeros past the configured axes), for a status published every cycle.
  [[nodiscard]] ChatterWindowSums window_sums() const noexcept;
  [[nodiscard]] ChatterLevel level(int axis) const noexcept {
    return level_[static_cast<std::size_t>(axis)];
  }
  [[nodiscard]] const ChatterMonitorParams& params() const noexcept { return p_; }

 private:
  struct Axis {
    std::array<double, kBlocks - 1> block_sq{};  // ring of the newest completed blocks
    std::array<std::int32_t, kBlocks - 1> block_clamps{};
    double done_sq = 0.0;          // over the completed blocks in the ring
    std::int64_t done_clamps = 0;
    double cur_sq = 0.0;           // current (partial) block
    std::int32_t cur_clamps = 0;
    double prev = 0.0;
    bool have_prev = false;
    std::int64_t warn_cycles = 0;   // consecutive cycles above a warning threshold
    std::int64_t fault_cycles = 0;  // consecutive cycles above a fault threshold
  };
  [[nodiscard]] std::int64_t window_samples() const noexcept;

  ChatterMonitorParams p_{};
  int axes_ = kChatterMaxAxes;
  std::int64_t block_cycles_ = 10;
  std::int64_t warn_cycles_needed_ = 0;
  std::int64_t fault_cycles_needed_ = 0;
  std::array<Axis, kChatterMaxAxes> ax_{};
  std::array<ChatterLevel, kChatterMaxAxes> level_{};
  std::int64_t cur_n_ = 0;        // samples in the current block
  std::int64_t blocks_done_ = 0;  // completed blocks since reset (saturating at kBlocks)
  int head_ = 0;                  // ring slot the next completed block goes to
};

}  // namespace contour::control
