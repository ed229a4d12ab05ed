#include "control/feed_drive.hpp"

namespace contour::control {

void FeedDrive::configure(const FeedDriveParams& p) {
  p_ = p;
  if (p_.delay_cycles < 0) p_.delay_cycles = 0;
  if (p_.delay_cycles > kMaxDelay) p_.delay_cycles = kMaxDelay;
  // tau = 0 is a pure integrator (velocity follows the command at once): a -> 0.
  const double tau = p_.tau_s > 1e-12 ? p_.tau_s : 1e-12;
  a_ = std::exp(-p_.period_s / tau);
  b_v_ = (1.0 - a_) * p_.gain_per_s;
  c_x_ = tau * (1.0 - a_);
  d_x_ = p_.gain_per_s * (p_.period_s - tau * (1.0 - a_));
  reset(0.0);
}

}  // namespace contour::control
