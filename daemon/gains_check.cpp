#include "daemon/gains_check.hpp"

#include "config/control_config.hpp"

namespace contour::daemon {

control::StabilityVerdict check_gains(const control::ServoParams& p, const config::MachineConfig& m) {
  control::StabilityOptions opt;
  for (std::size_t i = 0; i < m.axes.size() && i < opt.axis_names.size(); ++i) {
    if (!m.axes[i].name.empty()) opt.axis_names[i] = m.axes[i].name[0];
  }
  return control::check_loop_stability(p, config::make_loop_plant(m), opt);
}

std::string inactive_gain_reason(const std::string& key, const control::ServoParams& p) {
  const char* law = p.law == control::AxisLaw::kPid ? "pid" : "p";
  if ((key == "ki_per_s" || key == "kd_s") && p.law != control::AxisLaw::kPid) {
    return "gain '" + key + "' is not used by the active law " + law + " (" +
           (p.coupling.enable ? "cross-coupled: kp, ff, cp, ci_per_s, cd_s" : "kp, ff") +
           "; ki_per_s and kd_s need controller: pid)";
  }
  if ((key == "cp" || key == "ci_per_s" || key == "cd_s") && !p.coupling.enable) {
    return "gain '" + key + "' is not used by the active law " + law +
           " without coupling (set coupling=true with it, or use controller: ccc)";
  }
  return {};
}

}  // namespace contour::daemon
