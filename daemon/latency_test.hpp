#pragma once
// `contourd --latency-test SECONDS`: runs the RT loop set-up (same thread attributes, memory
// locking and CycleClock as the servo loop) without drives and records wake-up lateness like
// cyclictest. Prints min/avg/p99/p99.9/max and a histogram; optional PNG through gnuplot.
#include <string>

#include "daemon/rt_timing.hpp"

namespace contour::daemon {

struct LatencyTestOptions {
  double seconds = 10.0;
  std::int64_t period_ns = 1'000'000;
  RtSetupRequest rt{};
  std::string plot_png;   // empty: no plot
  bool json = false;      // last line JSON
};

// Returns the process exit status.
int run_latency_test(const LatencyTestOptions& opt);

}  // namespace contour::daemon
