// The simulated carousel's Geneva drive (control/plc_sim_plant.hpp): the ring stands at each
// pocket for kDwell of the crank's turn, so a PLC that sees its inputs late (a Modbus coupler
// under load) still stops the motor with the pocket in position. Before the dwell was modelled,
// the ring passed the +-0.04-pocket sensor window in 20 ms and a stop 30 ms late left it between
// pockets (seen in HIL: pocket 0 after T3 M6).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <deque>
#include <numbers>

#include "control/plc_sim_plant.hpp"

namespace contour::control::plc {
namespace {

constexpr double kDt_s = 0.001;
const std::array<double, 3> kAxes{0.0, 0.0, 0.0};

TEST(PlcSimPlant, TheCarouselDwellsAtEachPocketAndIndexesInKIndexS) {
  MachinePlant p;
  p.set(PlantPoint::kCarouselCw, 1);
  int in_pos_ms = 0, longest_in_pos_ms = 0, run_ms = 0;
  double last = p.carousel_position();
  double max_step = 0.0;
  for (int i = 0; i < 1000; ++i) {  // 1 s: four pockets
    p.step(kDt_s, kAxes);
    double d = p.carousel_position() - last;
    if (d < -4.0) d += MachinePlant::kPockets;  // the wrap from 8 to 0
    EXPECT_GE(d, 0.0) << "the ring ran backwards at " << i << " ms";
    max_step = std::fmax(max_step, d);
    last = p.carousel_position();
    if (p.get(PlantPoint::kCarouselInPosition) != 0) {
      ++in_pos_ms;
      ++run_ms;
      longest_in_pos_ms = std::max(longest_in_pos_ms, run_ms);
    } else {
      run_ms = 0;
    }
  }
  EXPECT_EQ(p.carousel_moves(), 4U);  // 1 s at kIndex_s = 0.25 s per pocket
  // A whole dwell, kDwell x kIndex_s = 156 ms, plus the +-0.04-pocket sensor window at both ends
  // of the slow-starting index (acos(0.92) / pi x 0.375 x 250 ms = 12 ms each): 180 ms.
  EXPECT_GE(longest_in_pos_ms, 178);
  EXPECT_LE(longest_in_pos_ms, 182);
  // Moving 1 - kDwell of the time, a half-cosine index: the peak speed is pi/2 x the mean.
  EXPECT_NEAR(max_step, kDt_s / MachinePlant::kIndex_s / (1.0 - MachinePlant::kDwell) * std::numbers::pi / 2.0, 1e-4);
}

// A PLC that sees the plant `late_ms` late: turn until the goal pocket is in position, then stop.
int stop_at_goal_with_late_inputs(int late_ms, int goal) {
  MachinePlant p;
  std::deque<std::pair<bool, int>> seen;  // (in position, pocket) as they reach the PLC
  for (int i = 0; i < 5000; ++i) {
    seen.emplace_back(p.get(PlantPoint::kCarouselInPosition) != 0,
                      static_cast<int>(p.get(PlantPoint::kCarouselPocket)));
    const auto [in_pos, pocket] = seen.front();
    if (static_cast<int>(seen.size()) > late_ms) seen.pop_front();
    const bool there = i > late_ms && in_pos && pocket == goal;
    p.set(PlantPoint::kCarouselCw, there ? 0 : 1);
    p.step(kDt_s, kAxes);
  }
  return p.get(PlantPoint::kCarouselInPosition) != 0 ? static_cast<int>(p.get(PlantPoint::kCarouselPocket)) : 0;
}

TEST(PlcSimPlant, AStopThatArrivesLateStillLeavesThePocketInPosition) {
  for (const int late_ms : {0, 5, 30, 100, 140})
    EXPECT_EQ(stop_at_goal_with_late_inputs(late_ms, 3), 3) << "inputs " << late_ms << " ms late";
  // Later than the dwell the ring is already indexing on: between pockets, as a real one would be.
  EXPECT_NE(stop_at_goal_with_late_inputs(200, 3), 3);
}

}  // namespace
}  // namespace contour::control::plc
