// The canonical layer: LinuxCNC's interpreter calls STRAIGHT_TRAVERSE, ARC_FEED, DWELL, ... in
// program coordinates and program units; its canon (emccanon) converts to machine units and adds
// the offsets: machine = R(rotation) (p + G92) + G5x + tool offset. Here the same conversion
// produces contourd Blocks. The enqueue_* wrappers hold calls while cutter compensation holds a
// move back (LinuxCNC's interp queue), so their order relative to motion is LinuxCNC's.
#include <cmath>
#include <numbers>

#include "control/gcode_interp.hpp"

namespace contour::control::gcode_detail {

namespace {
void rotate(double& x, double& y, double theta_deg) {
  const double t = theta_deg * (std::numbers::pi / 180.0);
  const double xx = x * std::cos(t) - y * std::sin(t);
  const double yy = x * std::sin(t) + y * std::cos(t);
  x = xx;
  y = yy;
}
}  // namespace

Eigen::Vector3d Interpreter::to_machine(double x, double y, double z) const {
  const double k = units_ == Units::kInch ? 25.4 : 1.0;
  double px = x * k + g92_mm_.x();
  double py = y * k + g92_mm_.y();
  const double pz = z * k + g92_mm_.z();
  rotate(px, py, rot_deg_);
  return {px + g5x_mm_.x() + tlo_mm_.x(), py + g5x_mm_.y() + tlo_mm_.y(), pz + g5x_mm_.z() + tlo_mm_.z()};
}

Eigen::Vector3d Interpreter::from_machine(const Eigen::Vector3d& m) const {
  const double k = units_ == Units::kInch ? 25.4 : 1.0;
  double px = m.x() - g5x_mm_.x() - tlo_mm_.x();
  double py = m.y() - g5x_mm_.y() - tlo_mm_.y();
  const double pz = m.z() - g5x_mm_.z() - tlo_mm_.z();
  rotate(px, py, -rot_deg_);
  return {(px - g92_mm_.x()) / k, (py - g92_mm_.y()) / k, (pz - g92_mm_.z()) / k};
}

Block Interpreter::base_block() const {
  Block b;
  b.line = emit_line_ >= 0 ? emit_line_ : sequence_;
  b.source = emit_source_ >= 0 ? emit_source_ : cur_source_;
  if (in_cycle_ || control_mode_ != 0) {
    b.blend = BlendMode::kExactStop;
  } else if (control_tolerance_ > 0.0) {
    b.blend = BlendMode::kLimited;
    b.tolerance_mm = control_tolerance_;
  } else {
    b.blend = BlendMode::kFull;
  }
  b.spindle = canon_spindle_;
  b.spindle_rpm = canon_rpm_;
  b.mist = canon_mist_;
  b.flood = canon_flood_;
  b.tool = canon_tool_;
  b.feed_mm_min = canon_feed_mm_min_;
  b.coord_system = canon_system_;
  b.work_offset_mm = g5x_mm_;
  b.g92_offset_mm = g92_mm_;
  b.tool_offset_mm = tlo_mm_;
  b.xy_rotation_deg = rot_deg_;
  return b;
}

void Interpreter::emit(Block b) {
  if (b.kind == BlockKind::kMotion) pos_mm_ = b.seg.end;
  if (suppress_ && b.kind != BlockKind::kEnd) return;
  out_->push_back(std::move(b));
}

void Interpreter::canon_straight(bool feed, int line, double x, double y, double z) {
  Block b = base_block();
  if (emit_line_ < 0) b.line = line;
  b.kind = BlockKind::kMotion;
  b.rapid = !feed;
  if (!feed) b.feed_mm_min = setup_.rapid_mm_min;
  b.seg = PathSegment::line(pos_mm_, to_machine(x, y, z));
  emit(std::move(b));
}

void Interpreter::canon_arc(int line, double fe, double se, double fc, double sc, int rotation, double ae) {
  if (rot_deg_ != 0.0 && canon_plane_ != 1)
    fail(1, "arc in the G18/G19 plane with a rotated coordinate system (G10 L2 R) is not supported");
  Block b = base_block();
  if (emit_line_ < 0) b.line = line;
  b.kind = BlockKind::kMotion;
  PathSegment s;
  s.kind = PathSegment::Kind::kArc;
  s.start = pos_mm_;
  Eigen::Vector3d c;
  if (canon_plane_ == 1) {
    s.end = to_machine(fe, se, ae);
    c = to_machine(fc, sc, ae);
    s.plane = Plane::kXY;
  } else if (canon_plane_ == 3) {
    s.end = to_machine(se, ae, fe);
    c = to_machine(sc, ae, fc);
    s.plane = Plane::kZX;
  } else {
    s.end = to_machine(ae, fe, se);
    c = to_machine(ae, fc, sc);
    s.plane = Plane::kYZ;
  }
  const PlaneAxes pa = plane_axes(s.plane);
  c[pa.n] = s.start[pa.n];
  s.center = c;
  s.ccw = rotation > 0;
  s.turns = std::abs(rotation) - 1;
  b.seg = s;
  emit(std::move(b));
}

void Interpreter::canon_dwell(double seconds) {
  Block b = base_block();
  b.kind = BlockKind::kDwell;
  b.dwell_s = seconds;
  b.seg = PathSegment::line(pos_mm_, pos_mm_);
  emit(std::move(b));
}

void Interpreter::canon_set_feed_rate(double rate) {
  canon_feed_mm_min_ = rate * (units_ == Units::kInch ? 25.4 : 1.0);
}
void Interpreter::canon_spindle(SpindleDir dir) { canon_spindle_ = dir; }
void Interpreter::canon_speed(double rpm) { canon_rpm_ = rpm; }
void Interpreter::canon_mist(bool on) { canon_mist_ = on; }
void Interpreter::canon_flood(bool on) { canon_flood_ = on; }
void Interpreter::canon_select_plane(int plane) { canon_plane_ = plane; }

void Interpreter::canon_g5x(int index, double x, double y, double z) {
  const double k = units_ == Units::kInch ? 25.4 : 1.0;
  g5x_mm_ = Eigen::Vector3d(x * k, y * k, z * k);
  canon_system_ = index;
}

void Interpreter::canon_g92(double x, double y, double z) {
  const double k = units_ == Units::kInch ? 25.4 : 1.0;
  g92_mm_ = Eigen::Vector3d(x * k, y * k, z * k);
}

void Interpreter::canon_rotation(double deg) { rot_deg_ = deg; }

void Interpreter::canon_tool_offset(double x, double y, double z) {
  const double k = units_ == Units::kInch ? 25.4 : 1.0;
  tlo_mm_ = Eigen::Vector3d(x * k, y * k, z * k);
}

void Interpreter::canon_change_tool(int tool_number) {
  canon_tool_ = tool_number;
  machine_changed_ = true;
  Block b = base_block();
  b.kind = BlockKind::kToolChange;
  b.seg = PathSegment::line(pos_mm_, pos_mm_);
  b.tool = tool_number;
  b.message = "manual tool change: insert tool " + std::to_string(tool_number) + ", then resume";
  emit(std::move(b));
}

void Interpreter::canon_set_tool_number(int tool_number) {
  canon_tool_ = tool_number;
  machine_changed_ = true;
}

void Interpreter::canon_stop(BlockKind kind, const std::string& message) {
  Block b = base_block();
  b.kind = kind;
  b.seg = PathSegment::line(pos_mm_, pos_mm_);
  b.message = message;
  emit(std::move(b));
}

void Interpreter::canon_user_m(int m, double p, double q) {
  Block b = base_block();
  b.kind = BlockKind::kDwell;
  b.dwell_s = 0.0;
  b.user_m = m;
  b.user_p = p;
  b.user_q = q;
  b.seg = PathSegment::line(pos_mm_, pos_mm_);
  b.message = "M" + std::to_string(m);
  emit(std::move(b));
}

void Interpreter::canon_message(const std::string& text) {
  if (suppress_) return;
  messages_.push_back(Message{Message::Kind::kMsg, sequence_,
                              sources_[static_cast<std::size_t>(cur_source_)].name, text, out_->size()});
}

// ---- enqueue_*: immediate unless cutter compensation holds moves back

namespace {
Queued make(Queued::Type t, int line, int source) {
  Queued q;
  q.type = t;
  q.line = line;
  q.source = source;
  return q;
}
}  // namespace

void Interpreter::enqueue_feed_rate(double f) {
  if (qc_.empty()) return canon_set_feed_rate(f);
  Queued q = make(Queued::Type::kFeedRate, sequence_, cur_source_);
  q.value = f;
  qc_.push_back(q);
}

void Interpreter::enqueue_dwell(double t) {
  if (qc_.empty()) return canon_dwell(t);
  Queued q = make(Queued::Type::kDwell, sequence_, cur_source_);
  q.value = t;
  qc_.push_back(q);
}

void Interpreter::enqueue_spindle(SpindleDir d) {
  if (qc_.empty()) return canon_spindle(d);
  Queued q = make(Queued::Type::kSpindle, sequence_, cur_source_);
  q.ivalue = static_cast<int>(d);
  qc_.push_back(q);
}

void Interpreter::enqueue_speed(double s) {
  if (qc_.empty()) return canon_speed(s);
  Queued q = make(Queued::Type::kSpeed, sequence_, cur_source_);
  q.value = s;
  qc_.push_back(q);
}

void Interpreter::enqueue_mist(bool on) {
  if (qc_.empty()) return canon_mist(on);
  Queued q = make(Queued::Type::kMist, sequence_, cur_source_);
  q.ivalue = on;
  qc_.push_back(q);
}

void Interpreter::enqueue_flood(bool on) {
  if (qc_.empty()) return canon_flood(on);
  Queued q = make(Queued::Type::kFlood, sequence_, cur_source_);
  q.ivalue = on;
  qc_.push_back(q);
}

void Interpreter::enqueue_user_m(int m, double p, double qv) {
  if (qc_.empty()) return canon_user_m(m, p, qv);
  Queued q = make(Queued::Type::kUserM, sequence_, cur_source_);
  q.ivalue = m;
  q.value = p;
  q.value2 = qv;
  qc_.push_back(q);
}

}  // namespace contour::control::gcode_detail
