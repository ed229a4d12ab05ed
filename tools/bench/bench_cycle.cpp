// Google Benchmark of one full 3-axis control cycle as contourd runs it (issue 11):
//   FIR interpolator step (short-segment CAM program planned once at setup, G64 P0.05 blending)
//   -> Smith predictor -> contour-error model (window update + circle model, eq 7)
//   -> axis + coupling controllers -> 2-DOF force controller step.
// The plant (3 FeedDrives + the force plant) runs inside the timed loop so the loop sees realistic
// lag; BM_PlantOnly measures that share alone (a few ns) so it can be subtracted by eye.
// PauseTiming() is deliberately not used: it costs ~200-400 ns per call here, more than the cycle.
//
// Second mode (not a benchmark): `bench_cycle --plan-file FILE [--period-ms T]` streams FILE line by
// line through GcodeParser + BlendPlanner (true-tolerance method, the program's G64 P) and discards
// planned segments after counting them, like contourd's planner thread feeding the RT ring. Prints
// one JSON line: blocks, program_s (simulated time incl. the FIR tail), wall_s, realtime_factor,
// peak_rss_mb (getrusage ru_maxrss of the whole process). tools/bench.sh uses it.
#include <benchmark/benchmark.h>

#include "tools/bench/plan_program.hpp"
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/contour_error.hpp"
#include "control/feed_drive.hpp"
#include "control/fir_interpolator.hpp"
#include "control/force_2dof.hpp"
#include "control/force_controller.hpp"
#include "control/gcode.hpp"
#include "control/servo_controller.hpp"

using namespace contour::control;

namespace {

// CAM-style program: 0.1-1.0 mm chords of a wandering 2-D curve with slow Z, G64 P0.05, 4 m/min.
std::vector<std::string> cam_program(int n) {
  std::vector<std::string> lines{"G17 G21 G90 G94", "G64 P0.05", "F4000"};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double x = 0.0, y = 0.0, z = 0.0, h = 0.0;
  for (int i = 0; i < n; ++i) {
    h += 0.6 * (u(rng) - 0.5);
    const double l = 0.1 + 0.9 * u(rng);
    x += l * std::cos(h);
    y += l * std::sin(h);
    z = 0.5 * std::sin(0.01 * i);
    char buf[96];
    std::snprintf(buf, sizeof buf, "G1 X%.4f Y%.4f Z%.4f", x, y, z);
    lines.emplace_back(buf);
  }
  lines.emplace_back("M2");
  return lines;
}

std::vector<PlannedSegment> plan_all(const std::vector<std::string>& prog) {
  return contour::bench::plan_program(prog);
}

struct CycleRig {
  std::vector<PlannedSegment> segs = plan_all(cam_program(3000));
  InterpolatorParams ip{};
  Interpolator interp;
  ContourErrorModel model;
  ServoController ctrl;
  std::array<FeedDrive, 3> drv;
  ForceController force;
  ForcePlantSim force_plant;
  InterpOutput io;
  double override_ = 1.0;
  Vec3 u = Vec3::Zero();
  Vec3 r_prev = Vec3::Zero();
  std::int64_t restarts = 0;

  CycleRig() {
    ip.capacity = segs.size() + 8;
    restart();
    ServoParams sp;
    sp.delay_cycles = 1;
    for (auto& d : sp.drive) d.delay_cycles = 1;
    ctrl.configure(sp);
    for (auto& d : drv) {
      FeedDriveParams p;
      p.delay_cycles = 1;
      p.blu_mm = 0.0005;
      d.configure(p);
    }
    const ForceDesign fd = design_force_2dof(ForceDesignParams{});
    force.configure(fd, ForceLimits{});
    force_plant.configure(ForcePlantParams{}, fd.period_s);
    force_plant.reset(1.0, 0.0, 0.0);
    force.enable(ForceEnableState{1.0, 3000.0, force_plant.force_N(), 0.0});
  }
  // Not timed-out of the loop (rare: once per ~3000 blocks); reuses the ring, no allocation.
  void restart() {
    interp.configure(ip, Eigen::Vector3d::Zero());
    for (const auto& s : segs) interp.push(s);
    ++restarts;
  }

