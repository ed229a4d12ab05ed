// Canned cycles G73 G81 G82 G83 G85 G89 in G17/G18/G19, expanded into rapids, feeds and dwells
// exactly as LinuxCNC's interpreter emits them (interp_cycles.cc semantics): the initial level
// (old Z) is kept across consecutive cycle blocks, R and Z of the first block are reused by later
// ones, L repeats with incremental X/Y (G91), G98 returns to the initial level and G99 to R.
// Plane coordinates: G17 (a, b, c) = (X, Y, Z), G19 = (Y, Z, X), G18 = (Z, X, Y); c is the drill
// axis. Cycle moves run in exact-path mode (Block::blend = kExactStop), as LinuxCNC switches to
// G61 for them.
#include <cmath>
#include <numbers>

#include "control/gcode_interp.hpp"

namespace contour::control::gcode_detail {

namespace {
// Axis indices (x=0, y=1, z=2) of plane coordinates a, b, c.
struct CycleAxes {
  int a, b, c;
  char la, lb, lc;
};
CycleAxes cycle_axes(int plane) {
  if (plane == 1) return {0, 1, 2, 'x', 'y', 'z'};
  if (plane == 2) return {1, 2, 0, 'y', 'z', 'x'};
  return {2, 0, 1, 'z', 'x', 'y'};
}
}  // namespace

void Interpreter::cycle_feed(int plane, double a, double b, double c) {
  const CycleAxes ax = cycle_axes(plane);
  double p[3];
  p[ax.a] = a;
  p[ax.b] = b;
  p[ax.c] = c;
  canon_straight(true, sequence_, p[0], p[1], p[2]);
}

void Interpreter::cycle_traverse(int plane, double a, double b, double c) {
  const CycleAxes ax = cycle_axes(plane);
  double p[3];
  p[ax.a] = a;
  p[ax.b] = b;
  p[ax.c] = c;
  canon_straight(false, sequence_, p[0], p[1], p[2]);
}

void Interpreter::convert_cycle(int motion) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  if (feed_rate_ == 0.0) fail(col, "canned cycle with zero feed rate (no F word programmed)");
  if (comp_side_ != CompSide::kOff) fail(col, "cannot use canned cycles with cutter radius compensation on");
  if (!blk_['r'].set) {
    if (motion_mode_ != motion) fail(col, "R (clearance plane) missing in the first block of a canned cycle");
    blk_['r'].v = cycle_r_;
  }
  if (blk_.l_number == 0) fail(word_col('l'), "L0: zero repeats of a canned cycle");
  if (blk_.l_number == -1) blk_.l_number = 1;
  convert_cycle_plane(motion);
  cycle_r_ = blk_['r'].v;
  motion_mode_ = motion;
}

