#include "control/gcode.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "control/gcode_interp.hpp"

namespace contour::control {

namespace {
// The machine context a ProgramSetup describes when it has no explicit one: its six work offsets
// (G54..G59), G28/G30 positions and tool lengths.
MachineContext context_from_setup(const ProgramSetup& s) {
  if (s.machine) return *s.machine;
  MachineContext m;
  for (int sys = 1; sys <= 6; ++sys) m.set_work_offset_mm(sys, s.work_offsets_mm[static_cast<std::size_t>(sys - 1)]);
  m.set_g28_mm(s.g28_mm);
  m.set_g30_mm(s.g30_mm);
  int pocket = 1;
  for (const auto& t : s.tools) {
    ToolData d;
    d.number = t.number;
    d.pocket = pocket++;
    d.offset[2] = t.length_mm;
    m.tools.push_back(d);
  }
  return m;
}

void rotate(double& x, double& y, double theta_deg) {
  const double t = theta_deg * (std::numbers::pi / 180.0);
  const double xx = x * std::cos(t) - y * std::sin(t);
  const double yy = x * std::sin(t) + y * std::cos(t);
  x = xx;
  y = yy;
}
}  // namespace

GcodeError::GcodeError(const std::string& file, int line, int column, const std::string& message)
    : std::runtime_error(file + ":" + std::to_string(line) + ":" + std::to_string(column) + ": " +
                         message),
      line_(line),
      column_(column) {}

GcodeParser::GcodeParser(ProgramSetup setup, std::string file_name) {
  MachineContext m = context_from_setup(setup);
  impl_ = std::make_unique<gcode_detail::Interpreter>(std::move(setup), std::move(m), std::move(file_name));
}

GcodeParser::~GcodeParser() = default;
GcodeParser::GcodeParser(GcodeParser&&) noexcept = default;
GcodeParser& GcodeParser::operator=(GcodeParser&&) noexcept = default;

void GcodeParser::parse_line(std::string_view text, std::vector<Block>& out) { impl_->push_line(text, out); }
void GcodeParser::finish(std::vector<Block>& out) { impl_->finish(out); }
void GcodeParser::set_block_delete(bool on) { impl_->set_block_delete(on); }
bool GcodeParser::ended() const { return impl_->ended(); }
int GcodeParser::line_number() const { return impl_->line_number(); }
const Eigen::Vector3d& GcodeParser::position_mm() const { return impl_->position_mm(); }
void GcodeParser::mdi(std::string_view text, std::vector<Block>& out) { impl_->mdi(text, out); }
void GcodeParser::set_position_mm(const Eigen::Vector3d& machine_mm) { impl_->set_position_mm(machine_mm); }
MachineContext GcodeParser::machine() const { return impl_->machine(); }
bool GcodeParser::machine_changed() const { return impl_->machine_changed(); }
ModalState GcodeParser::modal_state() const { return impl_->modal_state(); }
const std::optional<ModalState>& GcodeParser::resume_state() const { return impl_->resume_state(); }
std::vector<Message> GcodeParser::take_messages() { return impl_->take_messages(); }
const std::string& GcodeParser::source_name(int source) const { return impl_->source_name(source); }
std::size_t GcodeParser::retained_lines() const { return impl_->retained_lines(); }

Eigen::Vector3d work_coordinates(const Block& b, const Eigen::Vector3d& m) {
  double x = m.x() - b.work_offset_mm.x() - b.tool_offset_mm.x();
  double y = m.y() - b.work_offset_mm.y() - b.tool_offset_mm.y();
  const double z = m.z() - b.work_offset_mm.z() - b.tool_offset_mm.z();
  rotate(x, y, -b.xy_rotation_deg);
  return {x - b.g92_offset_mm.x(), y - b.g92_offset_mm.y(), z - b.g92_offset_mm.z()};
}

void Extents::add(const Eigen::Vector3d& p) {
  if (empty) {
    min_mm = max_mm = p;
    empty = false;
    return;
  }
  min_mm = min_mm.cwiseMin(p);
  max_mm = max_mm.cwiseMax(p);
}

void segment_extents(const PathSegment& s, Extents& e) {
  e.add(s.start);
  e.add(s.end);
  if (s.kind != PathSegment::Kind::kArc) return;
  const PlaneAxes pa = plane_axes(s.plane);
  const double r = arc_radius_mm(s);
  const double sweep = arc_sweep_rad(s);
  const double a0 = std::atan2(s.start[pa.b] - s.center[pa.b], s.start[pa.a] - s.center[pa.a]);
  // The in-plane extremes are at multiples of 90 degrees inside the swept angle.
  for (int k = 0; k < 4; ++k) {
    const double ang = k * std::numbers::pi / 2.0;
    double d = s.ccw ? ang - a0 : a0 - ang;
    d = std::fmod(d, 2.0 * std::numbers::pi);
    if (d < 0.0) d += 2.0 * std::numbers::pi;
    if (d > sweep) continue;
    const double u = sweep > 0.0 ? d / sweep : 0.0;
    Eigen::Vector3d q;
    q[pa.a] = s.center[pa.a] + r * std::cos(ang);
    q[pa.b] = s.center[pa.b] + r * std::sin(ang);
    q[pa.n] = s.start[pa.n] + u * (s.end[pa.n] - s.start[pa.n]);
    e.add(q);
  }
}

void ProgramPreview::add(const Block& b) {
  ++blocks;
  if (b.kind == BlockKind::kToolChange) tools.insert(b.tool);
  if (b.kind != BlockKind::kMotion) return;
  ++motion_blocks;
  if (b.tool > 0) tools.insert(b.tool);
  segment_extents(b.seg, machine);
  PathSegment w = b.seg;
  w.start = work_coordinates(b, b.seg.start);
  w.end = work_coordinates(b, b.seg.end);
  w.center = work_coordinates(b, b.seg.center);
  segment_extents(w, work);
  const double len = segment_length_mm(b.seg);
  if (b.rapid) {
    rapid_length_mm += len;
  } else {
    feed_length_mm += len;
    if (b.feed_mm_min > 0.0) feed_time_s += len / (b.feed_mm_min / 60.0);
  }
}

}  // namespace contour::control
