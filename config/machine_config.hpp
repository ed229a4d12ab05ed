#pragma once
// `machine:` section — the axes, their scaling, limits and the simulated drive behind each.
#include <cstdint>
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

// machine.axes[].home (issue 18): how the axis finds its machine zero. LinuxCNC's semantics:
// the search runs at search_vel towards the switch (the sign is the direction); the latch moves
// at latch_vel: with the opposite sign it backs off and latches where the switch releases, with
// the same sign it backs off past the release and latches where the switch closes again on the
// slow approach. The latch point becomes home_offset_mm in machine coordinates; the axis then
// moves to home_position_mm. Axes with the same `sequence` home together, lower numbers first.
struct HomeConfig {
  enum class Method : std::uint8_t {
    kNone,      // never homed: only with machine.allow_unhomed (the power-up position counts)
    kSwitch,    // the drive's home-switch input (CiA 402 0x60FD bit 2)
    kAbsolute,  // absolute encoder: machine position = encoder position + home_offset_mm
    kDrive,     // the drive homes itself (CiA 402 homing mode 6, method 0x6098 = drive_method)
  };
  bool present = false;  // the axis has a home: section
  Method method = Method::kNone;
  double search_vel_mm_s = 0.0;  // signed
  double latch_vel_mm_s = 0.0;   // signed
  double home_offset_mm = 0.0;
  double home_position_mm = 0.0;
  int sequence = 0;
  double search_distance_mm = 0.0;  // the switch must close within this travel (default 1.2 x range)
  double unhomed_jog_mm_s = 10.0;   // jog speed limit while not homed (no soft limits then)
  // LinuxCNC's HOME_USE_INDEX (method switch): after the switch edge the axis goes on at the
  // latch speed to the encoder's next index pulse, whose position becomes home_offset_mm.
  bool use_index = false;
  // method drive (CiA 402 homing mode 6): the drive's homing method (0x6098; the codes
  // kDriveMethods lists), its speeds (0x6099:01 search for the switch = |search_vel_mm_s|,
  // 0x6099:02 search for zero = |latch_vel_mm_s|; the method fixes the direction, so the signs
  // do not matter) and acceleration (0x609A), in mm here, counts at the bus' edge. The point the
  // drive homed to (where it reports position 0 afterwards) becomes home_offset_mm in machine
  // coordinates, as the latch point of method switch; then the axis moves to home_position_mm.
  // No "attained" within drive_timeout_s fails the homing.
  int drive_method = 0;
  double drive_accel_mm_s2 = 0.0;
  double drive_timeout_s = 60.0;
};

// The CiA 402 homing methods (0x6098) `home.method: drive` accepts, the ones the simulated drives
// (sim bus, contour-machine-sim) implement: 17/18 negative/positive limit switch (0x60FD bit 0/1,
// home where it releases), 19/20 positive home switch and 21/22 negative home switch (bit 2;
// 19/21 home where the switch opens leaving it, 20/22 where it closes entering it), 33/34 the next
// encoder index below/above, 35 and 37 the current position.
inline constexpr int kDriveMethods[] = {17, 18, 19, 20, 21, 22, 33, 34, 35, 37};
[[nodiscard]] bool drive_method_supported(int method) noexcept;

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
  HomeConfig home{};
  // Simulated machine only: the true position at power-up (the incremental encoder reads 0
  // there), so that homing has something to find.
  double sim_power_up_mm = 0.0;
  // Simulated machine only: the motor encoder's index, one pulse per sim_index_pitch_mm of true
  // travel at sim_index_phase_mm + k * pitch (machine.axes[].sim.index_pitch_mm, index_phase_mm;
  // 0 = no index).
  double sim_index_pitch_mm = 0.0;
  double sim_index_phase_mm = 0.0;
};

struct MachineConfig {
  std::vector<AxisConfig> axes;  // 1..3 linear axes, X Y Z order
  double period_s = 0.001;       // servo/interpolation period: copied from loop.period_us
  // Programs and MDI may run with unhomed axes (LinuxCNC's NO_FORCE_HOMING): the power-up
  // position then counts as machine position, soft limits included. Default: true only when no
  // axis has a home: section (configs from before homing keep working); with any home: section
  // it must be given explicitly, and an axis without homing (method none) needs it.
  bool allow_unhomed = false;
  [[nodiscard]] bool homing_required() const noexcept { return !allow_unhomed; }
};

// period_s comes from loop.period_us (one source of truth for the cycle time).
MachineConfig parse_machine(Section& s, double period_s);

// Start-up warnings (issue 16): one per axis whose `identified:` measurement contradicts the
// model the controller uses (`sim:`): a transport delay that differs (the Smith predictor then
// assumes the wrong one), a gain more than 5 % or a time constant more than 10 % off (the
// thresholds of `identify`'s verdict). Each names the axis. Empty when nothing was measured.
std::vector<std::string> identification_warnings(const MachineConfig& m);

}  // namespace contour::config