void Interpreter::convert_cycle_plane(int motion) {
  const int col = blk_.g_cols[gm::kMotion] ? blk_.g_cols[gm::kMotion] : 1;
  const int plane = plane_;
  const CycleAxes ax = cycle_axes(plane);
  const double d2r = std::numbers::pi / 180.0;
  double current_cc = cur_[ax.c];
  WordVal& C = blk_[ax.lc];
  if (motion_mode_ != motion && !C.set) {
    const char* pn = plane == 1 ? "G17" : plane == 2 ? "G19" : "G18";
    fail(col, std::string(1, static_cast<char>(ax.lc - 32)) + " missing in the first block of a canned cycle in the " + pn + " plane");
  }
  const double c_number = C.set ? C.v : cycle_cc_;
  double old_cc = 0.0;
  if (cycle_il_flag_) {
    old_cc = cycle_il_;
  } else {
    old_cc = cycle_il_ = current_cc;
    cycle_il_flag_ = true;
  }
  double aa = 0, bb = 0, r = 0, cc = 0;
  double aa_inc = 0, bb_inc = 0, radius_inc = 0, theta_inc = 0;
  const WordVal& A = blk_[ax.la];
  const WordVal& B = blk_[ax.lb];
  if (absolute_) {
    r = blk_['r'].v;
    cc = c_number;
    if (plane == 1 && (blk_.radius.set || blk_.theta.set)) {
      const double radius = blk_.radius.set ? blk_.radius.v : std::hypot(cur_[1], cur_[0]);
      const double theta = blk_.theta.set ? d2r * blk_.theta.v : std::atan2(cur_[1], cur_[0]);
      aa = radius * std::cos(theta);
      bb = radius * std::sin(theta);
    } else {
      aa = A.set ? A.v : cur_[ax.a];
      bb = B.set ? B.v : cur_[ax.b];
    }
  } else {
    if (A.set) aa_inc = A.v;
    if (B.set) bb_inc = B.v;
    if (plane == 1 && blk_.radius.set) radius_inc = blk_.radius.v;
    if (plane == 1 && blk_.theta.set) theta_inc = d2r * blk_.theta.v;
    r = blk_['r'].v + old_cc;
    cc = r + c_number;
    aa = cur_[ax.a];
    bb = cur_[ax.b];
  }
  if (r < cc)
    fail(word_col('r'), std::string("R (") + std::to_string(r) + ") below " +
                            static_cast<char>(ax.lc - 32) + " (" + std::to_string(cc) + ") in a canned cycle");
  // Below the R plane: rapid straight up to it first.
  if (old_cc < r) {
    double p[3] = {cur_[0], cur_[1], cur_[2]};
    p[ax.c] = r;
    canon_straight(false, sequence_, p[0], p[1], p[2]);
    old_cc = r;
    current_cc = old_cc;
  }
  const double clear_cc = retract_r_plane_ ? r : old_cc;
  // Checks and modal P/Q before any cycle motion.
  double p_number = blk_.p_number;
  double q_number = blk_.q_number;
  if (motion == g::k82 || motion == g::k89) {
    if (motion_mode_ != motion && p_number == -1.0)
      fail(col, std::string(motion == g::k82 ? "G82" : "G89") + " needs P (dwell seconds)");
    if (p_number == -1.0) p_number = cycle_p_;
  }
  if (motion == g::k73 || motion == g::k83) {
    if (motion_mode_ != motion && q_number == -1.0)
      fail(col, std::string(motion == g::k73 ? "G73" : "G83") + " needs Q (peck depth)");
    if (q_number == -1.0) q_number = cycle_q_;
  }
  in_cycle_ = true;
  const double rapid_delta = units_ == Units::kMm ? 0.010 * 25.4 : 0.010;
  const int l = blk_.l_number;
  for (int repeat = l; repeat > 0; --repeat) {
    aa += aa_inc;
    bb += bb_inc;
    if (radius_inc != 0.0) {
      if (bb == 0 && aa == 0) fail(blk_.radius.col, "incremental polar motion is indeterminate at the origin");
      const double t = std::atan2(bb, aa);
      const double rr = std::hypot(bb, aa) + radius_inc;
      aa = rr * std::cos(t);
      bb = rr * std::sin(t);
    }
    if (theta_inc != 0.0) {
      if (bb == 0 && aa == 0) fail(blk_.theta.col, "incremental polar motion is indeterminate at the origin");
      const double t = std::atan2(bb, aa) + theta_inc;
      const double rr = std::hypot(bb, aa);
      aa = rr * std::cos(t);
      bb = rr * std::sin(t);
    }
    if (repeat == l && current_cc > r) {
      cycle_traverse(plane, aa, bb, current_cc);
      cycle_traverse(plane, aa, bb, r);
    } else {
      cycle_traverse(plane, aa, bb, clear_cc);
      if (clear_cc > r) cycle_traverse(plane, aa, bb, r);
    }
    switch (motion) {
      case g::k81:
        cycle_feed(plane, aa, bb, cc);
        cycle_traverse(plane, aa, bb, clear_cc);
        break;
      case g::k82:
        cycle_feed(plane, aa, bb, cc);
        canon_dwell(p_number);
        cycle_traverse(plane, aa, bb, clear_cc);
        break;
      case g::k73:
      case g::k83: {
        if (q_number <= 0.0) {
          in_cycle_ = false;
          fail(blk_['q'].set ? blk_['q'].col : col, "Q (peck depth) must be greater than zero");
        }
        for (double depth = r - q_number; depth > cc; depth -= q_number) {
          cycle_feed(plane, aa, bb, depth);
          if (motion == g::k83) cycle_traverse(plane, aa, bb, r);
          cycle_traverse(plane, aa, bb, depth + rapid_delta);
        }
        cycle_feed(plane, aa, bb, cc);
        cycle_traverse(plane, aa, bb, clear_cc);
        break;
      }
      case g::k85:
        cycle_feed(plane, aa, bb, cc);
        cycle_feed(plane, aa, bb, r);
        cycle_traverse(plane, aa, bb, clear_cc);
        break;
      case g::k89:
        cycle_feed(plane, aa, bb, cc);
        canon_dwell(p_number);
        cycle_feed(plane, aa, bb, clear_cc);
        break;
      default:
        break;
    }
  }
  in_cycle_ = false;
  if (motion == g::k82 || motion == g::k89) cycle_p_ = p_number;
  if (motion == g::k73 || motion == g::k83) cycle_q_ = q_number;
  cur_[ax.a] = aa;
  cur_[ax.b] = bb;
  cur_[ax.c] = clear_cc;
  cycle_cc_ = c_number;
}

}  // namespace contour::control::gcode_detail
