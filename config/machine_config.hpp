#pragma once
// `machine:` section — the axes, their scaling, limits and the simulated drive behind each.
#include <string>
#include <vector>

#include "config/yaml_reader.hpp"
#include "control/feed_drive.hpp"

namespace contour::config {

// A drive model measured by `contourctl identify` and stored by `contourctl gains save`
// (machine.axes[].identified): kept beside the model the controller uses (`sim:`) so that a
// later hand edit of sim.delay_cycles that contradicts the measurement is a start-up warning.
struct IdentifiedDrive {
  bool present = false;
  double gain_per_s = 0.0;
  double tau_s = 0.0;
  int delay_cycles = 0;
  std::string date;  // free text, as written by gains save (ISO 8601 UTC)
};

struct AxisConfig {
  std::string name;             // "X", "Y", "Z"
  int node_id = 0;              // CANopen node-id (1..127); 0 = not on a bus
  double counts_per_mm = 2000;  // encoder/drive scaling (BLU = 1/counts_per_mm)
  double min_mm = -1000.0;      // soft limits, machine coordinates
  double max_mm = 1000.0;
  double max_velocity_mm_min = 10000.0;
  double max_accel_mm_s2 = 2000.0;
  // Simulated drive (contour-sim, sim bus, contour-machine-sim): seed 000 Table 1 by default.
  control::FeedDriveParams drive{};
  IdentifiedDrive identified{};  // machine.axes[].identified (optional)
};

struct MachineConfig {
  std::vector<AxisConfig> axes;  // 1..3 linear axes, X Y Z order
  double period_s = 0.001;       // servo/interpolation period: copied from loop.period_us
};

// period_s comes from loop.period_us (one source of truth for the cycle time).
MachineConfig parse_machine(Section& s, double period_s);

// Start-up warnings (issue 16): one per axis whose `identified:` measurement contradicts the
// model the controller uses (`sim:`): a transport delay that differs (the Smith predictor then
// assumes the wrong one), a gain more than 5 % or a time constant more than 10 % off (the
// thresholds of `identify`'s verdict). Each names the axis. Empty when nothing was measured.
std::vector<std::string> identification_warnings(const MachineConfig& m);

}  // namespace contour::config
