#pragma once
// Test support: plan a block list with BlendPlanner and load the whole plan into an Interpolator,
// with the programmed path registered on a PathMeter (the independent judge) and the start point
// as its first sample. The caller steps the interpolator and feeds the meter.
#include <Eigen/Core>
#include <vector>

#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/path_meter.hpp"

namespace contour::test {

inline void plan_into_interpolator(const control::PlannerParams& pp, const std::vector<control::Block>& blocks,
                                   const Eigen::Vector3d& start, control::PathMeter& meter,
                                   control::Interpolator& ip) {
  control::BlendPlanner pl(pp, start);
  for (const auto& b : blocks) {
    if (b.kind == control::BlockKind::kMotion) meter.add_segment(b.seg, b.line);
    pl.push(b);
  }
  std::vector<control::PlannedSegment> segs;
  control::PlannedSegment seg;
  while (pl.pop(seg)) segs.push_back(seg);
  control::InterpolatorParams p;
  p.fir_taps = pp.fir_taps;
  p.capacity = segs.size() + 8;  // the whole plan at once
  ip.configure(p, start);
  for (const auto& x : segs) ip.push(x);
  meter.add_sample(start);
}

}  // namespace contour::test
