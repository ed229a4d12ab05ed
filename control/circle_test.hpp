#pragma once
// Circular test analysis: servo-gain mismatch estimated apart from geometric errors (seed 003,
// Park, Kweon & Yang; interpretation.md "Seed 003").
//
// Circle (eq 1, generalised): commanded position c + R (cos theta, sin theta), theta = s w t,
// s = +1 CCW / -1 CW, w = F / R. The paper's eq 1 is CW with c = (-R, 0) relative to the start.
// Steady state (eq 2): x = c_x + m_x cos(w t + phi_x), y = c_y + s m_y sin(w t + phi_y).
// phi < 0 means lag. Each axis is a P loop around a first-order drive:
//   G(s) = k_p / (tau s^2 + s + k_p)
// Eq 3: k_p = m w / (R |sin phi|), tau = (1/w) (m / (R |sin phi|) + 1/tan phi).
// Eq 4 (phase matching, checked: exact): k'_y = k_p,x + w^2 (tau_y - tau_x); applied as a ratio on
// the configured gain: k_y,new = k_y,cfg * k'_y / k^_p,y.
// In a sampled loop tau_est absorbs the loop delay: tau + (d + 1/2) T (d = transport delay cycles,
// 1/2 T from the zero-order hold); k_p is biased by 1/(cos wD - w tau sin wD) - 1 ~ w^2 tau D
// (3e-4 at w = 8 rad/s, tau = 10 ms, D = 0.5 ms).
//
// Observability (why the ballbar fits take a reference gain): the radius of the eq 2 path,
// squared, holds only a mean and a second harmonic: three numbers for four unknowns. A common
// phase shift of both axes is visible only through the geometric errors (nm-level), so the
// ballbar fits fix k_p,x to a reference (the configured gain) and estimate (tau_x, m_y, phi_y).
// The machine's own encoder record (input a) gives each axis' (m, phi) directly; encoders do not
// see geometric errors, so that fit needs no geometric model.
//
// Methods:
//   fit_machine_record  input (a): per-axis linear sine fit of encoder vs command.
//   fit_ballbar         input (b): LM fit of the radial trace with the geometric model applied
//                       (geometry-aware) or with none (naive: geometry is attributed to the servo).
//   fit_reversal        CW + CCW traces, no geometric model: the servo ellipse flips with direction,
//                       geometry does not; a shared Fourier series in the position angle absorbs
//                       the geometry. tau is not observable this way (its effects do not flip):
//                       it is assumed (tau_assumed), only k_p,y is estimated.
// Also: simulate_circle (the test on the simulated machine, plant = control::FeedDrive) and the
// ellipse metrics of a radial trace.
//
// Offline analysis: allocates, may take O(N * iterations) time; not for the RT cycle. Bad input
// (sizes, non-positive radius/feed) throws std::invalid_argument.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "control/feed_drive.hpp"
#include "control/geometric_error.hpp"

namespace contour::control::circle {

enum class Direction { kCcw, kCw };

struct Circle {
  double radius_mm = 100.0;
  double feed_mm_min = 3000.0;
  Direction direction = Direction::kCw;
  Eigen::Vector2d center_mm = Eigen::Vector2d::Zero();
  double z_mm = 0.0;  // height of the circle plane (Z axis position)

