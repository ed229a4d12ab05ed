#pragma once
// Simulated feed drive: the one plant model shared by contour-sim, the in-process simulated bus,
// contour-machine-sim and the tests (style.md: fakes are part of the product).
//
// Model (seed 000 Table 1, interpretation.md): position/command = K / (s (tau s + 1)).
// The command u is position-like (mm); the drive turns it into a velocity K*u (mm/s) through a
// first-order lag tau. Discretised exactly under a zero-order hold at period T:
//   a      = exp(-T/tau)
//   v[k+1] = a v[k] + (1-a) K u[k]
//   x[k+1] = x[k] + tau (1-a) v[k] + K u[k] (T - tau (1-a))
// Optional transport delay of d whole periods (a command issued at step k acts from step k+d), and
// optional quantisation of the reported position to the encoder resolution (BLU).
//
// RT: step() is noexcept, allocation-free, O(1); the delay line is a fixed array.
#include <array>
#include <cmath>

namespace contour::control {

struct FeedDriveParams {
  double gain_per_s = 120.0;   // K, open-loop gain (velocity per unit command), 1/s
  double tau_s = 0.030;        // first-order lag of the velocity loop
  double period_s = 0.001;     // T
  double blu_mm = 0.0;         // encoder quantisation; 0 = none
  int delay_cycles = 0;        // transport delay of the command, whole periods (0..kMaxDelay)
};

class FeedDrive {
 public:
  static constexpr int kMaxDelay = 16;

  FeedDrive() { configure(FeedDriveParams{}); }
  explicit FeedDrive(const FeedDriveParams& p) { configure(p); }

  // Setup-time; clamps delay into [0, kMaxDelay]. Resets the state to rest at position 0.
  void configure(const FeedDriveParams& p);

  // Rest at position x_mm, delay line filled with zero command.
  void reset(double x_mm) noexcept {
    x_mm_ = x_mm;
    v_mm_s_ = 0.0;
    delay_.fill(0.0);
    head_ = 0;
  }

  // Advance one period with command u (mm-like units, see header). Returns the new true position.
  double step(double u) noexcept {
    double applied = u;
    if (p_.delay_cycles > 0) {
      applied = delay_[static_cast<std::size_t>(head_)];
      delay_[static_cast<std::size_t>(head_)] = u;
      if (++head_ == p_.delay_cycles) head_ = 0;  // (no division per step)
    }
    const double x = x_mm_ + c_x_ * v_mm_s_ + d_x_ * applied;
    v_mm_s_ = a_ * v_mm_s_ + b_v_ * applied;
    x_mm_ = x;
    return x_mm_;
  }

  // Replace the command of the last step() by u_last + du_mm (the state becomes what step() with
  // the corrected command would have given). Used by the controller's drive models when the
  // command the drives really got differs from the one computed (the daemon's clamps).
  // RT: noexcept, O(1).
  void correct_last_command(double du_mm) noexcept {
    if (p_.delay_cycles > 0) {
      const int last = head_ == 0 ? p_.delay_cycles - 1 : head_ - 1;
      delay_[static_cast<std::size_t>(last)] += du_mm;
      return;
    }
    x_mm_ += d_x_ * du_mm;
    v_mm_s_ += b_v_ * du_mm;
  }

  // Drives the velocity-mode form: the command is a velocity target v_cmd = K*u (mm/s).
  double step_velocity(double v_cmd_mm_s) noexcept {
    return step(p_.gain_per_s > 0.0 ? v_cmd_mm_s / p_.gain_per_s : 0.0);
  }

  [[nodiscard]] double position_mm() const noexcept { return x_mm_; }
  // Position as the encoder reports it (quantised to the BLU when configured).
  [[nodiscard]] double measured_mm() const noexcept {
    if (p_.blu_mm <= 0.0) return x_mm_;
    return std::round(x_mm_ / p_.blu_mm) * p_.blu_mm;
  }
  [[nodiscard]] double velocity_mm_s() const noexcept { return v_mm_s_; }
  [[nodiscard]] const FeedDriveParams& params() const noexcept { return p_; }

 private:
  FeedDriveParams p_{};
  double a_ = 0.0, b_v_ = 0.0, c_x_ = 0.0, d_x_ = 0.0;
  double x_mm_ = 0.0, v_mm_s_ = 0.0;
  std::array<double, kMaxDelay> delay_{};
  int head_ = 0;
};

}  // namespace contour::control
