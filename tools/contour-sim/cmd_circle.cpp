// contour-sim circle: circular test on the simulated machine (seed 003). Simulates the circle with
// the configured axis mismatch and geometric errors, estimates k_p and tau per axis (encoder
// record, geometry-aware ballbar fit, naive ballbar fit, CW/CCW reversal), matches Y to X,
// re-runs and reports the ellipse before/after. With --ballbar it analyses an imported trace.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "config/circle_test_config.hpp"
#include "config/geometry_config.hpp"
#include "control/circle_test.hpp"
#include "tools/contour-sim/commands.hpp"

namespace contour::sim {

namespace {
namespace cc = contour::control::circle;
using nlohmann::json;
constexpr double kPi = std::numbers::pi;

double r3(double v) { return std::round(v * 1000.0) / 1000.0; }
double r5(double v) { return std::round(v * 100000.0) / 100000.0; }

cc::Circle make_circle(double radius, double feed, cc::Direction d, const std::array<double, 2>& c,
                       double z) {
  cc::Circle circ;
  circ.radius_mm = radius;
  circ.feed_mm_min = feed;
  circ.direction = d;
  circ.center_mm = Eigen::Vector2d(c[0], c[1]);
  circ.z_mm = z;
  return circ;
}

// CSV with a header naming deviation_um and t_s and/or angle_deg. Angle-only traces are aligned
// by angle: t = (unwrapped s * angle) / w, i.e. the circle starts at angle 0 at t = 0.
cc::BallbarTrace read_ballbar_csv(const std::string& path, const cc::Circle& c) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::string line;
  int col_t = -1, col_a = -1, col_d = -1;
  std::size_t ncols = 0;
  if (!std::getline(in, line)) throw std::runtime_error(path + ":1: empty file");
  {
    std::stringstream ss(line);
    std::string name;
    int i = 0;
    while (std::getline(ss, name, ',')) {
      while (!name.empty() && (name.back() == '\r' || name.back() == ' ')) name.pop_back();
      while (!name.empty() && name.front() == ' ') name.erase(0, 1);
      if (name == "t_s") col_t = i;
      if (name == "angle_deg") col_a = i;
      if (name == "deviation_um") col_d = i;
      ++i;
    }
    ncols = static_cast<std::size_t>(i);
  }
  if (col_d < 0 || (col_t < 0 && col_a < 0)) {
    throw std::runtime_error(path + ":1: header must name deviation_um and t_s and/or angle_deg");
  }
  cc::BallbarTrace tr;
  const double w = c.omega_rad_s();
  double prev_angle = 0.0, unwrapped = 0.0;
  bool first = true;
  int lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    std::stringstream ss(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(ss, cell, ',')) {
      char* end = nullptr;
      const double x = std::strtod(cell.c_str(), &end);
      if (end == cell.c_str() || !std::isfinite(x)) {
        throw std::runtime_error(path + ":" + std::to_string(lineno) + ": column " +
                                 std::to_string(v.size() + 1) + ": not a number: '" + cell + "'");
      }
      v.push_back(x);
    }
    if (v.size() != ncols) {
      throw std::runtime_error(path + ":" + std::to_string(lineno) + ": expected " +
                               std::to_string(ncols) + " columns, got " + std::to_string(v.size()));
    }
    double angle = 0.0;
    if (col_a >= 0) {
      angle = v[static_cast<std::size_t>(col_a)] * kPi / 180.0;
      if (first) {
        unwrapped = c.sign() * angle;
      } else {
        unwrapped += c.sign() * std::remainder(angle - prev_angle, 2.0 * kPi);
      }
      prev_angle = angle;
    }
    double t = 0.0;
    if (col_t >= 0) {
      t = v[static_cast<std::size_t>(col_t)];
    } else {
      t = unwrapped / w;
    }
    if (col_a < 0) angle = c.sign() * w * t;
    first = false;
    tr.t_s.push_back(t);
    tr.angle_rad.push_back(angle);
    tr.deviation_um.push_back(v[static_cast<std::size_t>(col_d)]);
  }
  if (tr.t_s.size() < 16) throw std::runtime_error(path + ": fewer than 16 samples");
  return tr;
}

