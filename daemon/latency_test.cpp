#include "daemon/latency_test.hpp"

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

namespace contour::daemon {

int run_latency_test(const LatencyTestOptions& opt) {
  CycleStats stats;
  std::atomic<bool> stop{false};
  const auto cycles = static_cast<std::uint64_t>(opt.seconds * 1e9 / static_cast<double>(opt.period_ns));
  RtThread rt;
  RtSetupReport rep;
  try {
    rep = rt.start(opt.rt, [&] {
      CycleClock clock(opt.period_ns);
      clock.start();
      for (std::uint64_t i = 0; i < cycles && !stop.load(std::memory_order_relaxed); ++i) {
        const auto wake = clock.wait_next(stats);
        clock.end_cycle(stats, wake);
      }
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contourd: latency test: %s\n", e.what());
    return 1;
  }
  for (const auto& w : rep.warnings) std::fprintf(stderr, "contourd: WARNING: %s\n", w.c_str());
  rt.join();
  const auto& h = stats.wake_lateness;
  std::printf("latency test: %llu cycles of %.3f ms, %s, memory %s\n",
              static_cast<unsigned long long>(h.count()), static_cast<double>(opt.period_ns) / 1e6,
              rep.realtime ? "SCHED_FIFO" : "SCHED_OTHER (not permitted)",
              rep.memory_locked ? "locked" : "not locked");
  std::printf("wake-up lateness us: min %.1f avg %.1f p99 %.1f p99.9 %.1f max %.1f; overruns %llu\n",
              static_cast<double>(h.min_ns()) / 1000.0, h.mean_us(), h.quantile_us(0.99),
              h.quantile_us(0.999), static_cast<double>(h.max_ns()) / 1000.0,
              static_cast<unsigned long long>(stats.overruns.load()));
  std::printf("histogram (us_low count):\n");
  for (int i = 0; i < LatencyHistogram::kBins; ++i) {
    if (h.bin_count(i) > 0) {
      std::printf("  %8.0f %llu\n", LatencyHistogram::bin_low_us(i),
                  static_cast<unsigned long long>(h.bin_count(i)));
    }
  }
  if (!opt.plot_png.empty()) {
    const std::string dat = opt.plot_png + ".dat";
    {
      std::ofstream f(dat);
      for (int i = 0; i < LatencyHistogram::kBins; ++i) {
        if (h.bin_count(i) > 0) f << LatencyHistogram::bin_low_us(i) << ' ' << h.bin_count(i) << '\n';
      }
    }
    const std::string cmd =
        "gnuplot -e \"set terminal pngcairo size 1000,600; set output '" + opt.plot_png +
        "'; set logscale y; set xlabel 'wake-up lateness (us)'; set ylabel 'cycles'; "
        "set title 'contourd loop wake-up lateness'; plot '" + dat +
        "' using 1:2 with impulses lw 2 title 'cycles'\"";
    if (std::system(cmd.c_str()) != 0) {
      std::fprintf(stderr, "contourd: gnuplot failed; histogram data left in %s\n", dat.c_str());
    } else {
      std::remove(dat.c_str());
      std::printf("plot: %s\n", opt.plot_png.c_str());
    }
  }
  nlohmann::json j{{"cycles", h.count()},
                   {"min_us", static_cast<double>(h.min_ns()) / 1000.0},
                   {"avg_us", h.mean_us()},
                   {"p99_us", h.quantile_us(0.99)},
                   {"p999_us", h.quantile_us(0.999)},
                   {"max_us", static_cast<double>(h.max_ns()) / 1000.0},
                   {"overruns", stats.overruns.load()},
                   {"realtime", rep.realtime}};
  std::printf("%s\n", j.dump().c_str());
  return 0;
}

}  // namespace contour::daemon
