// Google Benchmark of the seed-000 RT cycle: contour-error model + 3 axis controllers + coupling +
// delay predictor (one cycle), the model alone, and the window update alone.
// Built by CMake with CONTOUR_BUILD_BENCHMARKS (tools/bench.sh). BM_Cycle pauses the timer for
// the reference generation each iteration: its median includes that overhead (bench_cycle's
// BM_Cycle3Axis is the full-cycle figure).
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "control/contour_error.hpp"
#include "control/feed_drive.hpp"
#include "control/servo_controller.hpp"

using namespace contour::control;

namespace {
// Eq 11 at 4 m/min in mm, 600 points, repeated with an offset so the path never ends.
std::vector<Vec3> eq11_points() {
  std::vector<Vec3> v;
  for (int k = 0; k < 600; ++k) {
    const double u = k / 599.0;
    v.emplace_back((1.5e5 * u * u - 1.5e5 * u) * 5e-4, -2e4 * u * 5e-4, -5e3 * u * 5e-4);
  }
  return v;
}

struct Loop {
  std::vector<Vec3> ref = eq11_points();
  ContourErrorModel model;
  ServoController ctrl;
  std::array<FeedDrive, 3> drv;
  long k = 0;
  Loop() {
    ServoParams sp;
    sp.delay_cycles = 1;
    ctrl.configure(sp);
    for (auto& d : drv) {
      FeedDriveParams p;
      p.delay_cycles = 1;
      p.blu_mm = 0.0005;
      d.configure(p);
    }
  }
  Vec3 next_ref() {
    const auto n = static_cast<long>(ref.size());
    const long lap = k / n;
    Vec3 r = ref[static_cast<std::size_t>(k % n)];
    r.y() += static_cast<double>(lap) * -10.0;  // continue downwards on the next lap
    ++k;
    return r;
  }
};
}  // namespace

static void BM_Cycle(benchmark::State& state) {
  Loop l;
  Vec3 u;
  for (auto _ : state) {
    const Vec3 r = l.next_ref();
    const Vec3 p(l.drv[0].measured_mm(), l.drv[1].measured_mm(), l.drv[2].measured_mm());
    const Vec3 ph = l.ctrl.predict(p);
    l.model.push_reference(r);
    const ContourErrorResult ce = l.model.update(ph);
    l.ctrl.update(r, ph, ce, Vec3::Zero(), u);
    benchmark::DoNotOptimize(u);
    // The plant is not part of the controller's budget, but it must move for realistic lag.
    state.PauseTiming();
    for (std::size_t i = 0; i < 3; ++i) l.drv[i].step(u[static_cast<Eigen::Index>(i)]);
    state.ResumeTiming();
  }
}
BENCHMARK(BM_Cycle);

// Same cycle without PauseTiming noise: includes the three plant steps (~10 ns).
static void BM_CycleWithPlant(benchmark::State& state) {
  Loop l;
  Vec3 u;
  for (auto _ : state) {
    const Vec3 r = l.next_ref();
    const Vec3 p(l.drv[0].measured_mm(), l.drv[1].measured_mm(), l.drv[2].measured_mm());
    const Vec3 ph = l.ctrl.predict(p);
    l.model.push_reference(r);
    const ContourErrorResult ce = l.model.update(ph);
    l.ctrl.update(r, ph, ce, Vec3::Zero(), u);
    for (std::size_t i = 0; i < 3; ++i) l.drv[i].step(u[static_cast<Eigen::Index>(i)]);
    benchmark::DoNotOptimize(u);
  }
}
BENCHMARK(BM_CycleWithPlant);

// Model alone: the tool 30 points (2 mm) behind on eq 11, window search + circle.
static void BM_ModelOnly(benchmark::State& state) {
  const auto ref = eq11_points();
  ContourErrorModel m;
  std::size_t i = 0;
  for (auto _ : state) {
    m.push_reference(ref[i % ref.size()]);
    const Vec3 p = ref[(i + ref.size() - 30) % ref.size()] + Vec3(0.001, 0.002, 0.0);
    benchmark::DoNotOptimize(m.update(p));
    ++i;
    if (i % ref.size() == 0) m.reset();
  }
}
BENCHMARK(BM_ModelOnly);

// Window update alone: push one point, advance the window (tool at the newest point).
static void BM_WindowUpdate(benchmark::State& state) {
  const auto ref = eq11_points();
  ContourErrorParams p;
  p.kind = ModelKind::kLinear;  // O(1) geometry, isolates push + ring bookkeeping
  ContourErrorModel m(p);
  std::size_t i = 0;
  for (auto _ : state) {
    m.push_reference(ref[i % ref.size()]);
    benchmark::DoNotOptimize(m.update(ref[i % ref.size()]));
    ++i;
    if (i % ref.size() == 0) m.reset();
  }
}
BENCHMARK(BM_WindowUpdate);

static void BM_ThreePointFoot(benchmark::State& state) {
  const Vec3 a(0, 0, 0), b(0.066, 0.01, 0.002), c(0.13, 0.03, 0.004), p(0.05, 0.03, 0.001);
  for (auto _ : state) benchmark::DoNotOptimize(three_point_foot(a, b, c, p));
}
BENCHMARK(BM_ThreePointFoot);

BENCHMARK_MAIN();
