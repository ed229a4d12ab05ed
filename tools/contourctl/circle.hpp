#pragma once
// contourctl circle-test: seed 003's circular test run on the machine through the socket, analysed
// with control/circle_test.hpp (input (a): the machine's own record, command vs encoder).
//
// Procedure: READY, no program loaded; the active gains are saved, the coupling controller and
// velocity feed-forward are switched off for the test (eq 3 models each axis as a P loop around
// a first-order drive; the coupling controller would couple the axes), telemetry is recorded to a
// CSV, an inline G2/G3 full circle (P turns) starting at the current position is run, the gains
// are restored (or, with --apply, replaced by the matched ones). The analysed window skips the
// first revolution (FIR ramp and settling; the slowest sim loop settles in ~0.2 s) and the last
// half revolution (deceleration).
//
// Estimates per axis (X, Y): loop gain k_p (1/s, eq 3) and loop time constant tau (s, eq 3, which
// in a sampled loop includes (d + 1/2) T of transport delay and hold); the drive gain K = k_p /
// position gain and the drive lag tau - (d + 1/2) T follow. Matched gains: eq 4 (Y matched to X).
#include <nlohmann/json.hpp>
#include <string>

#include "tools/contourctl/client.hpp"

namespace contour::ctl {

struct CircleTestOptions {
  double radius_mm = 10.0;
  double feed_mm_min = 2000.0;
  bool cw = true;
  bool ccw = false;
  int turns = 3;
  int delay_cycles = 1;  // bus transport delay (config: the drives' / sim's delay_cycles)
  // control.delay_compensation of the daemon's config (default true): the delay is then outside
  // the position loop and is removed from the measured phase. Neither value is reported by the
  // daemon today, hence options.
  bool delay_compensation = true;
  double period_s = 0.0;   // servo period; 0: from the CSV's t_s column
  bool keep_csv = false;  // keep the CSVs (in the daemon's telemetry directory; report "csv")
  bool apply = false;
  std::string plot_png;  // polar plot of the radial deviation ("" = none)
  bool verbose = true;   // progress lines on stderr
};

// Runs the test; returns a JSON report (per direction and combined estimates, proposed gains,
// applied or not). Throws ErrorReply / Unreachable / std::runtime_error with a clear message; the
// original gains are restored on every error path once they were changed.
nlohmann::json run_circle_test(Client& c, const CircleTestOptions& o);

// Human-readable summary of the report.
std::string format_circle_report(const nlohmann::json& r);

}  // namespace contour::ctl
