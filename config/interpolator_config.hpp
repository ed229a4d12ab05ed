#pragma once
// `interpolator:` section (issue 3, seed 004). Keys (all optional):
//   fir_ms: 100            acc/dec time t_A of the moving-average FIR (filter has t_A/T + 1 taps)
//   fir2_ms: 0             second cascaded FIR stage (jerk-limited S-curve); 0 = off
//   blend: limited         default corner mode before any G61/G64 in the program: g61|g64|limited
//   tolerance_um: 50       default G64 P tolerance (and the arc chord budget base)
//   arc_chord_fraction: 0.25  arcs become chords with sagitta <= fraction * tolerance
//   feed_override_max_percent: 150
//   rapid_override_max_percent: 100   rapid override ceiling (G0 runs at most at its planned speed)
//   rounding: ceil         block sample counts: ceil (never faster than F) | floor (paper)
//   method: true           blend search: true (verified true-path tolerance) | paper | exhaustive |
//                          lookahead (velocity look-ahead before the FIR, issue 23; not the default yet)
//   optional_stop: false   M1 holds when true
//   queue_capacity: 4096   RT segment ring size
// The period is machine.period_s.
#include <string>

#include "config/yaml_reader.hpp"
#include "control/blend_planner.hpp"

namespace contour::config {

struct InterpolatorConfig {
  double fir_ms = 100.0;
  double fir2_ms = 0.0;
  control::BlendMode blend = control::BlendMode::kLimited;
  double tolerance_um = 50.0;
  double arc_chord_fraction = 0.25;
  double feed_override_max_percent = 150.0;
  double rapid_override_max_percent = 100.0;  // 1..100 (LinuxCNC: rapids never above 100 %)
  bool floor_rounding = false;
  control::BlendMethod method = control::BlendMethod::kTrue;
  bool optional_stop = false;
  long queue_capacity = 4096;
};

InterpolatorConfig parse_interpolator(Section& s);

// Taps for a filter time at a period: round(ms / period) + 1 (paper: t_A/T + 1 = 101 at 100 ms,
// 1 ms). fir2: 0 when off.
int fir_taps(double ms, double period_s);

control::BlendMode parse_blend_mode(const std::string& s);  // g61|g64|limited, throws otherwise

}  // namespace contour::config
