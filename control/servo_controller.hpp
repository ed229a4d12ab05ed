#pragma once
// Axis controllers (P, PID eq 10 form, velocity feed-forward), the 3-axis coupling controller
// C = diag(C(z)) on the contour-error vector (seed 000 §2.2, eqs 9-10, Fig 2), command limits with
// anti-windup, and the one-cycle-transport-delay compensation (Smith predictor on the feed-drive
// model). Units: positions and commands in mm, time in s.
//
// Command convention (control/feed_drive.hpp): the command u is position-like (mm); a feed drive
// turns it into a velocity K*u (K = drive open-loop gain, 1/s). A velocity-mode drive (CiA 402
// CSV) gets the target velocity v_target = K_drive * u (mm/s, then scaled to counts/s at the
// driver edge); the K in that product is the `drive gain` configured for the axis (Table 1:
// 120 1/s X/Y, 115 1/s Z), not a property of the controller.
//
// Per axis i (e = R - P_hat, all from the same cycle k):
//   P:    u_i = Kp e
//   PID:  u_i = Kp e + Ki T sum(e) + Kd (e(k) - e(k-1)) / T          (eq 10 form, z/(z-1): the
//         integral includes the current sample)
//   FF:   + ff * v_ref_i / K_i (v_ref from the interpolator, mm/s; ff in [0, 1], default 0)
// Coupling (when enabled): u += Cp eps + Ci I + Cd (eps(k) - eps(k-1)) / T, I += T eps, and then,
//   when remove_tangential_integral is set, I -= t (t . I) with t the model's unit tangent at K.
//   Why: the paper's I accumulates an along-path component each time the path turns, which nothing
//   unwinds; the machine then comes to rest 0.1-0.5 mm from the end point (interpretation.md).
//   Dropping it each cycle makes the equilibrium unique (P on the end point) and also lowers the
//   coupled contour error.
// Limits: |u_i| <= u_max_i (mm; = max velocity / K). Anti-windup by conditional integration: on an
//   axis that is saturated, an integrator step that would push further into saturation is undone
//   (axis integrator and that axis' component of the coupling integrator).
// Delay compensation: a command computed after SYNC k acts from SYNC k+d (CANopen synchronous
//   PDOs: d = 1). predict() returns P_hat = P_meas + x_m(k) - x_m(k-d), x_m the undelayed drive
//   model driven by the issued commands (Smith predictor). With an exact model the controller sees
//   the undelayed plant shifted by d cycles, so the paper's gains keep their margin; without it
//   the coupled loop with the paper's gains is unstable at d = 1 (loop_margin() shows both).
//
// RT: predict() and update() are noexcept, allocation-free, O(axes). Budget < 1 us per cycle.
#include <array>
#include <cstdint>
#include <limits>

#include "control/contour_error.hpp"
#include "control/feed_drive.hpp"