json axis_json(const cc::FitResult& f, std::size_t a, const cc::SimAxis* truth) {
  json j;
  if (truth != nullptr) {
    j["kp_true"] = r5(truth->kp_per_s());
    j["tau_true_ms"] = r5(truth->drive.tau_s * 1000.0);
    j["tau_loop_ms"] = r5(truth->tau_loop_s() * 1000.0);
  }
  j["kp_est"] = r5(f.dynamics[a].kp_per_s);
  j["kp_is_reference"] = a == 0 && f.kp_x_is_reference;
  if (f.tau_estimated) {
    j["tau_est_ms"] = r5(f.dynamics[a].tau_s * 1000.0);
  } else {
    j["tau_est_ms"] = nullptr;
    j["tau_assumed_ms"] = r5(f.dynamics[a].tau_s * 1000.0);
  }
  j["m_mm"] = r5(f.response[a].m_mm);
  j["phi_rad"] = f.response[a].phi_rad;
  if (truth != nullptr) {
    j["kp_err_pct"] = r3(100.0 * (f.dynamics[a].kp_per_s / truth->kp_per_s() - 1.0));
    if (f.tau_estimated) {
      j["tau_err_pct"] = r3(100.0 * (f.dynamics[a].tau_s / truth->tau_loop_s() - 1.0));
    }
  }
  return j;
}

struct Metrics {
  cc::EllipseMetrics servo, total;
};
Metrics metrics_of(const cc::CircleRun& r) {
  return {cc::ellipse_metrics(r.servo_angle_rad, r.servo_deviation_um),
          cc::ellipse_metrics(r.ballbar.angle_rad, r.ballbar.deviation_um)};
}

void write_plot(const std::string& png, const cc::CircleRun& before, const cc::CircleRun& after,
                const std::string& title) {
  double maxdev = 1.0;
  for (double d : before.ballbar.deviation_um) maxdev = std::max(maxdev, std::abs(d));
  for (double d : after.ballbar.deviation_um) maxdev = std::max(maxdev, std::abs(d));
  const double base = 2.0 * maxdev;
  const std::string data = png + ".dat";
  {
    std::ofstream out(data);
    if (!out) throw std::runtime_error(data + ": cannot write plot data");
    auto block = [&](const cc::CircleRun& r) {
      const std::size_t step = std::max<std::size_t>(1, r.ballbar.t_s.size() / 2000);
      for (std::size_t i = 0; i < r.ballbar.t_s.size(); i += step) {
        out << r.ballbar.angle_rad[i] << ' ' << base + r.ballbar.deviation_um[i] << '\n';
      }
      out << "\n\n";
    };
    block(before);
    block(after);
  }
  // Ballbar style: the radius drawn is base + deviation, the tics are labelled in deviation.
  const double step = std::max(1.0, std::round(maxdev / 2.0));
  std::string tics;
  for (int k = -2; k <= 2; ++k) {
    tics += (tics.empty() ? "" : ", ") + std::string("\"") + std::to_string(static_cast<int>(k * step)) +
            " um\" " + std::to_string(base + k * step);
  }
  const std::string script =
      "set terminal pngcairo size 1000,1000\n"
      "set output '" + png + "'\n"
      "set polar\nset size square\nset angles radians\nunset border\nunset xtics\nunset ytics\n"
      "set grid polar pi/6\nset rtics (" + tics + ")\n"
      "set rrange [0:" + std::to_string(base + maxdev * 1.2) + "]\n"
      "set title \"" + title + "\\nradial deviation (ballbar trace, geometry + servo + noise)\"\n"
      "plot " + std::to_string(base) + " w l lc rgb 'gray' dt 2 t 'nominal circle (0 um)', '" + data +
      "' index 0 w l lw 2 lc rgb 'red' t 'before compensation', '" + data +
      "' index 1 w l lw 2 lc rgb 'blue' t 'after (geometry-aware match)'\n";
  FILE* gp = popen("gnuplot", "w");
  if (gp == nullptr) throw std::runtime_error("cannot start gnuplot");
  std::fputs(script.c_str(), gp);
  if (pclose(gp) != 0) throw std::runtime_error("gnuplot failed writing " + png);
  std::remove(data.c_str());
}