  [[nodiscard]] double omega_rad_s() const { return feed_mm_min / 60.0 / radius_mm; }
  [[nodiscard]] double sign() const { return direction == Direction::kCcw ? 1.0 : -1.0; }
  // Commanded position at t (eq 1).
  [[nodiscard]] Eigen::Vector2d command_mm(double t_s) const;
};

// Input (a): the machine's own record, one entry per sample (t = 0 at the circle start).
struct MachineRecord {
  std::vector<double> t_s;
  std::array<std::vector<double>, 2> command_mm;  // X, Y
  std::array<std::vector<double>, 2> encoder_mm;  // X, Y
};

// Input (b): ballbar radial deviation (actual radius - R), time-aligned with the command
// (t = 0 at the circle start); angle_rad is the position angle about the centre, CCW from +X.
struct BallbarTrace {
  std::vector<double> t_s;
  std::vector<double> angle_rad;
  std::vector<double> deviation_um;
};

struct AxisResponse {  // eq 2
  double m_mm = 0.0;
  double phi_rad = 0.0;
};
struct AxisDynamics {  // eq 3
  double kp_per_s = 0.0;
  double tau_s = 0.0;
};

// Eq 3 and its inverse (the steady-state response of G at w).
AxisDynamics dynamics_from_response(const AxisResponse& r, double radius_mm, double omega_rad_s);
AxisResponse response_of(const AxisDynamics& d, double radius_mm, double omega_rad_s);
// Eq 4 as printed in the paper (in m, phi) and its exact equivalent k_x + w^2 (tau_y - tau_x).
double matched_gain_eq4(const AxisResponse& x, const AxisResponse& y, const AxisDynamics& dx,
                        double radius_mm, double omega_rad_s);
double matched_gain(const AxisDynamics& x, const AxisDynamics& y, double omega_rad_s);

struct FitResult {
  std::array<AxisResponse, 2> response{};
  std::array<AxisDynamics, 2> dynamics{};
  bool kp_x_is_reference = false;  // k_p,x was fixed, not estimated
  bool tau_estimated = true;       // false: tau values are the assumed ones (reversal)
  Eigen::Vector2d center_offset_mm = Eigen::Vector2d::Zero();
  double rms_residual_um = 0.0;
  int iterations = 0;
  bool converged = false;
};

FitResult fit_machine_record(const Circle& c, const MachineRecord& rec);

struct BallbarFitOptions {
  const GeometricErrorModel* geometry = nullptr;  // nullptr: naive (geometry-blind) fit
  double kp_ref_x_per_s = 0.0;                    // reference gain of X (> 0 required)
  double tau_guess_s = 0.01;                      // start value for both axes
};
FitResult fit_ballbar(const Circle& c, const BallbarTrace& trace, const BallbarFitOptions& o);

struct ReversalFitOptions {
  double kp_ref_x_per_s = 0.0;
  std::array<double, 2> tau_assumed_s{0.01, 0.01};
  int harmonics = 6;  // Fourier orders 0..harmonics for the direction-independent part
};
FitResult fit_reversal(const Circle& cw, const BallbarTrace& trace_cw, const Circle& ccw,
                       const BallbarTrace& trace_ccw, const ReversalFitOptions& o);

struct GainMatch {
  double kp_target_y_per_s = 0.0;  // k'_y (eq 4)
  double ratio_y = 1.0;            // k'_y / k^_p,y: multiply the configured Y gain by this
};
GainMatch match_y_to_x(const FitResult& f, double omega_rad_s);

// Radial-trace metrics (Fourier fit of orders 0..4 in the position angle).
struct EllipseMetrics {
  double ellipse_um = 0.0;     // peak-to-peak of the 2nd harmonic (any orientation)
  double ellipse_45_um = 0.0;  // peak-to-peak of its sin(2 theta) part: the 45 deg (lag) ellipse
  double major_axis_deg = 0.0; // direction of the ellipse's long axis
  double circularity_um = 0.0; // max - min after removing the least-squares centre (1st harmonic)
  double mean_um = 0.0;
};
EllipseMetrics ellipse_metrics(const std::vector<double>& angle_rad,
                               const std::vector<double>& deviation_um);

// ---- Simulated test (the plant is control::FeedDrive, one per axis) ----
// Axis loop: u = position_gain * (command - encoder); the drive turns u into velocity K u through
// its lag tau, so the loop gain is k_p = K * position_gain (1/s).
struct SimAxis {
  FeedDriveParams drive{};
  double position_gain = 1.0;
  [[nodiscard]] double kp_per_s() const { return drive.gain_per_s * position_gain; }
  // tau + (d + 1/2) T: what eq 3 measures in the sampled loop.
  [[nodiscard]] double tau_loop_s() const {
    return drive.tau_s + (drive.delay_cycles + 0.5) * drive.period_s;
  }
};
struct SimOptions {
  const GeometricErrorModel* geometry = nullptr;  // machine's true geometric errors
  double noise_um = 0.0;                          // ballbar noise, Gaussian sigma
  std::uint64_t seed = 1;
  double min_settle_s = 0.5;  // at least this, and at least 12 / decay rate of the slowest axis
  int revolutions = 1;        // analysed revolutions after settling
};
struct CircleRun {
  MachineRecord record;   // analysed window only
  BallbarTrace ballbar;   // tool tip through the geometric model, plus noise
  std::vector<double> servo_angle_rad;     // position angle of the true axis positions
  std::vector<double> servo_deviation_um;  // their radial deviation: servo only, no noise
};
CircleRun simulate_circle(const std::array<SimAxis, 2>& axes, const Circle& c,
                          const SimOptions& o);

}  // namespace contour::control::circle
