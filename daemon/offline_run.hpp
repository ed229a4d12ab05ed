#pragma once
// In-process run of a part program through the daemon's own loop code (ServoLoop on a SimBus,
// ProgramPlanner, TelemetryWriter), driven cycle by cycle on the caller's thread without sleeping.
// The daemon in sim mode runs the same code, lockstep, so it must give the same figures; tests
// compare the two. Not RT (setup allocates; the cycles themselves do not).
#include <cstdint>
#include <string>

#include "config/config.hpp"
#include "daemon/planner.hpp"
#include "daemon/telemetry.hpp"

namespace contour::daemon {

struct OfflineResult {
  std::string state;            // final machine state
  std::string cause;            // its cause ("following error", ...; "none" after a clean run)
  int fault_axis = -1;          // axis of that fault when it names one
  double fault_value = 0.0, fault_limit = 0.0;
  bool finished_ok = false;
  std::uint64_t cycles = 0;     // program cycles (RUNNING/HOLD)
  RunStats stats;
  double duration_s = 0.0;
  std::uint64_t velocity_clamps = 0;
  std::uint64_t underruns = 0;
};

// Throws ProgramError / std::runtime_error. max_cycles bounds the run.
OfflineResult run_offline(const config::Config& cfg, const ProgramText& src,
                          std::uint64_t max_cycles = 2'000'000,
                          const std::string& csv_path = "");

}  // namespace contour::daemon
