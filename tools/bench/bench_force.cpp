// Google Benchmark of the 2-DOF force channel's per-cycle step (issue 5). Not wired into the
// build yet; by hand:
//   g++ -std=c++20 -O2 -DNDEBUG -I. -isystem /usr/include/eigen3 tools/bench/bench_force.cpp
//       control/lti.cpp control/force_2dof.cpp control/force_controller.cpp -lbenchmark -lpthread
//       -o /tmp/bench_force && /tmp/bench_force
#include <benchmark/benchmark.h>

#include "control/force_2dof.hpp"
#include "control/force_controller.hpp"

namespace {
using namespace contour::control;

void BM_ForceControllerStep(benchmark::State& state) {
  const ForceDesign d = design_force_2dof(ForceDesignParams{});
  ForceController c;
  c.configure(d, ForceLimits{});
  ForcePlantSim p;
  p.configure(ForcePlantParams{}, d.period_s);
  p.reset(1.0, 0.0, 0.0);
  c.enable(ForceEnableState{1.0, 3000.0, p.force_N(), 0.0});
  long k = 0;
  for (auto _ : state) {
    ForceInput in;
    in.force_ref_N = 1.0;
    in.planned_progress_mm = 4.5e-3 * static_cast<double>(k++);
    in.force_N = p.force_N();
    in.progress_mm = p.progress_mm();
    const ForceOutput o = c.step(in);
    benchmark::DoNotOptimize(o);
    p.step(o.feed_override, (o.spindle_rpm - 3000.0) / 1000.0);
  }
}
BENCHMARK(BM_ForceControllerStep);

void BM_ForceDesign(benchmark::State& state) {
  for (auto _ : state) {
    const ForceDesign d = design_force_2dof(ForceDesignParams{});
    benchmark::DoNotOptimize(d.f);
  }
}
BENCHMARK(BM_ForceDesign)->Unit(benchmark::kMillisecond);
}  // namespace

BENCHMARK_MAIN();