namespace contour::control {

inline constexpr int kMaxServoAxes = 3;

enum class AxisLaw { kP, kPid };

struct AxisGains {
  double kp = 0.6;        // axial gain (dimensionless: mm of command per mm of error)
  double ki_per_s = 0.0;  // integral gain, 1/s
  double kd_s = 0.0;      // derivative gain, s
  double ff = 0.0;        // velocity feed-forward fraction, 0..1
  double u_max_mm = std::numeric_limits<double>::infinity();  // command limit
};

struct CouplingGains {
  bool enable = true;
  double cp = 15.0;          // Table 1
  double ci_per_s = 300.0;
  double cd_s = 0.3;
  bool remove_tangential_integral = true;
};

// Filtering of the derivative terms (axis PID kd_s and coupling cd_s), issue 16. Why: on a
// 0.5 um encoder the derivative (e(k) - e(k-1)) / T turns every count into a command step of
// Cd K BLU / T = 18 mm/s (Table 1); through the daemon on Table 2 the cycle-to-cycle change of the
// velocity command was 14.2 / 13.1 / 20.0 mm/s RMS (X/Y/Z) with the coupling, 0.8 / 0.6 / 0.06
// with P only. A plain low-pass on the derivative cannot fix that here: the Table 1 coupled loop
// crosses over at ~1200 rad/s on the derivative's lead (Cd K / tau), and a 1 ms low-pass already
// costs 17 % of the seed-000 Table 2 figure (control/CHATTER.md has the table).
//   model_blend_s: the derivative terms act on the model-aided position
//       P_tilde = m(k) + F(z) (P_hat(k) - m(k)),  F(z) = ((1 - a) / (1 - a z^-1))^2,
//       a = exp(-T / model_blend_s),
//     m the undelayed drive model driven by the issued commands (the Smith predictor's model,
//     run at every delay). A complementary filter: at high frequency the derivative sees the
//     model's motion (no encoder counts, no phase lag), at low frequency the encoder. With an
//     exact model P_hat - m is the quantisation noise alone and the loop's dynamics are those of
//     the unquantised loop; with a model error the residual reaches the derivative through F (a
//     steady gain error gives a constant offset, which a derivative ignores). The P and I terms
//     keep the raw P_hat. 0 = off (the paper's law). This is a "filtered Smith predictor"
//     (Normey-Rico & Camacho) applied to the derivative path only.
//   same_geometry: the coupling derivative differences the previous and the current position on
//     THIS cycle's circle/line (eps_on), instead of eps(k) - eps(k-1) across two windows.
//     kAhead (default): only while the model extrapolates (window on the newest points, the tool
//     at or ahead of the reference: a decelerating reference at a blended corner); a new circle
//     there is a guess about the path ahead, not tool motion. kAlways costs 11 % of the seed-000
//     Table 2 figure (sharp G01 corners, where the window change is the real corner).
//   lowpass_s: first-order low-pass on the derivative terms' outputs (the textbook filtered D,
//     Kd s / (T_f s + 1)); 0 = off. Kept for drives whose model is poor; see CHATTER.md.
enum class SameGeometry { kNever, kAhead, kAlways };

struct DerivativeFilter {
  double model_blend_s = 0.0;
  SameGeometry same_geometry = SameGeometry::kNever;
  double lowpass_s = 0.0;
};

struct ServoParams {
  int axes = 3;
  AxisLaw law = AxisLaw::kP;
  std::array<AxisGains, kMaxServoAxes> axis{};
  CouplingGains coupling{};
  // Drive models (gain, tau, period). Used for the feed-forward scaling (u = v/K) and, when
  // delay_compensation is on, for the Smith predictor. delay_cycles here is the bus delay to
  // compensate (drives' own delay_cycles fields are ignored).
  std::array<FeedDriveParams, kMaxServoAxes> drive{};
  double period_s = 0.001;
  int delay_cycles = 0;
  bool delay_compensation = true;
  DerivativeFilter derivative{};
};

enum class ServoStatus : std::uint8_t { kOk = 0, kSaturated };

// The parts of the last command, before the limit (mm of command; times K = mm/s), for telemetry
// and tuning: u = axis_p + axis_i + axis_d + ff + coupling_p + coupling_i + coupling_d.
struct ServoTerms {
  Vec3 axis_p = Vec3::Zero(), axis_i = Vec3::Zero(), axis_d = Vec3::Zero(), ff = Vec3::Zero();
  Vec3 coupling_p = Vec3::Zero(), coupling_i = Vec3::Zero(), coupling_d = Vec3::Zero();
};

class ServoController {
 public:
  ServoController() { configure(ServoParams{}); }
  explicit ServoController(const ServoParams& p) { configure(p); }

  // Setup; throws std::invalid_argument on axes outside 1..3, non-positive period or drive gain,
  // negative gains, delay outside 0..FeedDrive::kMaxDelay.
  void configure(const ServoParams& p);
  // Zero integrators and predictor, tool at rest at p_mm.
  void reset() noexcept;

