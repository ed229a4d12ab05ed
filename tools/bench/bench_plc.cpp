// Google Benchmark of the soft PLC (issue 20), per servo cycle:
//   BM_PlcScanExample   PlcEngine::scan() of the shipped example machine logic
//                       (config/sim.yaml's plc: section: 5 programs, the simulated
//                       plant stepped, NC status in, requests out), the machine RUNNING, a tool
//                       change in progress now and then. What the `logic` stage adds to a cycle.
//   BM_PlcVmExample     the five compiled programs alone through the VM (no I/O, no plant)
//   BM_PlcScan1000Rungs PlcEngine::scan() of a generated 1,000-rung program (contacts in
//                       series/parallel into a coil; a TON every 10th rung) over 32 memory inputs
// Counters: instructions executed per scan (FB calls weighted as the budget counts them).
// Lockstep: the engine's time base is the cycle count, so timers run as on the machine.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "control/plc_vm.hpp"
#include "daemon/plc_engine.hpp"

namespace {

using namespace contour;

std::string read(const std::string& p) {
  std::ifstream in(p);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

config::Config example() {
  const std::string dir = std::string(CONTOUR_SOURCE_DIR) + "/config/";
  return config::load_config_string(read(dir + "sim.yaml"),
                                    dir + "bench_plc.yaml");
}

struct Scan {
  explicit Scan(const config::Config& c) : engine(c) {
    in.state = daemon::MachineState::kRunning;
    in.program_running = true;
    in.axes = 3;
    in.homed = {true, true, true};
    in.spindle_on = true;
    in.spindle_at_speed = true;
    in.coolant_flood = true;
  }
  daemon::PlcEngine engine;
  daemon::PlcNcInput in{};
  daemon::PlcCycleOutput out{};
  std::uint64_t cycle = 0;
};

void BM_PlcScanExample(benchmark::State& state) {
  Scan s(example());
  std::uint64_t changes = 0;
  for (auto _ : state) {
    s.in.cycle = ++s.cycle;
    s.in.pos_mm[0] = static_cast<double>(s.cycle % 1000) * 0.1;
    s.engine.scan(s.in, s.out);
    benchmark::DoNotOptimize(s.out);
    // A tool change every ~3 s of machine time keeps the sequence's branches busy.
    if (s.cycle % 3000 == 0 && s.engine.start_tool_change(static_cast<std::int32_t>(1 + (s.cycle / 3000) % 8))) ++changes;
    if (s.engine.tool_change_state() == daemon::Handshake::kDone) {
      s.in.tool = static_cast<std::int32_t>(1 + (s.cycle / 3000) % 8);
      s.engine.release_tool_change();
    }
  }
  const auto snap = s.engine.snapshot();
  std::uint64_t instr = 0;
  for (const auto& p : snap.programs) instr += p.stats.instructions_max;
  state.counters["instr_max_sum"] = static_cast<double>(instr);
  state.counters["tool_changes"] = static_cast<double>(changes);
}
BENCHMARK(BM_PlcScanExample)->MinTime(1.0);

void BM_PlcVmExample(benchmark::State& state) {
  const config::Config c = example();
  const auto& comp = *c.plc.compiled;
  std::vector<control::plc::Cell> mem(comp.entries.size(), control::plc::int_cell(0));
  std::vector<std::vector<control::plc::Instr>> code;
  std::size_t stack = 1;
  for (const auto& p : comp.programs) {
    code.push_back(control::plc::link(*p, static_cast<std::int32_t>(mem.size())));
    mem.insert(mem.end(), p->locals_init.begin(), p->locals_init.end());
    stack = std::max(stack, static_cast<std::size_t>(p->max_stack));
  }
  std::vector<control::plc::Cell> st(stack);
  std::int64_t now = 0;
  std::uint64_t executed = 0, scans = 0;
  for (auto _ : state) {
    now += 1000000;
    for (const auto& k : code) executed += control::plc::run(k, mem, st, now).executed;
    ++scans;
  }
  state.counters["instr_per_scan"] = static_cast<double>(executed) / static_cast<double>(scans);
}
BENCHMARK(BM_PlcVmExample)->MinTime(1.0);

std::string thousand_rungs() {
  std::string s = "PROGRAM rungs\nVAR\n";
  for (int i = 0; i < 1000; ++i) s += "  r" + std::to_string(i) + " : BOOL;\n";
  for (int i = 0; i < 100; ++i) s += "  t" + std::to_string(i) + " : TON;\n";
  s += "END_VAR\n";
  auto in = [](int k) { return "i" + std::to_string(k % 32); };
  for (int i = 0; i < 1000; ++i) {
    const std::string prev = i == 0 ? "r999" : "r" + std::to_string(i - 1);
    if (i % 10 == 9) {
      const std::string t = "t" + std::to_string(i / 10);
      s += "  " + t + "(IN := " + prev + " AND " + in(i) + ", PT := T#20ms);\n";
      s += "  r" + std::to_string(i) + " := " + t + ".Q OR NOT " + in(i + 5) + ";\n";
    } else {
      s += "  r" + std::to_string(i) + " := (" + in(i) + " AND NOT " + in(i + 1) + ") OR (" +
           prev + " AND " + in(i + 2) + ");\n";
    }
  }
  s += "  q := r999;\nEND_PROGRAM\n";
  return s;
}

void BM_PlcScan1000Rungs(benchmark::State& state) {
  const auto dir = std::filesystem::temp_directory_path() / ("bench_plc_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "rungs.st") << thousand_rungs();
  std::string y =
      "loop: {period_us: 1000}\nbus: {type: sim}\nmachine: {axes: [{name: X}]}\nplc:\n"
      "  instruction_budget: 100000\n  programs: [{file: rungs.st}]\n  signals:\n    - {name: q}\n";
  for (int k = 0; k < 32; ++k) y += "    - {name: i" + std::to_string(k) + "}\n";
  std::ofstream(dir / "c.yaml") << y;
  Scan s(config::load_config_file((dir / "c.yaml").string()));
  std::filesystem::remove_all(dir);
  for (int k = 0; k < 32; k += 3) (void)s.engine.force("i" + std::to_string(k), "TRUE");
  for (auto _ : state) {
    s.in.cycle = ++s.cycle;
    s.engine.scan(s.in, s.out);
    benchmark::DoNotOptimize(s.out);
  }
  const auto snap = s.engine.snapshot();
  state.counters["instr_per_scan"] = static_cast<double>(snap.programs[0].stats.instructions_max);
  state.counters["worst_case"] = static_cast<double>(snap.programs[0].worst_case);
}
BENCHMARK(BM_PlcScan1000Rungs)->MinTime(1.0);

}  // namespace

BENCHMARK_MAIN();