  // The controller part of one cycle; returns the command for the plant.
  void control_cycle() noexcept {
    if (interp.step(override_, io) == InterpStatus::kDone) {
      restart();
    }
    const Vec3& r = io.position_mm;
    const Vec3 v_ref = (r - r_prev) * 1000.0;
    r_prev = r;
    const Vec3 p(drv[0].measured_mm(), drv[1].measured_mm(), drv[2].measured_mm());
    const Vec3 ph = ctrl.predict(p);
    model.push_reference(r);
    const ContourErrorResult ce = model.update(ph);
    ctrl.update(r, ph, ce, v_ref, u);
    ForceInput in;
    in.force_ref_N = 1.0;
    in.planned_progress_mm = io.path_progress_mm;
    in.force_N = force_plant.force_N();
    in.progress_mm = force_plant.progress_mm();
    const ForceOutput fo = force.step(in);
    override_ = fo.feed_override;
    benchmark::DoNotOptimize(fo);
  }
  void plant_cycle() noexcept {
    for (Eigen::Index i = 0; i < 3; ++i) drv[static_cast<std::size_t>(i)].step(u[i]);
    force_plant.step(override_, 0.0);
  }
};

void BM_Cycle3Axis(benchmark::State& state) {
  CycleRig rig;
  for (auto _ : state) {
    rig.control_cycle();
    rig.plant_cycle();
    benchmark::DoNotOptimize(rig.u.data());
  }
  state.counters["program_restarts"] = static_cast<double>(rig.restarts - 1);
}
BENCHMARK(BM_Cycle3Axis);

void BM_PlantOnly(benchmark::State& state) {
  CycleRig rig;
  rig.u = Vec3(0.01, -0.02, 0.003);
  for (auto _ : state) {
    rig.plant_cycle();
    benchmark::DoNotOptimize(rig.drv[0].measured_mm());
  }
}
BENCHMARK(BM_PlantOnly);

void BM_InterpolatorStepCam(benchmark::State& state) {
  CycleRig rig;
  for (auto _ : state) {
    if (rig.interp.step(1.0, rig.io) == InterpStatus::kDone) rig.restart();
    benchmark::DoNotOptimize(rig.io.position_mm.data());
  }
}
BENCHMARK(BM_InterpolatorStepCam);

// The contour-error model alone on the interpolated CAM path, tool 20 cycles behind.
void BM_ContourModel(benchmark::State& state) {
  CycleRig rig;
  std::vector<Vec3> ref;
  InterpOutput o;
  for (int k = 0; k < 20000; ++k) {
    rig.interp.step(1.0, o);
    ref.push_back(o.position_mm);
  }
  ContourErrorModel m;
  std::size_t i = 0;
  for (auto _ : state) {
    m.push_reference(ref[i]);
    const Vec3 p = ref[i >= 20 ? i - 20 : 0] + Vec3(0.001, 0.002, 0.0);
    benchmark::DoNotOptimize(m.update(p));
    if (++i == ref.size()) {
      i = 0;
      m.reset();
    }
  }
}
BENCHMARK(BM_ContourModel);

double now_s() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int plan_file(const char* path, double period_ms) {
  std::ifstream in(path);
  if (!in) {
    std::fprintf(stderr, "bench_cycle: cannot open %s\n", path);
    return 2;
  }
  PlannerParams pp;
  pp.period_s = period_ms * 1e-3;
  const double t0 = now_s();
  GcodeParser parser(ProgramSetup{}, path);
  BlendPlanner planner(pp, Eigen::Vector3d::Zero());
  std::vector<Block> blocks;
  PlannedSegment s;
  std::int64_t end_cycle = 0, segments = 0, lines = 0;
  auto drain = [&] {
    for (const auto& b : blocks) planner.push(b);
    blocks.clear();
    while (planner.pop(s)) {
      ++segments;
      end_cycle = std::max(end_cycle, s.start_cycle + s.samples);
    }
  };
  std::string line;
  try {
    while (std::getline(in, line)) {
      ++lines;
      parser.parse_line(line, blocks);
      drain();
    }
    parser.finish(blocks);
    drain();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_cycle: %s\n", e.what());
    return 1;
  }
  const double wall_s = now_s() - t0;
  // The last block's command ends at end_cycle; the FIR tail (L-1 periods) settles it.
  const double program_s =
      static_cast<double>(end_cycle + pp.fir_taps - 1 + pp.fir2_taps) * pp.period_s;
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  std::printf(
      "{\"lines\":%lld,\"segments\":%lld,\"moves\":%lld,\"program_s\":%.3f,\"wall_s\":%.4f,"
      "\"realtime_factor\":%.1f,\"peak_rss_mb\":%.1f}\n",
      static_cast<long long>(lines), static_cast<long long>(segments),
      static_cast<long long>(planner.stats().moves), program_s, wall_s, program_s / wall_s,
      static_cast<double>(ru.ru_maxrss) / 1024.0);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 3 && std::strcmp(argv[1], "--plan-file") == 0) {
    double period_ms = 1.0;
    if (argc >= 5 && std::strcmp(argv[3], "--period-ms") == 0) period_ms = std::atof(argv[4]);
    return plan_file(argv[2], period_ms);
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
