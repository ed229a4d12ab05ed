#pragma once
// Feed-drive identification for commissioning (`contourctl identify [AXIS]`, issue 16): from a
// small-move experiment at standstill, estimate the axis' gain K (1/s), the time constant tau (s)
// of its velocity loop and the transport delay d in whole cycles, i.e. the model the controller
// and the stability check use (control/feed_drive.hpp):
//     position / command = K / (s (tau s + 1)) * z^-d,   command u = v_cmd / K_cmd (mm)
// where v_cmd is the velocity target the loop wrote (mm/s) and K_cmd the gain the loop used to
// turn its command into that target (the configured drive gain). For a velocity-mode drive that
// follows its target exactly in steady state, K = K_cmd; a drive whose velocity is off by a
// factor G (scaling, units) gives K = G * K_cmd.
//
// Conventions (the same as FeedDrive with delay_cycles = d and the daemon's cycle): sample k holds
// the position READ in cycle k and the velocity target WRITTEN in cycle k; with d = 0 the target
// written in cycle k first moves the position read in cycle k+1 (CANopen synchronous PDOs through
// the daemon: d = 1, the `sim.delay_cycles` default).
//
// Method: output error. For each candidate delay d in 0..max_delay_cycles and time constant tau,
// the exact ZOH response s(k; tau, d) of the unit-gain model to the recorded command is simulated;
// the position is linear in (x0, K) given (tau, d): x(k) = x0 + K s(k), solved by least squares.
// tau is found per d by a log-spaced grid (0.1 ms .. 2 s) refined by golden-section search; the
// delay with the smallest residual wins. Unbiased under white measurement noise (quantisation to
// the BLU, +-1 BLU noise), unlike an equation-error (ARX) fit on differenced positions.
// Cost: O(max_delay_cycles * 100 * samples); the default excitation (836 samples) with max delay 8:
// 8-17 ms on the shared 2-core VM (g++ -O2).
// Setup-time code (allocates); not for the RT thread.
#include <string>
#include <vector>

namespace contour::control {

// A short sequence of velocity pulses the machine can make at rest (the daemon writes one value
// per cycle on the axis under test, the other axes holding position). Net displacement zero; the
// axis ends at rest where it started (to the drive's accuracy).
//   1. +A for long_pulse_s, rest, -A for long_pulse_s, rest       (gain and time constant)
//   2. short_pulses pairs of +A / -A pulses of short_pulse_s each, rest after each (delay)
// Defaults: A = 5 mm/s, 100 ms / 4 ms pulses, 150 ms rests: 0.84 s, largest excursion
// A * long_pulse_s = 0.5 mm from the start, peak acceleration ~A / tau (167 mm/s^2 at 30 ms).
struct ExcitationParams {
  double period_s = 0.001;
  double amplitude_mm_s = 5.0;
  double long_pulse_s = 0.100;
  double short_pulse_s = 0.004;
  double rest_s = 0.150;
  int short_pulses = 2;
};

// Velocity targets, one per cycle (mm/s). Throws std::invalid_argument on non-positive
// period/amplitude/durations or durations shorter than one period.
std::vector<double> make_excitation(const ExcitationParams& p);
// Largest distance from the start of an ideal (lag-free) axis following `v_cmd_mm_s`, mm.
double excitation_excursion_mm(const std::vector<double>& v_cmd_mm_s, double period_s);

struct IdentificationInput {
  double period_s = 0.001;
  double command_gain_per_s = 120.0;  // K_cmd: the loop's v_cmd = K_cmd * u
  std::vector<double> v_cmd_mm_s;     // target written in cycle k
  std::vector<double> position_mm;    // position read in cycle k (same length)
  int max_delay_cycles = 8;           // 0..16
  double min_tau_s = 1e-4;
  double max_tau_s = 2.0;
};

struct IdentificationResult {
  bool ok = false;
  std::string message;            // why not ok, or a one-line summary
  double gain_per_s = 0.0;        // K
  double velocity_gain = 0.0;     // K / K_cmd (1 = the drive follows its target exactly)
  double tau_s = 0.0;
  int delay_cycles = 0;
  double offset_mm = 0.0;         // x0: the start position the fit found
  double rms_residual_mm = 0.0;   // of the best fit
  // Residual RMS of the best fit at the other delays (index = delay; NaN where not tried): how
  // clearly the delay is decided. For the default excitation with quantisation only the next
  // best is 4.7-4.9x the best; with +-1 count of noise 1.8-1.9x (control/CHATTER.md).
  std::vector<double> residual_by_delay_mm;
  double delay_confidence = 0.0;  // next-best residual / best residual
  double excursion_mm = 0.0;      // largest |x - x0| in the record
};

// Throws nothing: problems (length mismatch, too short, no excitation, non-finite samples, a
// time constant at the search bound) are reported with ok = false and a message.
IdentificationResult identify_axis(const IdentificationInput& in);

}  // namespace contour::control