  // Live gains (issue 9 "retune live"): the checks configure() makes, without touching any state.
  // Throws std::invalid_argument naming the problem.
  static void validate(const ServoParams& p);
  // Throws std::invalid_argument when `p` differs from the active set in a part that cannot change
  // while the controller runs: axes, period, drive models, delay_cycles, delay_compensation (the
  // Smith predictor's model and history are built from them). Setup-time (non-RT).
  void check_live_compatible(const ServoParams& p) const;
  // Swaps the gains (axis kp/ki/kd/ff/u_max, law, coupling gains and enable) and KEEPS the state:
  // axis and coupling integrators, previous errors (derivative terms), Smith predictor history.
  // Bumpless in the integral part: each integrator is rescaled so that its contribution to the
  // command (Ki * I) is the same before and after the swap; a contribution that the new set drops
  // (Ki or Ci = 0, law P, coupling off) is cleared, and an integrator that did not contribute
  // before restarts from 0. The proportional/derivative terms change with their gains (a command
  // step of dKp * e, unavoidable without a gain ramp). Precondition: validate(p) and
  // check_live_compatible(p) passed (debug assert only). RT: noexcept, no allocation, O(axes).
  void set_gains(const ServoParams& p) noexcept;

  // P_hat: the position the command computed now will meet (Smith predictor), mm.
  [[nodiscard]] Vec3 predict(const Vec3& p_meas_mm) const noexcept;

  // One cycle. r: reference R(k); p_hat: predict(P_meas); ce: the contour-error model's result for
  // p_hat; v_ref: reference velocity (mm/s, only used with ff > 0). Writes the command (mm).
  ServoStatus update(const Vec3& r_mm, const Vec3& p_hat_mm, const ContourErrorResult& ce,
                     const Vec3& v_ref_mm_s, Vec3& u_out) noexcept;

  // The command the drives really got this cycle (mm, same convention as update()'s output), when
  // the caller limited it after update() (the daemon's velocity and acceleration clamps): the
  // drive models (Smith predictor, derivative model blend) then follow the real drives instead of
  // drifting away from them. Call after update(), before the next predict(); a call without a
  // preceding update() (or a second one) is ignored. RT: noexcept, O(axes).
  void command_applied(const Vec3& u_applied_mm) noexcept;

  [[nodiscard]] const ServoParams& params() const noexcept { return p_; }
  [[nodiscard]] const ServoTerms& last_terms() const noexcept { return terms_; }
  [[nodiscard]] const Vec3& coupling_integral() const noexcept { return ic_; }

 private:
  ServoParams p_{};
  Vec3 ia_ = Vec3::Zero();      // axis integrators (mm s)
  Vec3 e_prev_ = Vec3::Zero();
  Vec3 ic_ = Vec3::Zero();      // coupling integrators
  Vec3 eps_prev_ = Vec3::Zero();
  Vec3 resid_f1_ = Vec3::Zero();
  Vec3 resid_f_ = Vec3::Zero();
  Vec3 p_tilde_prev_ = Vec3::Zero();
  Vec3 u_last_ = Vec3::Zero();   // the command the models were stepped with
  bool applied_pending_ = false; // update() ran; command_applied() may still correct it
  ServoTerms terms_{};           // the last update()'s terms (P, I, D, coupling)
  Vec3 d_axis_ = Vec3::Zero();   // low-passed derivative terms (mm of command)
  Vec3 d_coup_ = Vec3::Zero();
  double a_blend_ = 0.0;         // exp(-T / model_blend_s), 0 when off
  double a_lowpass_ = 0.0;       // exp(-T / lowpass_s), 0 when off
  bool first_ = true;
  std::array<FeedDrive, kMaxServoAxes> model_nd_{};  // undelayed model
  std::array<FeedDrive, kMaxServoAxes> model_d_{};   // same model with the bus delay
};

// Stability margin of the coupled loop in the direction normal to the path, where the axis and
// coupling controllers act on the same error: u = (Kp + C(z)) e_n, plant K/(s(tau s+1)) z^-d.
// plant_gain_scale multiplies the true plant gain (model mismatch; the predictor keeps the nominal
// model). Computed from the closed-loop state matrix (setup-time: allocates).
struct LoopMargin {
  double spectral_radius = 0.0;  // < 1: stable
  double gain_margin = 0.0;      // largest factor on all controller gains keeping it stable
};
LoopMargin loop_margin(const FeedDriveParams& drive, const AxisGains& axis,
                       const CouplingGains& coupling, int delay_cycles, bool smith_predictor,
                       double plant_gain_scale = 1.0);

}  // namespace contour::control
