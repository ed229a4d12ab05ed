#pragma once
// The simulated machine around the soft PLC (issue 20): what the PLC's inputs see and its outputs
// drive on the example machine of config/sim.yaml (its plc: section). One model, two hosts (style.md:
// fakes are part of the product): daemon/plc_sim.hpp steps it inside the PLC scan on the sim bus
// (lockstep, deterministic), and contour-machine-sim serves it as a Modbus TCP I/O coupler
// (tools/contour-machine-sim/plant_io.hpp) for HIL.
//
//   door        operator opens/closes it; a PLC door lock (output) keeps it closed
//   air         pressure switch: OK unless the operator or a fault removes the supply
//   lube        pump output builds pressure: lube_pressure_ok after kLubeBuild_s of pumping,
//               lost kLubeHold_s after the pump stops
//   carousel    8 pockets on a ring, turned by carousel_cw / carousel_ccw through a Geneva drive:
//               the motor's crank turns once per pocket in kIndex_s, and the ring moves during
//               1 - kDwell of that turn (a smooth index) and stands still at the pocket for the
//               rest (kDwell: 0.625 for an 8-slot Geneva wheel, 135 of 360 degrees moving).
//               carousel_in_position inside +-kPocketWindow of a pocket, carousel_pocket = the
//               pocket number 1..8 there (0 between pockets). The dwell is what lets a PLC stop
//               the motor at a pocket through slow remote I/O (a Modbus coupler polled every few
//               ms, late under load): it has kDwell x kIndex_s (156 ms) to react, not the few ms
//               the ring needs to pass the sensor window.
//   drawbar     drawbar_unclamp (valve) opens the drawbar in kDrawbar_s when air is present;
//               drawbar_clamped / drawbar_unclamped end switches, both off while travelling
//   limits      per axis a negative and a positive overtravel switch, TRUE when actuated (the
//               axis beyond the switch position), positions given at construction
// Faults (set from outside, thread-safe flags are the host's business): air loss, a jammed
// carousel (motor on, no motion), a drawbar stuck clamped, a dead pocket sensor.
//
// Pure computation (no I/O, no allocation); step() is noexcept, O(1). Units in the names.
#include <array>
#include <cstdint>
#include <string_view>

#include "control/plc_types.hpp"

namespace contour::control::plc {

// The plant's points, as a PLC signal binds them (`sim: door_closed`).
enum class PlantPoint : std::uint8_t {
  // inputs of the PLC (the plant drives them)
  kDoorClosed, kAirOk, kLubePressureOk, kCarouselInPosition, kCarouselPocket, kDrawbarClamped,
  kDrawbarUnclamped, kLimitXNeg, kLimitXPos, kLimitYNeg, kLimitYPos, kLimitZNeg, kLimitZPos,
  // outputs of the PLC (the plant follows them)
  kCarouselCw, kCarouselCcw, kDrawbarUnclamp, kLubePump, kDoorLock, kWorkLight,
};
inline constexpr int kPlantPoints = 19;
inline constexpr int kPlantFirstOutput = static_cast<int>(PlantPoint::kCarouselCw);

struct PlantPointInfo {
  PlantPoint point;
  const char* name;  // lower case, as in YAML
  Type type;
  bool plc_input;    // true: the PLC reads it; false: the PLC drives it
};
[[nodiscard]] const PlantPointInfo& plant_point(PlantPoint p) noexcept;
bool find_plant_point(std::string_view name, PlantPoint& out) noexcept;

struct PlantFaults {
  bool air_lost = false;
  bool carousel_jam = false;
  bool drawbar_stuck = false;
  bool pocket_sensor_dead = false;
};

class MachinePlant {
 public:
  static constexpr int kPockets = 8;
  static constexpr double kIndex_s = 0.25;        // carousel time per pocket
  static constexpr double kPocketWindow = 0.04;   // in-position window, in pockets
  static constexpr double kDwell = 0.625;         // fraction of a crank turn standing at a pocket
  static constexpr double kDrawbar_s = 0.15;
  static constexpr double kLubeBuild_s = 1.5;
  static constexpr double kLubeHold_s = 5.0;

  MachinePlant() = default;
  // Overtravel switch positions per axis (mm); +-1e300 (the default) means no switch.
  void set_limits(const std::array<double, 3>& neg_mm, const std::array<double, 3>& pos_mm) noexcept;

  // Operator / fault side.
  void set_door_open(bool open) noexcept { door_open_request_ = open; }
  void set_air_supply(bool on) noexcept { air_supply_ = on; }
  void set_faults(const PlantFaults& f) noexcept { faults_ = f; }
  void set_carousel_position(double pockets) noexcept;  // 0 = pocket 1 under the spindle (the
                                                         // crank too: mid-dwell at a pocket)

  // One step of dt_s with the PLC's outputs as they are now and the axes' positions.
  void step(double dt_s, const std::array<double, 3>& axis_mm) noexcept;

  // PLC side: outputs are set with set(), inputs read with get() (BOOL 0/1, INT as integers).
  void set(PlantPoint p, std::int64_t v) noexcept { value_[static_cast<std::size_t>(p)] = v; }
  [[nodiscard]] std::int64_t get(PlantPoint p) const noexcept {
    return value_[static_cast<std::size_t>(p)];
  }

  [[nodiscard]] double carousel_position() const noexcept { return carousel_; }
  [[nodiscard]] bool door_blocked() const noexcept { return door_blocked_; }  // lock held it
  [[nodiscard]] std::uint64_t carousel_moves() const noexcept { return pocket_passes_; }

 private:
  std::array<std::int64_t, kPlantPoints> value_{};
  PlantFaults faults_{};
  bool door_open_request_ = false;
  bool door_blocked_ = false;
  bool air_supply_ = true;
  double crank_ = 0.0;          // the Geneva drive's crank, in pocket turns, [0, kPockets)
  double carousel_ = 0.0;       // the ring, pockets, [0, kPockets)
  double drawbar_ = 0.0;        // 0 clamped .. 1 unclamped
  double lube_on_s_ = 0.0;      // pumping time towards kLubeBuild_s
  double lube_off_s_ = 1e9;     // time since the pump stopped
  bool lube_ok_ = false;
  int last_pocket_ = 1;
  std::uint64_t pocket_passes_ = 0;
  std::array<double, 3> neg_mm_{-1e300, -1e300, -1e300};
  std::array<double, 3> pos_mm_{1e300, 1e300, 1e300};
};

}  // namespace contour::control::plc
