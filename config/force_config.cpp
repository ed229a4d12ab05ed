#include "config/force_config.hpp"

namespace contour::config {

ForceConfig parse_force(Section& s) {
  ForceConfig f;
  if (!s.present()) return f;
  f.enable = s.boolean("enable", false);
  f.reference_N = s.number("reference_N", 1.0, -1e6, 1e6);
  auto& pl = f.design.plant;
  {
    Section p = s.child("plant");
    pl.k_f_N = p.number("k_f_N", pl.k_f_N, -1e6, 1e6);
    if (pl.k_f_N == 0.0) p.error("k_f_N", "must not be zero");
    pl.tau_f_s = p.number("tau_f_ms", pl.tau_f_s * 1e3, 1e-3, 1e6) / 1e3;
    pl.k_s_N = p.number("k_s_N", pl.k_s_N, -1e6, 1e6);
    if (pl.k_s_N == 0.0) p.error("k_s_N", "must not be zero");
    pl.tau_s_s = p.number("tau_s_ms", pl.tau_s_s * 1e3, 1e-3, 1e6) / 1e3;
    pl.k_v_mm_s = p.number("k_v_mm_s", pl.k_v_mm_s, 1e-6, 1e6);
    pl.spindle_pole = p.choice("spindle_pole", "physical", {"physical", "printed"}) == "printed"
                          ? control::SpindlePole::kPrinted
                          : control::SpindlePole::kPhysical;
    p.finish();
  }
  {
    Section m = s.child("reference_model");
    f.design.tau_m_s = m.number("tau_m_ms", f.design.tau_m_s * 1e3, 1e-3, 1e6) / 1e3;
    if (f.design.tau_m_s >= pl.tau_f_s || f.design.tau_m_s >= pl.tau_s_s) {
      m.error("tau_m_ms", "must be smaller than plant.tau_f_ms and plant.tau_s_ms (paper eq 3.6)");
    }
    f.design.position_model = m.choice("position", "type2", {"type2", "paper"}) == "paper"
                                  ? control::PositionModel::kPaper
                                  : control::PositionModel::kType2;
    m.finish();
  }
  {
    Section d = s.child("design");
    auto& w = f.design.weights;
    const double big = 1e12;
    w.q_force = d.number("q_force", w.q_force, 1e-12, big);
    w.q_position = d.number("q_position", w.q_position, 1e-12, big);
    w.q_force_integral = d.number("q_force_integral", w.q_force_integral, 1e-12, big);
    w.q_position_integral = d.number("q_position_integral", w.q_position_integral, 1e-12, big);
    w.r_feed = d.number("r_feed", w.r_feed, 1e-15, big);
    w.r_spindle = d.number("r_spindle", w.r_spindle, 1e-15, big);
    w.observer_input_noise = d.number("observer_input_noise", w.observer_input_noise, 1e-12, big);
    w.observer_state_noise = d.number("observer_state_noise", w.observer_state_noise, 0.0, big);
    w.observer_measurement_noise =
        d.number("observer_measurement_noise", w.observer_measurement_noise, 1e-15, big);
    d.finish();
  }
  auto& l = f.limits;
  {
    Section li = s.child("limits");
    l.override_min = li.number("override_min_pct", l.override_min * 100.0, 0.0, 1000.0) / 100.0;
    l.override_max = li.number("override_max_pct", l.override_max * 100.0, 0.0, 1000.0) / 100.0;
    if (l.override_max <= l.override_min) {
      li.error("override_max_pct", "must be greater than override_min_pct");
    }
    l.override_rate_per_s =
        li.number("override_rate_pct_s", l.override_rate_per_s * 100.0, 1e-3, 1e7) / 100.0;
    l.force_ceiling_N = li.number("force_ceiling_N", l.force_ceiling_N, 1e-9, 1e9);
    li.finish();
  }
  {
    Section sp = s.child("spindle");
    l.spindle_nominal_rpm = sp.number("nominal_rpm", l.spindle_nominal_rpm, 0.0, 1e6);
    l.spindle_rpm_per_unit = sp.number("rpm_per_unit", l.spindle_rpm_per_unit, 1e-6, 1e6);
    l.spindle_min_rpm = sp.number("min_rpm", l.spindle_min_rpm, 0.0, 1e6);
    l.spindle_max_rpm = sp.number("max_rpm", l.spindle_max_rpm, 0.0, 1e6);
    l.spindle_rate_rpm_s = sp.number("rate_rpm_s", l.spindle_rate_rpm_s, 1e-3, 1e9);
    if (l.spindle_max_rpm <= l.spindle_min_rpm) sp.error("max_rpm", "must be greater than min_rpm");
    if (l.spindle_nominal_rpm < l.spindle_min_rpm || l.spindle_nominal_rpm > l.spindle_max_rpm) {
      sp.error("nominal_rpm", "must lie in [min_rpm, max_rpm]");
    }
    sp.finish();
  }
  const std::string fallback = s.choice("fallback", "hold", {"hold", "programmed_feed", "fault"});
  l.fallback = fallback == "programmed_feed" ? control::ForceFallback::kProgrammedFeed
                                             : control::ForceFallback::kHold;
  // `fault`: the controller holds the feed (as `hold`) and the loop faults in the same cycle.
  f.stale_faults = fallback == "fault";
  l.stale_age_s = s.number("stale_ms", l.stale_age_s * 1e3, 0.1, 1e5) / 1e3;
  l.bumpless_tau_s = s.number("bumpless_ms", l.bumpless_tau_s * 1e3, 0.1, 1e5) / 1e3;
  return f;
}

}  // namespace contour::config
