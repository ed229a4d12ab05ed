#pragma once
// The stability check on every path a gain set reaches the loop (issue 16): `gains set`, SIGHUP,
// start-up. The check itself is control/loop_stability.hpp (linear margin with the real plant,
// delay, predictor and filters, plus closed-loop simulations of the real controller code with
// quantisation and the daemon's clamps); this names the machine's axes and builds the plant from
// the machine section. Setup-time only (allocates, ~10 ms): never on the RT thread.
#include <string>

#include "config/config.hpp"
#include "control/loop_stability.hpp"

namespace contour::daemon {

// The verdict for `p` on machine `m` (its drive models as the plant, its limits as the clamps).
control::StabilityVerdict check_gains(const control::ServoParams& p, const config::MachineConfig& m);

// Empty when `key` (a `gains set` key: kp, ki_per_s, kd_s, ff, cp, ci_per_s, cd_s, coupling) is
// used by the law `p` runs; else why not, naming the law ("gain 'ki_per_s' is not used by the
// active law p (...)"). A gain the law ignores would be "accepted" and change nothing.
std::string inactive_gain_reason(const std::string& key, const control::ServoParams& p);

}  // namespace contour::daemon
