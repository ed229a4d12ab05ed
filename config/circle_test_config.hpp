#pragma once
// Standalone config file for the circle test on the simulated machine (contour-sim circle).
// Not a section of the main config (whose loader rejects unknown top-level keys): this file holds
// the simulated X/Y axes with their position-loop gains and the test circle.
//
// Schema (config/circle_test.yaml is the example):
//   period_us: 1000                      # servo period
//   axes:                                # X and Y, both required
//     X: {gain_per_s: 30, position_gain: 1.0, tau_ms: 10, blu_um: 0.1, delay_cycles: 0}
//     Y: {gain_per_s: 27, position_gain: 1.0, tau_ms: 12, blu_um: 0.1, delay_cycles: 0}
//   test:
//     radius_mm: 100, feed_mm_min: 3000, direction: cw|ccw|both, center_mm: [0, 0], z_mm: 0,
//     noise_um: 0.1, seed: 1, revolutions: 1,
//     geometry: geometry/example.yaml    # relative to this file; "" = no geometric errors
// gain_per_s, tau_ms, blu_um, delay_cycles mean what machine.axes[].sim means in the main config
// (control::FeedDrive). The axis loop is u = position_gain * (command - encoder), so the loop gain
// is k_p = gain_per_s * position_gain (1/s); the matched gain is applied to position_gain.
#include <array>
#include <string>

#include "config/yaml_reader.hpp"
#include "control/circle_test.hpp"

namespace contour::config {

struct CircleTestConfig {
  std::array<control::circle::SimAxis, 2> axes{};  // X, Y
  double radius_mm = 100.0;
  double feed_mm_min = 3000.0;
  std::string direction = "cw";  // cw | ccw | both
  std::array<double, 2> center_mm{0.0, 0.0};
  double z_mm = 0.0;
  double noise_um = 0.1;
  long seed = 1;
  int revolutions = 1;
  std::string geometry_file;  // resolved against the config file's directory; empty = none
};

CircleTestConfig load_circle_test_config(const std::string& path);
CircleTestConfig load_circle_test_config_string(const std::string& text,
                                                const std::string& name = "<string>");

}  // namespace contour::config
