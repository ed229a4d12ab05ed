#include "control/blend_planner.hpp"

namespace contour::control {

BlendPlanner::BlendPlanner(const PlannerParams& p, const Eigen::Vector3d& start_mm)
    : overlap_(p, start_mm) {
  if (p.method == BlendMethod::kLookahead) lookahead_ = std::make_unique<LookaheadPlanner>(p, start_mm);
}

void BlendPlanner::push(const Block& b) {
  if (lookahead_) {
    lookahead_->push(b);
  } else {
    overlap_.push(b);
  }
}

bool BlendPlanner::pop(PlannedSegment& out) {
  return lookahead_ ? lookahead_->pop(out) : overlap_.pop(out);
}

std::size_t BlendPlanner::ready() const {
  return lookahead_ ? lookahead_->ready() : overlap_.ready();
}

bool BlendPlanner::ended() const { return lookahead_ ? lookahead_->ended() : overlap_.ended(); }

void BlendPlanner::on_corner(std::function<void(const CornerReport&)> cb) {
  if (lookahead_) {
    lookahead_->on_corner(std::move(cb));
  } else {
    overlap_.on_corner(std::move(cb));
  }
}

const std::vector<std::string>& BlendPlanner::messages() const {
  return lookahead_ ? lookahead_->messages() : overlap_.messages();
}

const PlannerStats& BlendPlanner::stats() const {
  return lookahead_ ? lookahead_->stats() : overlap_.stats();
}

BlendPlanner::TwoBlock BlendPlanner::paper_two_block(const Eigen::Vector3d& a0,
                                                     const Eigen::Vector3d& vertex,
                                                     const Eigen::Vector3d& b1, std::int64_t na,
                                                     std::int64_t nb, double eps,
                                                     bool incremental) const {
  const auto r = overlap_.paper_two_block(a0, vertex, b1, na, nb, eps, incremental);
  return {r.overlap_cycles, r.error_mm};
}

}  // namespace contour::control