int run_import(const std::string& csv, const std::string& csv_ccw, double radius, double feed,
               const std::string& direction, double kp_ref, double kp_cfg_y, double tau_ms,
               const std::optional<control::GeometricErrorModel>& geom) {
  if (!(radius > 0.0) || !(feed > 0.0) || !(kp_ref > 0.0)) {
    std::fputs("contour-sim circle: --ballbar needs --radius-mm, --feed-mm-min and --kp-ref > 0\n",
               stderr);
    return 2;
  }
  if (direction == "both") {
    std::fputs("contour-sim circle: --ballbar takes --direction cw|ccw (give the other direction "
               "with --ballbar-ccw)\n", stderr);
    return 2;
  }
  const cc::Direction d = direction == "ccw" ? cc::Direction::kCcw : cc::Direction::kCw;
  const cc::Circle c = make_circle(radius, feed, d, {0.0, 0.0}, 0.0);
  const cc::BallbarTrace tr = read_ballbar_csv(csv, c);
  const double w = c.omega_rad_s();
  if (!(kp_cfg_y > 0.0)) kp_cfg_y = kp_ref;
  json out;
  out["command"] = "circle";
  out["input"] = csv;
  out["radius_mm"] = radius;
  out["feed_mm_min"] = feed;
  out["omega_rad_s"] = w;
  out["direction"] = direction;
  const auto total = cc::ellipse_metrics(tr.angle_rad, tr.deviation_um);
  out["ellipse_total_um"] = r3(total.ellipse_um);
  out["circularity_um"] = r3(total.circularity_um);
  json methods = json::array();
  auto add = [&](const char* name, const cc::FitResult& f) {
    const cc::GainMatch g = cc::match_y_to_x(f, w);
    json m;
    m["method"] = name;
    m["X"] = axis_json(f, 0, nullptr);
    m["Y"] = axis_json(f, 1, nullptr);
    m["kp_y_target"] = r5(g.kp_target_y_per_s);
    m["kp_y_ratio"] = r5(g.ratio_y);
    m["kp_y_new"] = r5(kp_cfg_y * g.ratio_y);
    m["fit_rms_um"] = r3(f.rms_residual_um);
    m["converged"] = f.converged;
    methods.push_back(m);
  };
  cc::BallbarFitOptions o;
  o.kp_ref_x_per_s = kp_ref;
  o.tau_guess_s = tau_ms / 1000.0;
  if (geom) {
    o.geometry = &*geom;
    add("geometry", cc::fit_ballbar(c, tr, o));
  }
  o.geometry = nullptr;
  add("naive", cc::fit_ballbar(c, tr, o));
  if (!csv_ccw.empty()) {
    cc::Circle c2 = c;
    c2.direction = d == cc::Direction::kCw ? cc::Direction::kCcw : cc::Direction::kCw;
    const cc::BallbarTrace tr2 = read_ballbar_csv(csv_ccw, c2);
    cc::ReversalFitOptions ro;
    ro.kp_ref_x_per_s = kp_ref;
    ro.tau_assumed_s = {tau_ms / 1000.0, tau_ms / 1000.0};
    add("reversal", d == cc::Direction::kCw ? cc::fit_reversal(c, tr, c2, tr2, ro)
                                            : cc::fit_reversal(c2, tr2, c, tr, ro));
  }
  out["methods"] = methods;
  std::cout << out.dump() << std::endl;
  return 0;
}
}  // namespace

