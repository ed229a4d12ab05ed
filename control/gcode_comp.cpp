// Cutter radius compensation G41/G42 (G41.1/G42.1) in the XY and XZ planes, LinuxCNC 2.9
// semantics: the entry move (first move after G41/G42) ends perpendicular to the programmed
// direction at the tool radius; later moves are offset by the radius, with an arc around convex
// corners and the previous move shortened at concave ones. The previous move is held back in a
// queue until the next move decides where it ends; a corner the tool cannot reach without
// cutting into the programmed path ("gouging") is an error on the line that causes it. Lines and
// arcs are handled in the plane's coordinates (XZ mapped onto XY as LinuxCNC does).
#include <algorithm>
#include <cmath>
#include <numbers>

#include "control/gcode_interp.hpp"

namespace contour::control::gcode_detail {

namespace {
// LinuxCNC computes these angles with long double pi (M_PIl, M_PI_2l) and stores the results
// in doubles; the same arithmetic here keeps nearly straight compensated arcs identical to the
// last bit (their centres are ill-conditioned).
constexpr long double kPi = 3.141592653589793238462643383279502884L;
constexpr long double kHalfPi = kPi / 2.0L;
constexpr double kConcave = 0.05;  // LinuxCNC TOLERANCE_CONCAVE_CORNER, rad
constexpr double kEqual = 0.0001;  // LinuxCNC TOLERANCE_EQUAL

bool tool_inside_arc(CompSide side, int turn) {
  return (side == CompSide::kLeft && turn > 0) || (side == CompSide::kRight && turn < 0);
}
}  // namespace

void Interpreter::comp_get_current(double& x, double& y, double& z) const {
  if (plane_ == 3) {
    x = cur_[2];
    y = cur_[0];
    z = cur_[1];
  } else {
    x = cur_[0];
    y = cur_[1];
    z = cur_[2];
  }
}

void Interpreter::comp_set_current(double x, double y, double z) {
  if (plane_ == 3) {
    cur_[0] = y;
    cur_[1] = z;
    cur_[2] = x;
  } else {
    cur_[0] = x;
    cur_[1] = y;
    cur_[2] = z;
  }
}

void Interpreter::comp_get_programmed(double& x, double& y, double& z) const {
  if (plane_ == 3) {
    x = prog_[2];
    y = prog_[0];
    z = prog_[1];
  } else {
    x = prog_[0];
    y = prog_[1];
    z = prog_[2];
  }
}

void Interpreter::comp_set_programmed(double x, double y, double z) {
  if (plane_ == 3) {
    prog_[0] = y;
    prog_[1] = z;
    prog_[2] = x;
  } else {
    prog_[0] = x;
    prog_[1] = y;
    prog_[2] = z;
  }
}

double Interpreter::find_turn(double x1, double y1, double cx, double cy, int turn, double x2, double y2) const {
  if (turn == 0) return 0.0;
  double alpha = std::atan2(y1 - cy, x1 - cx);
  double beta = std::atan2(y2 - cy, x2 - cx);
  if (turn > 0) {
    if (beta <= alpha) beta = static_cast<double>(beta + 2 * kPi);
    return static_cast<double>((beta - alpha) + (turn - 1) * (2 * kPi));
  }
  if (alpha <= beta) alpha = static_cast<double>(alpha + 2 * kPi);
  return static_cast<double>((beta - alpha) + (turn + 1) * (2 * kPi));
}

void Interpreter::enqueue_straight(bool feed, double dx, double dy, double dz, double x, double y, double z) {
  Queued q;
  q.type = feed ? Queued::Type::kFeed : Queued::Type::kTraverse;
  q.line = sequence_;
  q.source = cur_source_;
  if (plane_ == 3) {
    q.dz = dx;
    q.dx = dy;
    q.dy = dz;
    q.z = x;
    q.x = y;
    q.y = z;
  } else {
    q.dx = dx;
    q.dy = dy;
    q.dz = dz;
    q.x = x;
    q.y = y;
    q.z = z;
  }
  qc_.push_back(q);
}

void Interpreter::enqueue_arc(double original_turns, double e1, double e2, double c1, double c2, int turn,
                              double e3) {
  Queued q;
  q.type = Queued::Type::kArc;
  q.line = sequence_;
  q.source = cur_source_;
  q.original_turns = original_turns;
  q.end1 = e1;
  q.end2 = e2;
  q.center1 = c1;
  q.center2 = c2;
  q.turn = turn;
  q.end3 = e3;
  qc_.push_back(q);
}

void Interpreter::set_endpoint(double x, double y) {
  endpoint_[0] = x;
  endpoint_[1] = y;
  endpoint_valid_ = true;
}

void Interpreter::qc_scale(double k) {
  for (auto& q : qc_) {
    // LinuxCNC scales the saved endpoint once per queued call; kept for identical gouge checks.
    endpoint_[0] *= k;
    endpoint_[1] *= k;
    if (q.type == Queued::Type::kArc) {
      q.end1 *= k;
      q.end2 *= k;
      q.end3 *= k;
      q.center1 *= k;
      q.center2 *= k;
    } else if (q.type == Queued::Type::kFeed || q.type == Queued::Type::kTraverse) {
      q.x *= k;
      q.y *= k;
      q.z *= k;
    }
  }
}

void Interpreter::move_endpoint_and_flush(double x, double y) {
  if (qc_.empty()) return;
  for (auto& q : qc_) {
    if (q.type == Queued::Type::kArc) {
      const double r1 = std::hypot(q.end1 - q.center1, q.end2 - q.center2);
      const double l1 = q.original_turns;
      const double r2 = std::hypot(x - q.center1, y - q.center2);
      const double l2 = find_turn(endpoint_[0], endpoint_[1], q.center1, q.center2, q.turn, x, y);
      if (std::abs(r1 - r2) > 0.01)
        fail(1, "cutter compensation produced an arc with mismatched radii (internal error)");
      if (l1 != 0.0 && endpoint_valid_ && std::abs(l2) > std::abs(l1) + (units_ == Units::kMm ? 0.0254 : 0.001))
        fail(1, "cutter compensation: arc move in a concave corner cannot be reached by the tool without gouging");
      q.end1 = x;
      q.end2 = y;
    } else if (q.type == Queued::Type::kFeed || q.type == Queued::Type::kTraverse) {
      const double x1 = plane_ == 3 ? q.dz : q.dx;
      const double y1 = plane_ == 3 ? q.dx : q.dy;
      const double x2 = x - endpoint_[0];
      const double y2 = y - endpoint_[1];
      const double dot = x1 * x2 + y1 * y2;
      if (endpoint_valid_ && dot < 0)
        fail(1, std::string("cutter compensation: straight ") + (q.type == Queued::Type::kFeed ? "feed" : "traverse") +
                    " in a concave corner cannot be reached by the tool without gouging");
      if (plane_ == 3) {
        q.z = x;
        q.x = y;
      } else {
        q.x = x;
        q.y = y;
      }
    }
  }
  dequeue_canons();
  set_endpoint(x, y);
}

void Interpreter::dequeue_canons() {
  endpoint_valid_ = false;
  if (qc_.empty()) return;
  // Lathe tool orientations move the controlled point off the radius centre (G18, L1..L8).
  const auto lx = [&](double x) {
    const int o = comp_orientation_;
    if (plane_ != 3) return x;
    if (o == 2 || o == 6 || o == 1) x -= comp_radius_;
    if (o == 3 || o == 8 || o == 4) x += comp_radius_;
    return x;
  };
  const auto lz = [&](double z) {
    const int o = comp_orientation_;
    if (plane_ != 3) return z;
    if (o == 2 || o == 7 || o == 3) z -= comp_radius_;
    if (o == 1 || o == 5 || o == 4) z += comp_radius_;
    return z;
  };
  std::vector<Queued> q;
  q.swap(qc_);
  for (const auto& c : q) {
    emit_line_ = c.line;
    emit_source_ = c.source;
    switch (c.type) {
      case Queued::Type::kArc:
        canon_arc(c.line, lz(c.end1), lx(c.end2), lz(c.center1), lx(c.center2), c.turn, c.end3);
        break;
      case Queued::Type::kFeed:
      case Queued::Type::kTraverse:
        canon_straight(c.type == Queued::Type::kFeed, c.line, lx(c.x), c.y, lz(c.z));
        break;
      case Queued::Type::kFeedRate: canon_set_feed_rate(c.value); break;
      case Queued::Type::kDwell: canon_dwell(c.value); break;
      case Queued::Type::kSpindle: canon_spindle(static_cast<SpindleDir>(c.ivalue)); break;
      case Queued::Type::kSpeed: canon_speed(c.value); break;
      case Queued::Type::kMist: canon_mist(c.ivalue != 0); break;
      case Queued::Type::kFlood: canon_flood(c.ivalue != 0); break;
      case Queued::Type::kUserM: canon_user_m(c.ivalue, c.value, c.value2); break;
      case Queued::Type::kMessage: break;
    }
  }
  emit_line_ = -1;
  emit_source_ = -1;
}

void Interpreter::convert_straight_comp1(int move, double px, double py, double pz) {
  const double radius = comp_radius_;
  const CompSide side = comp_side_;
  double cx = 0, cy = 0, cz = 0;
  comp_get_current(cx, cy, cz);
  const double distance = std::hypot(px - cx, py - cy);
  if (distance <= radius)
    fail(blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1,
         "cutter compensation entry move is not longer than the tool radius");
  const double alpha = static_cast<double>(std::atan2(py - cy, px - cx) + (side == CompSide::kLeft ? kPi / 2.0L : -kPi / 2.0L));
  const double end_x = px + radius * std::cos(alpha);
  const double end_y = py + radius * std::sin(alpha);
  set_endpoint(cx, cy);
  enqueue_straight(move == g::k1, std::cos(alpha), std::sin(alpha), 0, end_x, end_y, pz);
  comp_firstmove_ = false;
  comp_set_current(end_x, end_y, pz);
  comp_set_programmed(px, py, pz);
}

void Interpreter::convert_straight_comp2(int move, double px, double py, double pz) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  double cx = 0, cy = 0, cz = 0;
  comp_get_current(cx, cy, cz);
  double end_x = cx, end_y = cy;
  double opx = 0, opy = 0, opz = 0;
  comp_get_programmed(opx, opy, opz);
  const bool feed = move == g::k1;
  if (py == opy && px == opx) {
    enqueue_straight(feed, px - opx, py - opy, pz - opz, cx, cy, pz);
  } else {
    const CompSide side = comp_side_;
    const double radius = comp_radius_;
    double theta = std::atan2(cy - opy, cx - opx);
    double alpha = std::atan2(py - opy, px - opx);
    double beta = 0, gamma = 0;
    if (side == CompSide::kLeft) {
      if (theta < alpha) theta = static_cast<double>(theta + 2 * kPi);
      beta = static_cast<double>((theta - alpha) - kHalfPi);
      gamma = static_cast<double>(kHalfPi);
    } else {
      if (alpha < theta) alpha = static_cast<double>(alpha + 2 * kPi);
      beta = static_cast<double>((alpha - theta) - kHalfPi);
      gamma = static_cast<double>(-kHalfPi);
    }
    end_x = px + radius * std::cos(alpha + gamma);
    end_y = py + radius * std::sin(alpha + gamma);
    double mid_x = opx + radius * std::cos(alpha + gamma);
    double mid_y = opy + radius * std::sin(alpha + gamma);
    bool concave = false;
    if (beta < -kConcave || beta > kPi + kConcave) {
      concave = true;
    } else if (beta > kPi - kConcave && !qc_.empty() && qc_.front().type == Queued::Type::kArc &&
               ((side == CompSide::kRight && qc_.front().turn > 0) ||
                (side == CompSide::kLeft && qc_.front().turn < 0))) {
      concave = true;  // "h" shape: stay above and right of the tangent arc
    }
    if (!concave && beta > kConcave) {
      move_endpoint_and_flush(cx, cy);
      if (feed) {
        enqueue_arc(0.0, mid_x, mid_y, opx, opy, side == CompSide::kLeft ? -1 : 1, cz);
        dequeue_canons();
        set_endpoint(mid_x, mid_y);
      } else {
        enqueue_straight(false, 0.0, 0.0, 0.0, mid_x, mid_y, cz);
        dequeue_canons();
        set_endpoint(mid_x, mid_y);
      }
    } else if (concave) {
      if (qc_.empty() || qc_.front().type != Queued::Type::kArc) {
        // line -> line: shorten the previous move
        const double halfcorner = static_cast<double>((beta + kPi) / 2.0L);
        if (halfcorner == 0.0) fail(col, "cutter compensation: zero-degree inside corner");
        const double retreat = radius / std::tan(halfcorner);
        mid_x = cx + retreat * std::cos(theta + gamma);
        mid_y = cy + retreat * std::sin(theta + gamma);
        move_endpoint_and_flush(mid_x, mid_y);
      } else {
        // arc -> line
        const Queued prev = qc_.front();
        const double oldrad = std::hypot(prev.center2 - prev.end2, prev.center1 - prev.end1);
        const double base_dir = std::atan2(py - opy, px - opx);
        const double th = static_cast<double>(prev.turn > 0 ? base_dir + kHalfPi : base_dir - kHalfPi);
        const double phi = std::atan2(prev.center2 - opy, prev.center1 - opx);
        const double oldrad_uncomp = tool_inside_arc(side, prev.turn) ? oldrad + radius : oldrad - radius;
        const double a = th - phi;
        const double d = oldrad_uncomp * std::cos(a);
        double angle = 0.0;
        if (tool_inside_arc(side, prev.turn)) {
          const double l = (d - radius) / oldrad;
          if (l > 1.0 || l < -1.0)
            fail(col, "cutter compensation: arc to straight motion makes a corner the tool cannot fit without gouging");
          angle = static_cast<double>(prev.turn > 0 ? -std::acos(l) + th + kPi : std::acos(l) + th + kPi);
        } else {
          const double l = (d + radius) / oldrad;
          if (l > 1.0 || l < -1.0)
            fail(col, "cutter compensation: arc to straight motion makes a corner the tool cannot fit without gouging");
          angle = static_cast<double>(prev.turn > 0 ? std::acos(l) + th + kPi : -std::acos(l) + th + kPi);
        }
        mid_x = prev.center1 + oldrad * std::cos(angle);
        mid_y = prev.center2 + oldrad * std::sin(angle);
        move_endpoint_and_flush(mid_x, mid_y);
      }
    } else {
      // straight on (collinear, or a tangent arc -> line)
      dequeue_canons();
      set_endpoint(cx, cy);
    }
    enqueue_straight(feed, px - opx, py - opy, pz - opz, end_x, end_y, pz);
  }
  comp_set_current(end_x, end_y, pz);
  comp_set_programmed(px, py, pz);
}

