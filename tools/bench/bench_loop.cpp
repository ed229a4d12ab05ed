// Google Benchmark of ServoLoop::cycle() as contourd runs it (issue 15): every stage of the
// pipeline (read -> commands -> logic -> reference -> control -> channels -> write -> supervise
// -> publish) on the in-process simulated machine (SimBus, lockstep), while the Table 2 part
// program runs; the program is re-loaded when it ends (outside the timed region's hot path: one
// load per ~5000 cycles). Compare its median with bench_cycle's control-only figure, and across
// commits as a ratio within one run (tools/bench.sh).
#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "config/config.hpp"
#include "daemon/planner.hpp"
#include "daemon/servo_loop.hpp"
#include "daemon/sim_bus.hpp"

namespace {

using namespace contour;

struct LoopBench {
  LoopBench()
      : cfg(config::load_config_file(config_path())),
        bus(drives()),
        loop(cfg, bus, 1 << 16),
        planner(cfg) {
    loop.post({daemon::CommandKind::kEnable});
    for (int i = 0; i < 10; ++i) loop.cycle();
  }
  // CONTOUR_BENCH_CONFIG=FILE runs the loop on another config (e.g. with a round-2 feature
  // switched off, to measure what it costs); default config/sim.yaml.
  static std::string config_path() {
    const char* env = std::getenv("CONTOUR_BENCH_CONFIG");
    return env != nullptr && *env != '\0' ? std::string(env)
                                           : std::string(CONTOUR_SOURCE_DIR) + "/config/sim.yaml";
  }
  std::vector<control::FeedDriveParams> drives() const {
    std::vector<control::FeedDriveParams> d;
    for (const auto& a : cfg.machine.axes) {
      auto p = a.drive;
      p.period_s = cfg.machine.period_s;
      d.push_back(p);
    }
    return d;
  }
  void start_program() {
    const auto st = loop.status();
    const Eigen::Vector3d start(st.ref_mm[0], st.ref_mm[1], st.ref_mm[2]);
    job = planner.start({"table2.ngc", std::string(CONTOUR_SOURCE_DIR) + "/config/programs/table2.ngc", ""},
                        start, ++id, [](std::uint64_t, const control::PlannedSegment&) {});
    daemon::ProgramPlanner::wait_prefill(*job, 30.0);
    loop.post({daemon::CommandKind::kAttachJob, 0, 0.0, 0.0, job.get()});
    loop.cycle();
    loop.post({daemon::CommandKind::kRun});
    loop.cycle();
  }
  config::Config cfg;
  daemon::SimBus bus;
  daemon::ServoLoop loop;
  daemon::ProgramPlanner planner;
  std::shared_ptr<daemon::ProgramJob> job;
  std::uint64_t id = 0;
};

void BM_ServoLoopCycle(benchmark::State& state) {
  LoopBench b;
  b.start_program();
  daemon::RtEvent e;
  daemon::TelemetrySample s;
  std::uint32_t n = 0;
  for (auto _ : state) {
    b.loop.cycle();
    while (b.loop.events().pop(e)) {}
    while (b.loop.telemetry().pop(s)) {}
    // The program's end is looked for every 64 cycles: status() copies the whole published
    // status (a seqlock read the daemon makes per request, not per cycle), which is not the
    // cycle's cost. Up to 63 cycles at rest after the end are timed as cycles (~1 %).
    if ((++n & 63U) == 0 && b.loop.status().state != daemon::MachineState::kRunning) {
      state.PauseTiming();
      b.start_program();
      state.ResumeTiming();
    }
  }
}
BENCHMARK(BM_ServoLoopCycle)->MinTime(2.0);

}  // namespace

BENCHMARK_MAIN();