int run_circle(int argc, char** argv) {
  CLI::App app{"circular test: servo-gain mismatch apart from geometric errors (seed 003)",
               "contour-sim circle"};
  std::string config_file, geometry_file, plot_file, ballbar_file, ballbar_ccw_file, direction;
  double radius = 0.0, feed = 0.0, noise = -1.0, kp_ref = 0.0, kp_cfg_y = 0.0, tau_ms = 10.0;
  long seed = -1;
  double model_error_pct = 0.0;
  app.add_option("--config", config_file, "circle-test config (config/circle_test.yaml)");
  app.add_option("--radius-mm", radius, "circle radius (overrides the config)");
  app.add_option("--feed-mm-min", feed, "feed (overrides the config)");
  app.add_option("--direction", direction, "cw | ccw | both")
      ->check(CLI::IsMember({"cw", "ccw", "both"}));
  app.add_option("--geometry", geometry_file,
                 "geometric-error YAML (overrides the config; 'none' = no geometric errors)");
  app.add_option("--noise-um", noise, "ballbar noise sigma (overrides the config)");
  app.add_option("--seed", seed, "noise seed (overrides the config)");
  app.add_option("--model-error-pct", model_error_pct,
                 "analyse with the geometric model scaled by (1 + pct/100): a wrong model");
  std::string write_ballbar;
  app.add_option("--write-ballbar", write_ballbar,
                 "write the simulated (before) trace(s) as ballbar CSV: FILE, and FILE.ccw.csv "
                 "for the CCW run with --direction both");
  app.add_option("--plot", plot_file, "polar plot PNG (before / after)");
  app.add_option("--ballbar", ballbar_file,
                 "analyse an imported ballbar CSV (t_s and/or angle_deg, deviation_um) instead");
  app.add_option("--ballbar-ccw", ballbar_ccw_file, "second trace, other direction (reversal)");
  app.add_option("--kp-ref", kp_ref, "--ballbar: configured X loop gain used as reference (1/s)");
  app.add_option("--kp-cfg-y", kp_cfg_y, "--ballbar: configured Y loop gain (default kp-ref)");
  app.add_option("--tau-ms", tau_ms, "--ballbar: start value / reversal assumption for tau");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }

  std::optional<control::GeometricErrorModel> geom;
  if (!ballbar_file.empty()) {
    if (!geometry_file.empty() && geometry_file != "none") {
      geom = config::load_geometry_file(geometry_file);
    }
    return run_import(ballbar_file, ballbar_ccw_file, radius, feed,
                      direction.empty() ? "cw" : direction, kp_ref, kp_cfg_y, tau_ms, geom);
  }
  if (config_file.empty()) {
    std::fputs("contour-sim circle: --config FILE (or --ballbar FILE) is required\n", stderr);
    return 2;
  }
  config::CircleTestConfig cfg = config::load_circle_test_config(config_file);
  if (radius > 0.0) cfg.radius_mm = radius;
  if (feed > 0.0) cfg.feed_mm_min = feed;
  if (!direction.empty()) cfg.direction = direction;
  if (noise >= 0.0) cfg.noise_um = noise;
  if (seed >= 0) cfg.seed = seed;
  if (!geometry_file.empty()) cfg.geometry_file = geometry_file == "none" ? "" : geometry_file;
  if (!cfg.geometry_file.empty()) geom = config::load_geometry_file(cfg.geometry_file);

  std::vector<cc::Direction> dirs;
  if (cfg.direction != "ccw") dirs.push_back(cc::Direction::kCw);
  if (cfg.direction != "cw") dirs.push_back(cc::Direction::kCcw);
  std::vector<cc::Circle> circles;
  for (auto d : dirs) {
    circles.push_back(make_circle(cfg.radius_mm, cfg.feed_mm_min, d, cfg.center_mm, cfg.z_mm));
  }
  const double w = circles[0].omega_rad_s();
  cc::SimOptions so;
  so.geometry = geom ? &*geom : nullptr;
  so.noise_um = cfg.noise_um;
  so.seed = static_cast<std::uint64_t>(cfg.seed);
  so.revolutions = cfg.revolutions;
  auto run_all = [&](const std::array<cc::SimAxis, 2>& axes) {
    std::vector<cc::CircleRun> runs;
    for (std::size_t i = 0; i < circles.size(); ++i) {
      cc::SimOptions o = so;
      o.seed = so.seed + i;
      runs.push_back(cc::simulate_circle(axes, circles[i], o));
    }
    return runs;
  };
  const std::vector<cc::CircleRun> before = run_all(cfg.axes);
  const Metrics mb = metrics_of(before[0]);
  if (!write_ballbar.empty()) {
    for (std::size_t i = 0; i < before.size(); ++i) {
      const std::string name =
          i == 0 ? write_ballbar : write_ballbar + (dirs[i] == cc::Direction::kCcw ? ".ccw.csv" : ".cw.csv");
      std::ofstream csv(name);
      if (!csv) throw std::runtime_error(name + ": cannot write");
      csv.precision(10);
      csv << "t_s,angle_deg,deviation_um\n";
      const auto& b = before[i].ballbar;
      for (std::size_t k = 0; k < b.t_s.size(); ++k) {
        csv << b.t_s[k] << ',' << b.angle_rad[k] * 180.0 / kPi << ',' << b.deviation_um[k] << '\n';
      }
    }
  }
  kp_ref = cfg.axes[0].kp_per_s();

  struct Named {
    std::string name;
    cc::FitResult fit;
  };
  std::vector<Named> fits;
  fits.push_back({"encoder", cc::fit_machine_record(circles[0], before[0].record)});
  cc::BallbarFitOptions bo;
  bo.kp_ref_x_per_s = kp_ref;
  bo.tau_guess_s = cfg.axes[0].tau_loop_s();
  std::optional<control::GeometricErrorModel> model;
  if (geom) model = geom->scaled(1.0 + model_error_pct / 100.0);
  if (geom) {
    bo.geometry = &*model;
    fits.push_back({"geometry", cc::fit_ballbar(circles[0], before[0].ballbar, bo)});
  }
  bo.geometry = nullptr;
  fits.push_back({"naive", cc::fit_ballbar(circles[0], before[0].ballbar, bo)});
  if (circles.size() == 2) {
    cc::ReversalFitOptions ro;
    ro.kp_ref_x_per_s = kp_ref;
    // The reversal cannot see tau (its effects do not flip with direction): assume both axes
    // lag like X's configured loop.
    ro.tau_assumed_s = {cfg.axes[0].tau_loop_s(), cfg.axes[0].tau_loop_s()};
    fits.push_back({"reversal", cc::fit_reversal(circles[0], before[0].ballbar, circles[1],
                                                 before[1].ballbar, ro)});
  }

  json out;
  out["command"] = "circle";
  out["config"] = config_file;
  out["geometry"] = cfg.geometry_file;
  out["radius_mm"] = cfg.radius_mm;
  out["feed_mm_min"] = cfg.feed_mm_min;
  out["omega_rad_s"] = w;
  out["direction"] = cfg.direction;
  out["noise_um"] = cfg.noise_um;
  out["model_error_pct"] = model_error_pct;
  out["kp_ref_source"] = "configured X loop gain (gain_per_s * position_gain)";
  json methods = json::array();
  std::optional<cc::CircleRun> plot_after;
  for (const auto& nf : fits) {
    const cc::GainMatch g = cc::match_y_to_x(nf.fit, w);
    std::array<cc::SimAxis, 2> axes = cfg.axes;
    axes[1].position_gain *= g.ratio_y;
    const std::vector<cc::CircleRun> after = run_all(axes);
    const Metrics ma = metrics_of(after[0]);
    json m;
    m["method"] = nf.name;
    m["X"] = axis_json(nf.fit, 0, &cfg.axes[0]);
    m["Y"] = axis_json(nf.fit, 1, &cfg.axes[1]);
    m["kp_y_target"] = r5(g.kp_target_y_per_s);
    m["kp_y_new"] = r5(axes[1].kp_per_s());
    m["position_gain_y_new"] = r5(axes[1].position_gain);
    m["ellipse_servo_um_before"] = r3(mb.servo.ellipse_um);
    m["ellipse_servo_um_after"] = r3(ma.servo.ellipse_um);
    m["ellipse_servo_45_um_before"] = r3(mb.servo.ellipse_45_um);
    m["ellipse_servo_45_um_after"] = r3(ma.servo.ellipse_45_um);
    m["ellipse_total_um_before"] = r3(mb.total.ellipse_um);
    m["ellipse_total_um_after"] = r3(ma.total.ellipse_um);
    m["circularity_um_before"] = r3(mb.total.circularity_um);
    m["circularity_um_after"] = r3(ma.total.circularity_um);
    m["fit_rms_um"] = r3(nf.fit.rms_residual_um);
    m["converged"] = nf.fit.converged;
    methods.push_back(m);
    if (nf.name == (geom ? "geometry" : "naive")) plot_after = after[0];
  }
  out["methods"] = methods;
  if (!plot_file.empty() && plot_after) {
    std::ostringstream title;
    title << "circle R " << cfg.radius_mm << " mm, F " << cfg.feed_mm_min << " mm/min, "
          << (dirs[0] == cc::Direction::kCw ? "CW" : "CCW") << ": servo ellipse "
          << r3(mb.servo.ellipse_um) << " -> " << r3(metrics_of(*plot_after).servo.ellipse_um)
          << " um";
    write_plot(plot_file, before[0], *plot_after, title.str());
    out["plot"] = plot_file;
  }
  std::cout << out.dump() << std::endl;
  return 0;
}

}  // namespace contour::sim