void Interpreter::convert_arc_comp1(int move, double ex, double ey, double ez, double ox, double oy) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  const CompSide side = comp_side_;
  const double tool_radius = comp_radius_;
  const double spiral = units_ == Units::kInch ? setup_.arc_tolerance_inch : setup_.arc_tolerance_mm;
  const double rtol = units_ == Units::kInch ? 0.00005 : 0.00005 * 25.4;
  const int p = blk_['p'].set ? static_cast<int>(std::nearbyint(blk_.p_number)) : 1;
  double cx = 0, cy = 0, cz = 0;
  comp_get_current(cx, cy, cz);
  if (std::hypot(ex - cx, ey - cy) <= tool_radius)
    fail(col, "cutter compensation entry arc: its radius is not greater than the tool radius");
  double center_x = 0, center_y = 0;
  int turn = 0;
  const bool inside_move = (side == CompSide::kLeft && move == g::k3) || (side == CompSide::kRight && move == g::k2);
  if (blk_['r'].set) {
    if (std::abs(blk_['r'].v) <= tool_radius && inside_move)
      fail(col, "tool radius not less than the arc radius with cutter compensation");
    arc_data_r(move, cx, cy, ex, ey, blk_['r'].v, p, center_x, center_y, turn, rtol, word_col('r'));
  } else {
    arc_data_ijk(move, cx, cy, ex, ey, ijk_absolute_, ox, oy, p, center_x, center_y, turn, rtol, spiral, col);
    if (std::hypot(center_x - cx, center_y - cy) <= tool_radius && inside_move)
      fail(col, "tool radius not less than the arc radius with cutter compensation");
  }
  const double gamma = tool_inside_arc(side, turn) ? std::atan2(center_y - ey, center_x - ex)
                                                   : std::atan2(ey - center_y, ex - center_x);
  comp_firstmove_ = false;
  comp_set_programmed(ex, ey, ez);
  ex += tool_radius * std::cos(gamma);
  ey += tool_radius * std::sin(gamma);
  const double b_len = std::hypot(cy - ey, cx - ex) / 2.0;
  const double ab_ang = std::atan2(center_y - ey, center_x - ex);
  const double a_ang = std::atan2(cy - ey, cx - ex) - ab_ang;
  if (std::abs(std::cos(a_ang)) < kEqual) fail(col, "tool radius not less than the arc radius with cutter compensation");
  const double c_len = b_len / std::cos(a_ang);
  center_x = ex + c_len * std::cos(ab_ang);
  center_y = ey + c_len * std::sin(ab_ang);
  if (std::abs(std::hypot(center_x - ex, center_y - ey) - std::hypot(center_x - cx, center_y - cy)) > spiral)
    fail(col, "cutter compensation could not compute the entry arc (internal error)");
  if (comp_orientation_ != 0 && comp_orientation_ != 9) {
    enqueue_straight(true, 0, 0, 0, cx, cy, cz);
    set_endpoint(cx, cy);
  }
  enqueue_arc(find_turn(cx, cy, center_x, center_y, turn, ex, ey), ex, ey, center_x, center_y, turn, ez);
  comp_set_current(ex, ey, ez);
}

