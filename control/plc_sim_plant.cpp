#include "control/plc_sim_plant.hpp"

#include <cmath>
#include <numbers>

namespace contour::control::plc {

namespace {
constexpr std::array<PlantPointInfo, kPlantPoints> kPoints{{
    {PlantPoint::kDoorClosed, "door_closed", Type::kBool, true},
    {PlantPoint::kAirOk, "air_ok", Type::kBool, true},
    {PlantPoint::kLubePressureOk, "lube_pressure_ok", Type::kBool, true},
    {PlantPoint::kCarouselInPosition, "carousel_in_position", Type::kBool, true},
    {PlantPoint::kCarouselPocket, "carousel_pocket", Type::kInt, true},
    {PlantPoint::kDrawbarClamped, "drawbar_clamped", Type::kBool, true},
    {PlantPoint::kDrawbarUnclamped, "drawbar_unclamped", Type::kBool, true},
    {PlantPoint::kLimitXNeg, "limit_x_neg", Type::kBool, true},
    {PlantPoint::kLimitXPos, "limit_x_pos", Type::kBool, true},
    {PlantPoint::kLimitYNeg, "limit_y_neg", Type::kBool, true},
    {PlantPoint::kLimitYPos, "limit_y_pos", Type::kBool, true},
    {PlantPoint::kLimitZNeg, "limit_z_neg", Type::kBool, true},
    {PlantPoint::kLimitZPos, "limit_z_pos", Type::kBool, true},
    {PlantPoint::kCarouselCw, "carousel_cw", Type::kBool, false},
    {PlantPoint::kCarouselCcw, "carousel_ccw", Type::kBool, false},
    {PlantPoint::kDrawbarUnclamp, "drawbar_unclamp", Type::kBool, false},
    {PlantPoint::kLubePump, "lube_pump", Type::kBool, false},
    {PlantPoint::kDoorLock, "door_lock", Type::kBool, false},
    {PlantPoint::kWorkLight, "work_light", Type::kBool, false},
}};
}  // namespace

const PlantPointInfo& plant_point(PlantPoint p) noexcept {
  return kPoints[static_cast<std::size_t>(p)];
}

bool find_plant_point(std::string_view name, PlantPoint& out) noexcept {
  for (const auto& p : kPoints) {
    if (name == p.name) {
      out = p.point;
      return true;
    }
  }
  return false;
}

void MachinePlant::set_limits(const std::array<double, 3>& neg_mm,
                              const std::array<double, 3>& pos_mm) noexcept {
  neg_mm_ = neg_mm;
  pos_mm_ = pos_mm;
}

namespace {
double wrap_pockets(double p) noexcept {
  const double n = MachinePlant::kPockets;
  return std::fmod(std::fmod(p, n) + n, n);
}
// The ring of a Geneva drive at crank position `crank` (pocket turns): standing at pocket k for
// crank in [k - kDwell/2, k + kDwell/2], a half-cosine index from k to k + 1 in between.
double geneva_ring(double crank) noexcept {
  constexpr double half = MachinePlant::kDwell / 2.0;
  const double k = std::floor(crank - half);
  const double s = std::fmin(1.0, (crank - half - k) / (1.0 - MachinePlant::kDwell));
  return wrap_pockets(k + 0.5 * (1.0 - std::cos(std::numbers::pi * s)));
}
}  // namespace

void MachinePlant::set_carousel_position(double pockets) noexcept {
  crank_ = wrap_pockets(pockets);
  carousel_ = geneva_ring(crank_);
}

void MachinePlant::step(double dt_s, const std::array<double, 3>& axis_mm) noexcept {
  auto on = [&](PlantPoint p) { return get(p) != 0; };
  auto put = [&](PlantPoint p, bool v) { set(p, v ? 1 : 0); };
  const bool air = air_supply_ && !faults_.air_lost;

  // Door: the operator's request, unless the lock holds it closed.
  const bool locked = on(PlantPoint::kDoorLock);
  door_blocked_ = door_open_request_ && locked;
  put(PlantPoint::kDoorClosed, !door_open_request_ || locked);
  put(PlantPoint::kAirOk, air);

  // Lube pump.
  if (on(PlantPoint::kLubePump)) {
    lube_on_s_ += dt_s;
    lube_off_s_ = 0.0;
    if (lube_on_s_ >= kLubeBuild_s) lube_ok_ = true;
  } else {
    lube_on_s_ = 0.0;
    lube_off_s_ += dt_s;
    if (lube_off_s_ >= kLubeHold_s) lube_ok_ = false;
  }
  put(PlantPoint::kLubePressureOk, lube_ok_);

  // Carousel: both directions at once cancel (a contactor interlock would).
  const int dir = (on(PlantPoint::kCarouselCw) ? 1 : 0) - (on(PlantPoint::kCarouselCcw) ? 1 : 0);
  if (dir != 0 && !faults_.carousel_jam) {
    crank_ = wrap_pockets(crank_ + dir * dt_s / kIndex_s);
    carousel_ = geneva_ring(crank_);
  }
  const double nearest = std::round(carousel_);
  const bool in_pos = std::fabs(carousel_ - nearest) <= kPocketWindow && !faults_.pocket_sensor_dead;
  const int pocket = static_cast<int>(nearest) % kPockets + 1;
  if (in_pos && pocket != last_pocket_) {
    ++pocket_passes_;
    last_pocket_ = pocket;
  }
  put(PlantPoint::kCarouselInPosition, in_pos);
  set(PlantPoint::kCarouselPocket, in_pos ? pocket : 0);

  // Drawbar: pneumatic, needs air to open; springs close it.
  const bool open_cmd = on(PlantPoint::kDrawbarUnclamp) && air && !faults_.drawbar_stuck;
  const double rate = dt_s / kDrawbar_s;
  drawbar_ = open_cmd ? std::fmin(1.0, drawbar_ + rate) : std::fmax(0.0, drawbar_ - rate);
  put(PlantPoint::kDrawbarClamped, drawbar_ <= 0.0);
  put(PlantPoint::kDrawbarUnclamped, drawbar_ >= 1.0);

  // Overtravel switches.
  const PlantPoint neg[3] = {PlantPoint::kLimitXNeg, PlantPoint::kLimitYNeg, PlantPoint::kLimitZNeg};
  const PlantPoint pos[3] = {PlantPoint::kLimitXPos, PlantPoint::kLimitYPos, PlantPoint::kLimitZPos};
  for (std::size_t a = 0; a < 3; ++a) {
    put(neg[a], axis_mm[a] <= neg_mm_[a]);
    put(pos[a], axis_mm[a] >= pos_mm_[a]);
  }
}

}  // namespace contour::control::plc
