#pragma once
// `machine:` section — the axes, their scaling, limits and the simulated drive behind each.
#include <string>
#include <vector>

#include "config/yaml_reader.hpp"
#include "control/feed_drive.hpp"

namespace contour::config {

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
};

struct MachineConfig {
  std::vector<AxisConfig> axes;  // 1..3 linear axes, X Y Z order
  double period_s = 0.001;       // servo/interpolation period: copied from loop.period_us
};

// period_s comes from loop.period_us (one source of truth for the cycle time).
MachineConfig parse_machine(Section& s, double period_s);

}  // namespace contour::config
