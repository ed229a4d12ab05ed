// Google Benchmark (not wired into the build yet: the lead adds the target).
// BM_ParsePlan100k: parse + plan a generated 100,000-segment CAM-style program (short random
//   segments, G64 P0.05, true-tolerance method). Reports blocks/s (items_per_second).
// BM_InterpolatorStep: per-cycle cost of Interpolator::step with the short-segment plan queued
//   (~tens of blocks in motion at once).
#include <benchmark/benchmark.h>

#include "tools/bench/plan_program.hpp"

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"

using namespace contour::control;

namespace {
std::vector<std::string> make_program(int n) {
  std::vector<std::string> lines{"G17 G21 G90 G94", "G64 P0.05", "F1500"};
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  double x = 0, y = 0, h = 0;
  for (int i = 0; i < n; ++i) {
    h += 0.6 * (u(rng) - 0.5);
    const double l = 0.1 + 0.9 * u(rng);
    x += l * std::cos(h);
    y += l * std::sin(h);
    lines.push_back("G1 X" + std::to_string(x) + " Y" + std::to_string(y));
  }
  lines.push_back("M2");
  return lines;
}

std::vector<PlannedSegment> plan(const std::vector<std::string>& prog, std::int64_t* moves) {
  return contour::bench::plan_program(prog, moves);
}
}  // namespace

static void BM_ParsePlan100k(benchmark::State& state) {
  const auto prog = make_program(100000);
  std::int64_t moves = 0;
  for (auto _ : state) {
    auto segs = plan(prog, &moves);
    benchmark::DoNotOptimize(segs.data());
  }
  state.SetItemsProcessed(state.iterations() * moves);
}
BENCHMARK(BM_ParsePlan100k)->Unit(benchmark::kMillisecond)->Iterations(1);

static void BM_InterpolatorStep(benchmark::State& state) {
  const auto prog = make_program(5000);
  std::int64_t moves = 0;
  const auto segs = plan(prog, &moves);
  Interpolator ip;
  InterpolatorParams p;
  p.capacity = segs.size() + 8;
  ip.configure(p, Eigen::Vector3d::Zero());
  for (const auto& s : segs) ip.push(s);
  InterpOutput out;
  for (auto _ : state) {
    if (ip.step(1.0, out) == InterpStatus::kDone) {
      state.PauseTiming();
      ip.configure(p, Eigen::Vector3d::Zero());
      for (const auto& s : segs) ip.push(s);
      state.ResumeTiming();
    }
    benchmark::DoNotOptimize(out.position_mm.data());
  }
}
BENCHMARK(BM_InterpolatorStep);

BENCHMARK_MAIN();
