// contour-sim force: 2-DOF cutting-force / position control (seed 001), Figs 4.1-4.5.
//   contour-sim force --scenario track|impulse|step|model-error|noise [--plant physical|printed]
//                     [--config FILE] [--csv FILE] [--plot FILE.png]
// The design is computed from the `force:` section (or the built-in defaults = the paper's eq 3.8
// with the physical spindle reading), its quality is printed, the scenario is simulated on the
// same plant model (ForcePlantSim) and the last stdout line is one JSON object.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>

#include "config/config.hpp"
#include "control/force_2dof.hpp"
#include "control/force_controller.hpp"
#include "tools/contour-sim/commands.hpp"

namespace contour::sim {

namespace {
using control::ForceScenarioKind;

bool write_csv(const std::string& path, const control::ForceTrace& tr) {
  std::ofstream f(path);
  if (!f) return false;
  f << "t_s,force_N,force_ref_N,force_model_N,progress_mm,plan_mm,feed_override,spindle_rpm\n";
  f.precision(9);
  for (std::size_t i = 0; i < tr.t_s.size(); ++i) {
    f << tr.t_s[i] << ',' << tr.force_N[i] << ',' << tr.force_ref_N[i] << ','
      << tr.force_model_N[i] << ',' << tr.progress_mm[i] << ',' << tr.plan_mm[i] << ','
      << tr.feed_override[i] << ',' << tr.spindle_rpm[i] << '\n';
  }
  return static_cast<bool>(f);
}

bool write_plot(const std::string& png, const control::ForceTrace& tr, const std::string& title) {
  const auto dat = std::filesystem::temp_directory_path() /
                   ("contour_force_" + std::to_string(::getpid()) + ".dat");
  {
    std::ofstream f(dat);
    if (!f) return false;
    f.precision(9);
    for (std::size_t i = 0; i < tr.t_s.size(); i += 5) {
      f << tr.t_s[i] << ' ' << tr.force_N[i] << ' ' << tr.force_ref_N[i] << ' '
        << tr.force_model_N[i] << ' ' << tr.feed_override[i] * 100.0 << ' ' << tr.spindle_rpm[i]
        << ' ' << tr.plan_mm[i] - tr.progress_mm[i] << '\n';
    }
  }
  FILE* gp = ::popen("gnuplot", "w");
  if (gp == nullptr) return false;
  const std::string d = dat.string();
  std::fprintf(gp,
               "set terminal pngcairo size 1200,800\nset output '%s'\nset multiplot layout 2,1 "
               "title '%s'\nset grid\nset xlabel 't (s)'\nset ylabel 'force (N)'\n"
               "plot '%s' u 1:3 w l lw 2 t 'reference', '%s' u 1:4 w l dt 2 t 'reference model', "
               "'%s' u 1:2 w l t 'force'\n"
               "set ylabel 'feed override (%%)'\nset y2label 'spindle (rpm)'\nset y2tics\n"
               "plot '%s' u 1:5 w l t 'feed override' axes x1y1, '%s' u 1:6 w l t 'spindle rpm' "
               "axes x1y2\nunset multiplot\n",
               png.c_str(), title.c_str(), d.c_str(), d.c_str(), d.c_str(), d.c_str(), d.c_str());
  const int rc = ::pclose(gp);
  std::filesystem::remove(dat);
  return rc == 0;
}
}  // namespace

int run_force(int argc, char** argv) {
  CLI::App app{"2-DOF cutting-force / position control (seed 001), Figs 4.1-4.5", "force"};
  std::string scenario = "track", plant_opt, config_path, csv_path, plot_path;
  bool no_anti_windup = false;
  unsigned seed = 1;
  app.add_option("--scenario", scenario, "track | impulse | step | model-error | noise")
      ->check(CLI::IsMember({"track", "impulse", "step", "model-error", "noise"}));
  app.add_option("--plant", plant_opt, "spindle term reading: physical | printed (overrides config)")
      ->check(CLI::IsMember({"physical", "printed"}));
  app.add_option("--config", config_path, "YAML file with a force: section")->check(CLI::ExistingFile);
  app.add_option("--csv", csv_path, "write the time series");
  app.add_option("--plot", plot_path, "write force vs reference and feed override vs time (PNG)");
  app.add_option("--seed", seed, "noise seed");
  app.add_flag("--no-anti-windup", no_anti_windup, "disable anti-windup (to show wind-up)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }

  config::ForceConfig fc;
  double period_s = 0.001;
  if (!config_path.empty()) {
    try {
      const config::Config cfg = config::load_config_file(config_path);
      fc = cfg.force;
      period_s = cfg.machine.period_s;
    } catch (const config::ConfigError& e) {
      for (const auto& m : e.errors()) std::cerr << m << '\n';
      std::cout << nlohmann::json{{"error", "invalid config"}}.dump() << '\n';
      return 2;
    }
  }
  if (plant_opt == "printed") fc.design.plant.spindle_pole = control::SpindlePole::kPrinted;
  if (plant_opt == "physical") fc.design.plant.spindle_pole = control::SpindlePole::kPhysical;
  fc.design.period_s = period_s;
  fc.limits.anti_windup = !no_anti_windup;

  const control::ForceDesign design = control::design_force_2dof(fc.design);
  std::cout << "force design: " << control::describe_quality(design.quality) << '\n';

  control::ForceScenario sc;
  sc.force_ref_N = fc.reference_N;
  sc.feed_mm_s = fc.design.plant.k_v_mm_s;  // programmed feed = 100 % override
  sc.disturbance_N = 0.5 * fc.reference_N;
  sc.noise_sigma_N = 0.02 * std::abs(fc.reference_N);
  sc.seed = seed;
  sc.true_plant = fc.design.plant;
  sc.limits = fc.limits;
  if (scenario == "track") sc.kind = ForceScenarioKind::kTrack;
  if (scenario == "noise") sc.kind = ForceScenarioKind::kNoise;
  if (scenario == "step") sc.kind = ForceScenarioKind::kStep;
  if (scenario == "impulse") {
    sc.kind = ForceScenarioKind::kImpulse;
    sc.disturbance_N = 2.0 * fc.reference_N;  // 20 ms pulse, Fig 4.3
  }
  if (scenario == "model-error") {
    // Fig 4.5: plant gains and time constants off by 30 % (a corner that makes the force loop
    // faster and stronger than designed and the feed slower).
    sc.kind = ForceScenarioKind::kModelError;
    sc.true_plant.k_f_N *= 1.3;
    sc.true_plant.tau_f_s *= 0.7;
    sc.true_plant.k_s_N *= 1.3;
    sc.true_plant.tau_s_s *= 0.7;
    sc.true_plant.k_v_mm_s *= 0.7;
  }
  control::ForceTrace trace;
  const control::ForceMetrics m = control::run_force_scenario(design, sc, &trace);
  const auto pd = control::lti::c2d_zoh(control::force_plant_model(sc.true_plant), period_s);
  const double radius = control::lti::max_pole_radius(
      control::lti::closed_loop_a(pd, control::force_feedback_controller(design)));

  if (!csv_path.empty() && !write_csv(csv_path, trace)) {
    std::cerr << "contour-sim force: cannot write " << csv_path << '\n';
    return 1;
  }
  if (!plot_path.empty() &&
      !write_plot(plot_path, trace,
                  "contour-sim force --scenario " + scenario + " (" +
                      (fc.design.plant.spindle_pole == control::SpindlePole::kPrinted ? "printed"
                                                                                      : "physical") +
                      " plant)")) {
    std::cerr << "contour-sim force: gnuplot failed for " << plot_path << '\n';
    return 1;
  }
  const auto& q = design.quality;
  nlohmann::json j;
  j["scenario"] = scenario;
  j["plant"] = fc.design.plant.spindle_pole == control::SpindlePole::kPrinted ? "printed" : "physical";
  j["position_model"] = fc.design.position_model == control::PositionModel::kType2 ? "type2" : "paper";
  j["stable"] = m.stable;
  j["max_pole_radius"] = radius;
  j["phase_margin_deg"] = {{"feed", q.input_phase_margin_deg[0]}, {"spindle", q.input_phase_margin_deg[1]}};
  j["output_phase_margin_deg"] = {{"force", q.output_phase_margin_deg[0]},
                                  {"position", q.output_phase_margin_deg[1]}};
  j["delay_margin_ms"] = q.delay_margin_s * 1e3;
  j["peak_sensitivity"] = {{"input", q.peak_input_sensitivity},
                           {"output", q.peak_output_sensitivity},
                           {"output_complementary", q.peak_output_complementary}};
  j["bezout_residual"] = q.bezout_residual;
  j["force_settling_s"] = m.force_settling_s;
  j["reference_model_settling_s"] = 5.8335 * fc.design.tau_m_s;
  j["force_overshoot_pct"] = m.force_overshoot_pct;
  j["force_rms_error"] = m.force_rms_error;
  j["force_rms_error_vs_model"] = m.force_rms_error_vs_model;
  j["position_rms_error_mm"] = m.position_rms_error_mm;
  j["position_ramp_lag_mm"] = m.position_ramp_lag_mm;
  j["disturbance_recovery_s"] = m.disturbance_recovery_s;
  j["disturbance_N"] = (sc.kind == ForceScenarioKind::kStep || sc.kind == ForceScenarioKind::kImpulse)
                           ? sc.disturbance_N
                           : 0.0;
  // Minimum recovery time ANY controller could reach with these actuator limits (kStep only).
  j["disturbance_recovery_bound_s"] = m.disturbance_recovery_bound_s;
  j["steady_force_error"] = m.steady_force_error;
  std::cout << j.dump() << '\n';
  return m.stable ? 0 : 1;
}

}  // namespace contour::sim
