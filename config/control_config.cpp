#include "config/control_config.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace contour::config {

namespace {
void read3(Section& s, const std::string& key, std::array<double, 3>& out, double min, double max) {
  if (!s.has(key)) {
    s.accept(key);
    return;
  }
  if (s.node()[key].IsScalar()) {
    // One value: applies to every axis.
    const double x = s.number(key, out[0], min, max);
    out = {x, x, x};
    return;
  }
  const std::vector<double> v = s.numbers(key, 1, 3);
  for (std::size_t i = 0; i < v.size() && i < 3; ++i) {
    if (v[i] < min || v[i] > max) {
      s.error(key, "value " + std::to_string(v[i]) + " out of range [" + std::to_string(min) +
                       ", " + std::to_string(max) + "]");
      continue;
    }
    out[i] = v[i];
  }
  // One value given: applies to every axis.
  if (v.size() == 1) out[1] = out[2] = out[0];
}
}  // namespace

ControllerType parse_controller_type(const std::string& name) {
  if (name == "p") return ControllerType::kP;
  if (name == "pid") return ControllerType::kPid;
  if (name == "ccc") return ControllerType::kCcc;
  throw std::invalid_argument("controller must be p, pid or ccc, got '" + name + "'");
}

const char* controller_type_name(ControllerType t) {
  switch (t) {
    case ControllerType::kP:
      return "p";
    case ControllerType::kPid:
      return "pid";
    case ControllerType::kCcc:
      return "ccc";
  }
  return "?";
}

ControlConfig parse_control(Section& s) {
  ControlConfig c;
  c.controller = parse_controller_type(s.choice("controller", "ccc", {"p", "pid", "ccc"}));
  read3(s, "kp", c.kp, 0.0, 1e3);
  {
    Section pid = s.child("pid");
    read3(pid, "kp", c.pid_kp, 0.0, 1e3);
    read3(pid, "kd_s", c.pid_kd_s, 0.0, 1e3);
    read3(pid, "ki_per_s", c.pid_ki_per_s, 0.0, 1e6);
    pid.finish();
  }
  c.feed_forward = s.number("feed_forward", 0.0, 0.0, 1.0);
  read3(s, "velocity_limit_mm_min", c.velocity_limit_mm_min, 0.0, 1e7);
  {
    Section cp = s.child("coupling");
    c.coupling.enable = true;
    c.coupling.cp = cp.number("cp", 15.0, 0.0, 1e4);
    c.coupling.ci_per_s = cp.number("ci_per_s", 300.0, 0.0, 1e7);
    c.coupling.cd_s = cp.number("cd_s", 0.3, 0.0, 1e3);
    c.coupling.remove_tangential_integral = cp.boolean("remove_tangential_integral", true);
    cp.finish();
  }
  const std::string model = s.choice("model", "circle", {"circle", "nearest", "linear"});
  c.model = model == "nearest"  ? control::ModelKind::kNearestPoint
            : model == "linear" ? control::ModelKind::kLinear
                                : control::ModelKind::kCircle;
  c.window_rule = s.choice("window_rule", "multi_step", {"multi_step", "literal"}) == "literal"
                      ? control::WindowRule::kLiteral
                      : control::WindowRule::kMultiStep;
  c.window_capacity = static_cast<int>(s.integer("window_capacity", 256, 4, 1 << 20));
  c.delay_compensation = s.boolean("delay_compensation", true);
  {
    Section d = s.child("derivative");
    c.derivative.model_blend_s = d.number("model_blend_ms", 5.0, 0.0, 1000.0) / 1000.0;
    const std::string sg = d.choice("same_geometry", "ahead", {"never", "ahead", "always"});
    c.derivative.same_geometry = sg == "never"    ? control::SameGeometry::kNever
                                 : sg == "always" ? control::SameGeometry::kAlways
                                                  : control::SameGeometry::kAhead;
    c.derivative.lowpass_s = d.number("lowpass_ms", 0.0, 0.0, 1000.0) / 1000.0;
    d.finish();
  }
  return c;
}

control::ServoParams make_servo_params(const ControlConfig& cfg, ControllerType type,
                                       const std::array<control::FeedDriveParams, 3>& drives,
                                       int axes, double period_s, int delay_cycles) {
  control::ServoParams p;
  p.axes = axes;
  p.period_s = period_s;
  p.drive = drives;
  p.delay_cycles = delay_cycles;
  p.delay_compensation = cfg.delay_compensation;
  p.derivative = cfg.derivative;
  p.law = type == ControllerType::kPid ? control::AxisLaw::kPid : control::AxisLaw::kP;
  p.coupling = cfg.coupling;
  p.coupling.enable = type == ControllerType::kCcc;
  for (std::size_t i = 0; i < 3; ++i) {
    control::AxisGains& g = p.axis[i];
    if (type == ControllerType::kPid) {
      g.kp = cfg.pid_kp[i];
      g.kd_s = cfg.pid_kd_s[i];
      g.ki_per_s = cfg.pid_ki_per_s[i];
    } else {
      g.kp = cfg.kp[i];
    }
    g.ff = cfg.feed_forward;
    g.u_max_mm = cfg.velocity_limit_mm_min[i] > 0.0
                     ? cfg.velocity_limit_mm_min[i] / 60.0 / drives[i].gain_per_s
                     : std::numeric_limits<double>::infinity();
  }
  return p;
}

control::ContourErrorParams make_model_params(const ControlConfig& cfg) {
  control::ContourErrorParams m;
  m.kind = cfg.model;
  m.rule = cfg.window_rule;
  m.window_capacity = cfg.window_capacity;
  return m;
}

control::LoopPlant make_loop_plant(const MachineConfig& m) {
  control::LoopPlant pl;
  pl.axes = static_cast<int>(std::min<std::size_t>(m.axes.size(), control::kMaxServoAxes));
  for (int i = 0; i < pl.axes; ++i) {
    const AxisConfig& a = m.axes[static_cast<std::size_t>(i)];
    control::AxisPlant& p = pl.axis[static_cast<std::size_t>(i)];
    p.gain_per_s = a.drive.gain_per_s;
    p.tau_s = a.drive.tau_s;
    p.delay_cycles = a.drive.delay_cycles;
    p.blu_mm = a.drive.blu_mm > 0.0 ? a.drive.blu_mm : 1.0 / a.counts_per_mm;
    p.max_velocity_mm_s = a.max_velocity_mm_min / 60.0;
    p.max_accel_mm_s2 = a.max_accel_mm_s2;
    p.clamp_tau_s = a.drive.tau_s;
  }
  return pl;
}

}  // namespace contour::config
