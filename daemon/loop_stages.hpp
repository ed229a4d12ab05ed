#pragma once
// The records that flow between the stages of one servo cycle (daemon/servo_loop.hpp):
//
//   read -> [commands] -> logic -> reference -> control -> channels -> write -> supervise -> publish
//
// `read` fills one Feedback snapshot per cycle; every later stage reads that snapshot, never the
// bus. Exactly one reference source (daemon/reference_sources.hpp) turns it into this cycle's
// RefPoint. Plain data: no allocation, trivially copyable where Eigen allows.
// Units: mm, mm/s, N, s. Positions in machine coordinates.
#include <array>
#include <cstdint>

#include <Eigen/Core>

#include "daemon/axis_bus.hpp"
#include "drivers/modbus/dynamometer_reader.hpp"

namespace contour::daemon {

// One consistent picture of the machine, taken by the `read` stage.
struct Feedback {
  BusFeedback bus{};
  // Last measured position per axis (held through a missed TPDO; `bus.axis[i].fresh` says whether
  // it is this cycle's).
  Eigen::Vector3d act_mm = Eigen::Vector3d::Zero();
  std::array<int, kMaxAxes> missed_streak{};  // consecutive cycles without a TPDO, per axis
  // Consecutive cycles without the drive's 0x60FD digital inputs (TPDO2 on CANopen), per axis
  // that has them (AxisFeedback::digital_inputs_present); 0 for an axis without.
  std::array<int, kMaxAxes> inputs_missed_streak{};
  // Force channel input (RtIo with a dynamometer; zero / kNoData without).
  drivers::modbus::ForceReading force{};
  std::array<double, 3> force_xyz_N{};  // filtered channels (0 when not mapped)
  double force_N = 0.0;                 // resultant of the mapped channels
  double force_age_s = 0.0;
  bool estop_input = false;             // the E-stop input latch (RtIo)
};

// The reference source that produced a RefPoint.
enum class SourceKind : std::uint8_t {
  kProgram,  // interpolator + planner segment queue (RUNNING/HOLD with a program)
  kJog,      // single-axis jog (READY)
  kHold,     // standstill: the reference stays where it is (READY), or follows the measured
             // position while the drives do not servo (DISABLED, ENABLING, ESTOP)
  kStop,     // FAULT: the controlled stop ramp
  kHoming,   // `home`: switch search, latch and the move to the home position (READY)
};
const char* to_string(SourceKind k) noexcept;

// This cycle's reference. `track`: the controllers servo the axes to position_mm. Otherwise the
// velocity in velocity_mm_s is commanded directly (the controlled stop) with the drives enabled
// while `drives_on`.
struct RefPoint {
  SourceKind source = SourceKind::kHold;
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();
  bool track = false;
  std::array<double, kMaxAxes> velocity_mm_s{};
  bool drives_on = false;
  bool quick_stop = false;  // the drives' own CiA 402 quick stop (stop source: standstill timeout)
};

}  // namespace contour::daemon