void Interpreter::convert_arc_comp2(int move, double ex, double ey, double ez, double ox, double oy) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  const double spiral = units_ == Units::kInch ? setup_.arc_tolerance_inch : setup_.arc_tolerance_mm;
  const double rtol = units_ == Units::kInch ? 0.00005 : 0.00005 * 25.4;
  const int p = blk_['p'].set ? static_cast<int>(std::nearbyint(blk_.p_number)) : 1;
  double opx = 0, opy = 0, opz = 0;
  comp_get_programmed(opx, opy, opz);
  double cx = 0, cy = 0, cz = 0;
  comp_get_current(cx, cy, cz);
  double centerx = 0, centery = 0;
  int turn = 0;
  if (blk_['r'].set) arc_data_r(move, opx, opy, ex, ey, blk_['r'].v, p, centerx, centery, turn, rtol, word_col('r'));
  else arc_data_ijk(move, opx, opy, ex, ey, ijk_absolute_, ox, oy, p, centerx, centery, turn, rtol, spiral, col);
  const CompSide side = comp_side_;
  const double tool_radius = comp_radius_;
  const double arc_radius = std::hypot(centerx - ex, centery - ey);
  double theta = std::atan2(cy - opy, cx - opx);
  theta = static_cast<double>(side == CompSide::kLeft ? theta - kHalfPi : theta + kHalfPi);
  double delta = std::atan2(centery - opy, centerx - opx);
  const double alpha = static_cast<double>(move == g::k3 ? delta - kHalfPi : delta + kHalfPi);
  double beta = side == CompSide::kLeft ? theta - alpha : alpha - theta;
  beta = static_cast<double>(beta > 1.5L * kPi ? beta - 2 * kPi : beta < -kHalfPi ? beta + 2 * kPi : static_cast<long double>(beta));
  double gamma = 0.0;
  if ((side == CompSide::kLeft && move == g::k3) || (side == CompSide::kRight && move == g::k2)) {
    gamma = std::atan2(centery - ey, centerx - ex);
    if (arc_radius <= tool_radius) fail(col, "tool radius not less than the arc radius with cutter compensation");
  } else {
    gamma = std::atan2(ey - centery, ex - centerx);
    delta = static_cast<double>(delta + kPi);
  }
  const double new_end_x = ex + tool_radius * std::cos(gamma);
  const double new_end_y = ey + tool_radius * std::sin(gamma);
  if (beta < -kConcave || beta > kPi + kConcave || (std::abs(beta - kPi) < kConcave && !tool_inside_arc(side, turn))) {
    // concave
    if (qc_.empty() || qc_.front().type != Queued::Type::kArc) {
      // line -> arc
      const double ccy = static_cast<double>(arc_radius * std::sin(beta - kHalfPi));
      double angle = 0.0;
      double dist = 0.0;
      if (tool_inside_arc(side, turn)) {
        dist = arc_radius - tool_radius;
        const double l = (ccy + tool_radius) / dist;
        if (l > 1.0 || l < -1.0)
          fail(col, "cutter compensation: arc move in a concave corner cannot be reached by the tool without gouging");
        angle = turn > 0 ? theta + std::asin(l) : theta - std::asin(l);
      } else {
        dist = arc_radius + tool_radius;
        const double l = (ccy - tool_radius) / dist;
        if (l > 1.0 || l < -1.0)
          fail(col, "cutter compensation: arc move in a concave corner cannot be reached by the tool without gouging");
        angle = static_cast<double>(turn > 0 ? theta + kPi - std::asin(l) : theta + kPi + std::asin(l));
      }
      move_endpoint_and_flush(centerx + dist * std::cos(angle), centery + dist * std::sin(angle));
    } else {
      // arc -> arc
      const Queued prev = qc_.front();
      const double oldrad = std::hypot(prev.center2 - prev.end2, prev.center1 - prev.end1);
      const double newrad = tool_inside_arc(side, turn) ? arc_radius - tool_radius : arc_radius + tool_radius;
      const double arc_cc = std::hypot(prev.center2 - centery, prev.center1 - centerx);
      if (oldrad == 0 || arc_cc == 0) fail(col, "cutter compensation: arc to arc motion with arcs of the same centre");
      const double a = (oldrad * oldrad + arc_cc * arc_cc - newrad * newrad) / (2 * oldrad * arc_cc);
      if (a > 1.0 || a < -1.0)
        fail(col, "cutter compensation: arc to arc motion makes a corner the tool cannot fit without gouging");
      const double pullback = std::acos(a);
      const double cc_dir = std::atan2(centery - prev.center2, centerx - prev.center1);
      double dir = 0.0;
      if (tool_inside_arc(side, prev.turn)) dir = turn > 0 ? cc_dir + pullback : cc_dir - pullback;
      else dir = turn > 0 ? cc_dir - pullback : cc_dir + pullback;
      move_endpoint_and_flush(prev.center1 + oldrad * std::cos(dir), prev.center2 + oldrad * std::sin(dir));
    }
    enqueue_arc(find_turn(opx, opy, centerx, centery, turn, ex, ey), new_end_x, new_end_y, centerx, centery, turn, ez);
  } else if (beta > kConcave) {
    // convex corner: an arc around the programmed corner first
    const double midx = opx + tool_radius * std::cos(delta);
    const double midy = opy + tool_radius * std::sin(delta);
    dequeue_canons();
    enqueue_arc(0.0, midx, midy, opx, opy, side == CompSide::kLeft ? -1 : 1, cz);
    dequeue_canons();
    set_endpoint(midx, midy);
    enqueue_arc(find_turn(opx, opy, centerx, centery, turn, ex, ey), new_end_x, new_end_y, centerx, centery, turn, ez);
  } else {
    dequeue_canons();
    set_endpoint(cx, cy);
    enqueue_arc(find_turn(opx, opy, centerx, centery, turn, ex, ey), new_end_x, new_end_y, centerx, centery, turn, ez);
  }
  comp_set_programmed(ex, ey, ez);
  comp_set_current(new_end_x, new_end_y, ez);
}

}  // namespace contour::control::gcode_detail
