// contour-sim contour: seed 000 reproduction. A parametric curve (YAML) or a G-code program is
// interpolated at constant feed without acc/dec, followed by three simulated feed drives
// (control/feed_drive.hpp, quantised to the BLU, bus transport delay) under P, PID or the
// cross-coupled controller (CCC) with the three-point-circle contour-error model; the true
// contour error is the distance to the programmed path (control/true_contour_error.hpp).
//
// Last stdout line: one JSON object (controller, feed_mm_min, samples, max_contour_error_um,
// rms_contour_error_um, max_model_error_blu, end_position_error_um, stable,
// command_chatter_rms_mm_s / command_chatter_max_mm_s (per axis: the cycle-to-cycle change of the
// velocity command K u, issue 16), ...). With --compare
// it holds one object per controller under "runs" plus the P/CCC and PID/CCC ratios.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "config/control_config.hpp"
#include "config/curve_file.hpp"
#include "control/chatter_monitor.hpp"
#include "control/contour_error.hpp"
#include "control/gcode.hpp"
#include "control/reference_path.hpp"
#include "control/servo_controller.hpp"
#include "control/true_contour_error.hpp"
#include "tools/contour-sim/commands.hpp"

namespace contour::sim {

namespace {

namespace fs = std::filesystem;
using control::Vec3;

struct Program {
  std::string name;
  std::unique_ptr<config::CurveFile> curve;       // parametric
  std::vector<control::PathSegment> segments;     // G-code
  std::vector<Vec3> vertices;                     // G-code reference polyline (arcs chorded)
};

Program load_program(const std::string& path) {
  Program p;
  p.name = fs::path(path).stem().string();
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".yaml" || ext == ".yml") {
    p.curve = std::make_unique<config::CurveFile>(config::load_curve_file(path));
    return p;
  }
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  control::GcodeParser parser(control::ProgramSetup{}, path);
  std::vector<control::Block> blocks;
  std::string line;
  while (!parser.ended() && std::getline(in, line)) parser.parse_line(line, blocks);
  parser.finish(blocks);
  for (const auto& b : blocks) {
    if (b.kind != control::BlockKind::kMotion) continue;
    if ((b.seg.end - b.seg.start).norm() < 1e-12 && b.seg.kind == control::PathSegment::Kind::kLine) {
      continue;
    }
    p.segments.push_back(b.seg);
  }
  if (p.segments.empty()) throw std::runtime_error(path + ": no motion blocks");
  p.vertices.push_back(p.segments.front().start);
  for (const auto& s : p.segments) {
    // Arcs become chords within 0.01 BLU (5 nm) so the reference polyline is the path.
    control::chord_points(s, 5e-6, p.vertices);
  }
  return p;
}

// A contourd telemetry CSV's reference (rx_mm, ry_mm, rz_mm), from the first READY/RUNNING row
// (state >= 2) on: one point per cycle, velocity by differences.
std::vector<control::ReferencePoint> load_reference_csv(const std::string& path, double period_s) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path + ": empty");
  std::vector<std::string> head;
  {
    std::stringstream ss(line);
    std::string f;
    while (std::getline(ss, f, ',')) head.push_back(f);
  }
  auto col = [&](const char* name) {
    for (std::size_t i = 0; i < head.size(); ++i) {
      if (head[i] == name) return i;
    }
    throw std::runtime_error(path + ": no column " + name);
  };
  const std::size_t cs = col("state"), cx = col("rx_mm"), cy = col("ry_mm"), cz = col("rz_mm");
  std::vector<control::ReferencePoint> ref;
  int row = 1;
  while (std::getline(in, line)) {
    ++row;
    std::vector<std::string> c;
    std::stringstream ss(line);
    std::string f;
    while (std::getline(ss, f, ',')) c.push_back(f);
    if (c.size() <= std::max({cs, cx, cy, cz})) {
      throw std::runtime_error(path + ":" + std::to_string(row) + ": short row");
    }
    try {
      if (std::stoi(c[cs]) < 2) continue;
      control::ReferencePoint p;
      p.r_mm = Vec3(std::stod(c[cx]), std::stod(c[cy]), std::stod(c[cz]));
      if (!ref.empty()) p.v_mm_s = (p.r_mm - ref.back().r_mm) / period_s;
      ref.push_back(p);
    } catch (const std::exception&) {
      throw std::runtime_error(path + ":" + std::to_string(row) + ": not a number");
    }
  }
  if (ref.size() < 3) throw std::runtime_error(path + ": fewer than 3 reference rows");
  return ref;
}

struct Sample {
  double t_s;
  Vec3 r, p;
  double contour_um;      // true, NaN when beyond the end
  double model_um;        // |eps_model|
  double model_err_blu;   // | |eps| - true distance of the same point |
};

struct RunResult {
  std::string controller;
  long samples = 0;
  long path_samples = 0;
  double max_contour_um = 0.0;
  double rms_contour_um = 0.0;
  double max_model_err_blu = 0.0;
  double end_position_err_um = 0.0;
  double end_overshoot_um = 0.0;
  double max_tracking_err_um = 0.0;
  bool stable = true;
  long lag_overflows = 0;
  control::ChatterFigure chatter;  // velocity command K u, cycle-to-cycle change (issue 16)
  std::vector<Sample> trace;
};

struct RunSetup {
  const config::Config* cfg = nullptr;
  const Program* prog = nullptr;
  const std::vector<control::ReferencePoint>* ref = nullptr;
  const control::CurveDistance* curve_dist = nullptr;
  const control::SegmentPathDistance* seg_dist = nullptr;
  int delay_cycles = 1;        // the controller's (Smith predictor) delay
  int plant_delay_cycles = 1;  // the drives' real delay (differs to show a mismatch)
  double settle_s = 1.0;
  double blu_mm = 0.0005;
  bool quantise = true;
  bool keep_trace = false;
  // The daemon's control stage (daemon/servo_loop.cpp control_step): v = K u, |v| <= v_max,
  // v within v_actual +- a_max tau; the drives get the clamped v. command_applied: the controller
  // is told (ServoController::command_applied, the wiring proposed for the daemon).
  bool daemon_clamps = false;
  bool command_applied = false;
};

RunResult run_one(const RunSetup& s, config::ControllerType type) {
  const config::Config& cfg = *s.cfg;
  const auto& ref = *s.ref;
  const int axes = 3;
  std::array<control::FeedDriveParams, 3> dp{};
  std::array<control::FeedDrive, 3> drive{};
  for (std::size_t i = 0; i < 3; ++i) {
    dp[i] = cfg.machine.axes[i].drive;
    dp[i].period_s = cfg.machine.period_s;
    dp[i].delay_cycles = s.delay_cycles;
    if (!s.quantise) dp[i].blu_mm = 0.0;
    control::FeedDriveParams plant = dp[i];
    plant.delay_cycles = s.plant_delay_cycles;
    drive[i].configure(plant);
    drive[i].reset(ref.front().r_mm[static_cast<Eigen::Index>(i)]);
  }
  control::ServoController ctrl(
      config::make_servo_params(cfg.control, type, dp, axes, cfg.machine.period_s, s.delay_cycles));
  control::ContourErrorModel model(config::make_model_params(cfg.control));
  control::ChatterMeter chatter(axes);

  RunResult res;
  res.controller = config::controller_type_name(type);
  const long n = static_cast<long>(ref.size());
  const long total = n + static_cast<long>(std::lround(s.settle_s / cfg.machine.period_s));
  const Vec3 end = ref.back().r_mm;
  double hint = std::numeric_limits<double>::quiet_NaN();
  double hint_hat = hint;
  double sum2 = 0.0;
  long count = 0;
  Vec3 last_min = Vec3::Constant(1e300), last_max = Vec3::Constant(-1e300);
  for (long k = 0; k < total; ++k) {
    const auto& rp = ref[static_cast<std::size_t>(std::min(k, n - 1))];
    const Vec3 r = rp.r_mm;
    const Vec3 v = k < n ? rp.v_mm_s : Vec3::Zero();
    Vec3 p_true, p_meas;
    for (std::size_t i = 0; i < 3; ++i) {
      p_true[static_cast<Eigen::Index>(i)] = drive[i].position_mm();
      p_meas[static_cast<Eigen::Index>(i)] = drive[i].measured_mm();
    }
    const Vec3 p_hat = ctrl.predict(p_meas);
    model.push_reference(r);
    const control::ContourErrorResult ce = model.update(p_hat);
    if (ce.status == control::ContourStatus::kLagOverflow) ++res.lag_overflows;
    Vec3 u;
    ctrl.update(r, p_hat, ce, v, u);
    // The velocity command a velocity-mode drive would get (v = K u, mm/s).
    std::array<double, 3> v_cmd{};
    for (std::size_t i = 0; i < 3; ++i) {
      const auto e = static_cast<Eigen::Index>(i);
      double vi = dp[i].gain_per_s * u[e];
      if (s.daemon_clamps) {
        const auto& ax = cfg.machine.axes[i];
        const double vmax = ax.max_velocity_mm_min / 60.0;
        vi = std::clamp(vi, -vmax, vmax);
        const double dv = ax.max_accel_mm_s2 * ax.drive.tau_s;
        const double va = drive[i].velocity_mm_s();
        if (dv > 0.0) vi = std::clamp(vi, va - dv, va + dv);
        u[e] = vi / dp[i].gain_per_s;
      }
      v_cmd[i] = vi;
    }
    if (s.command_applied) ctrl.command_applied(u);
    for (std::size_t i = 0; i < 3; ++i) drive[i].step(u[static_cast<Eigen::Index>(i)]);
    chatter.add(v_cmd);

    if (!p_true.allFinite() || p_true.norm() > 1e6) {
      res.stable = false;
      res.samples = k + 1;
      break;
    }
    // True contour error of the actual tool, and of the point the model was given.
    control::TrueError te, te_hat;
    if (s.curve_dist != nullptr) {
      te = s.curve_dist->query(p_true, hint);
      te_hat = s.curve_dist->query(p_hat, hint_hat);
      hint = te.u;
      hint_hat = te_hat.u;
    } else {
      te = s.seg_dist->query(p_true);
      te_hat = s.seg_dist->query(p_hat);
    }
    res.max_tracking_err_um = std::max(res.max_tracking_err_um, (r - p_true).norm() * 1e3);
    Sample smp{static_cast<double>(k) * cfg.machine.period_s, r, p_true,
               std::numeric_limits<double>::quiet_NaN(), ce.eps.norm() * 1e3,
               std::numeric_limits<double>::quiet_NaN()};
    if (te.beyond_end) {
      res.end_overshoot_um = std::max(res.end_overshoot_um, te.distance_mm * 1e3);
    } else {
      const double um = te.distance_mm * 1e3;
      smp.contour_um = um;
      res.max_contour_um = std::max(res.max_contour_um, um);
      sum2 += um * um;
      ++count;
    }
    if (!te_hat.beyond_end) {
      smp.model_err_blu = std::abs(ce.eps.norm() - te_hat.distance_mm) / s.blu_mm;
      res.max_model_err_blu = std::max(res.max_model_err_blu, smp.model_err_blu);
    }
    if (total - k <= 100) {
      last_min = last_min.cwiseMin(p_true);
      last_max = last_max.cwiseMax(p_true);
    }
    if (s.keep_trace) res.trace.push_back(smp);
    res.samples = k + 1;
  }
  res.path_samples = n;
  res.chatter = chatter.figure();
  res.rms_contour_um = count > 0 ? std::sqrt(sum2 / static_cast<double>(count)) : 0.0;
  Vec3 p_end;
  for (std::size_t i = 0; i < 3; ++i) p_end[static_cast<Eigen::Index>(i)] = drive[i].position_mm();
  res.end_position_err_um = (p_end - end).norm() * 1e3;
  // Stable: finite, came to rest (< 1 um of motion over the last 100 ms) near the end point.
  if (res.stable) {
    res.stable = std::isfinite(res.end_position_err_um) && res.end_position_err_um < 1000.0 &&
                 (last_max - last_min).maxCoeff() < 1e-3;
  }
  return res;
}

nlohmann::json to_json(const RunResult& r) {
  nlohmann::json j;
  j["controller"] = r.controller;
  j["samples"] = r.samples;
  j["path_samples"] = r.path_samples;
  j["max_contour_error_um"] = r.max_contour_um;
  j["rms_contour_error_um"] = r.rms_contour_um;
  j["max_model_error_blu"] = r.max_model_err_blu;
  j["end_position_error_um"] = r.end_position_err_um;
  j["end_overshoot_um"] = r.end_overshoot_um;
  j["max_tracking_error_um"] = r.max_tracking_err_um;
  j["lag_overflows"] = r.lag_overflows;
  j["stable"] = r.stable;
  // Issue 16 chatter figure: RMS and largest cycle-to-cycle change of the velocity command K u.
  j["command_chatter_rms_mm_s"] = std::vector<double>(r.chatter.rms_mm_s.begin(),
                                                      r.chatter.rms_mm_s.end());
  j["command_chatter_max_mm_s"] = std::vector<double>(r.chatter.max_mm_s.begin(),
                                                      r.chatter.max_mm_s.end());
  return j;
}

std::string default_config_path() {
  if (fs::exists("config/table1.yaml")) return "config/table1.yaml";
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    // <build>/tools/contour-sim -> <source>/config via the build tree's parent (in-tree builds
    // under build/<name>), else give the relative name so the error message says what is missing.
    for (fs::path d = exe.parent_path(); !d.empty() && d != d.root_path(); d = d.parent_path()) {
      if (fs::exists(d / "config/table1.yaml")) return (d / "config/table1.yaml").string();
    }
  }
  return "config/table1.yaml";
}

void write_csv(const std::string& file, const RunResult& r) {
  std::ofstream out(file);
  if (!out) throw std::runtime_error(file + ": cannot write");
  out << "t_s,rx_mm,ry_mm,rz_mm,px_mm,py_mm,pz_mm,contour_error_um,model_error_um,"
         "model_minus_true_blu\n";
  out.precision(10);
  for (const auto& s : r.trace) {
    out << s.t_s << ',' << s.r.x() << ',' << s.r.y() << ',' << s.r.z() << ',' << s.p.x() << ','
        << s.p.y() << ',' << s.p.z() << ',' << s.contour_um << ',' << s.model_um << ','
        << s.model_err_blu << '\n';
  }
}

void write_plot(const std::string& png, const std::vector<RunResult>& runs, const std::string& title) {
  std::vector<std::string> data_files;
  for (const auto& r : runs) {
    char tmpl[] = "/tmp/contour-sim-XXXXXX";
    const int fd = mkstemp(tmpl);
    if (fd < 0) throw std::runtime_error("cannot create a temporary file");
    close(fd);
    std::ofstream out(tmpl);
    for (const auto& s : r.trace) {
      // Blank line = gap (tool past the end point: tracking, not contour error).
      if (std::isfinite(s.contour_um)) {
        out << s.t_s << ' ' << s.contour_um << '\n';
      } else {
        out << '\n';
      }
    }
    data_files.emplace_back(tmpl);
  }
  std::ostringstream gp;
  gp << "set terminal pngcairo size 1200,800\nset output '" << png << "'\n"
     << "set title '" << title << "'\nset xlabel 'time (s)'\nset ylabel 'contour error (um)'\n"
     << "set grid\n";
  if (runs.size() > 1) gp << "set logscale y\n";
  gp << "plot ";
  for (std::size_t i = 0; i < runs.size(); ++i) {
    gp << (i ? ", " : "") << "'" << data_files[i] << "' using 1:2 with lines lw 2 title '"
       << runs[i].controller << " (max " << std::round(runs[i].max_contour_um * 100.0) / 100.0
       << " um)'";
  }
  gp << "\n";
  FILE* g = popen("gnuplot", "w");
  if (g == nullptr) throw std::runtime_error("cannot run gnuplot");
  const std::string script = gp.str();
  std::fwrite(script.data(), 1, script.size(), g);
  const int rc = pclose(g);
  for (const auto& f : data_files) std::remove(f.c_str());
  if (rc != 0) throw std::runtime_error("gnuplot failed writing " + png);
}

}  // namespace

int run_contour(int argc, char** argv) {
  CLI::App app{"Seed 000: contour-error model and P / PID / cross-coupled control", "contour"};
  std::string path, controller = "ccc", config_path, csv, plot, model_name, window_rule;
  double feed_mm_min = 4000.0;
  int delay_cycles = -1, plant_delay_cycles = -1;
  std::string reference_csv;
  bool daemon_clamps = false, command_applied = false;
  double settle_s = 1.0, model_blend_ms = -1.0, lowpass_ms = -1.0;
  std::string same_geometry;
  bool compare = false, no_quantise = false, no_delay_comp = false, no_integrator_fix = false;
  app.add_option("--path", path, "program: .ngc G-code or .yaml parametric curve")->required();
  app.add_option("--controller", controller, "p | pid | ccc")
      ->check(CLI::IsMember({"p", "pid", "ccc"}));
  app.add_option("--feed-mm-min", feed_mm_min, "path feed, mm/min (constant, no acc/dec)")
      ->check(CLI::Range(1.0, 1e6));
  app.add_option("--config", config_path, "machine + control config (default config/table1.yaml)");
  app.add_option("--delay-cycles", delay_cycles,
                 "command transport delay in cycles (default: the config's drives, 1 = CANopen)")
      ->check(CLI::Range(0, control::FeedDrive::kMaxDelay));
  app.add_option("--plant-delay-cycles", plant_delay_cycles,
                 "the drives' real transport delay when it differs from the controller's "
                 "(--delay-cycles); default: the same")
      ->check(CLI::Range(0, control::FeedDrive::kMaxDelay));
  app.add_option("--model-blend-ms", model_blend_ms,
                 "override control.derivative.model_blend_ms (0 = off)")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--lowpass-ms", lowpass_ms, "override control.derivative.lowpass_ms (0 = off)")
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--same-geometry", same_geometry, "override control.derivative.same_geometry")
      ->check(CLI::IsMember({"never", "ahead", "always"}));
  app.add_option("--reference-csv", reference_csv,
                 "replay a recorded reference (contourd telemetry CSV, e.g. from `contour-sim "
                 "run --csv`: rx_mm, ry_mm, rz_mm from READY on) instead of interpolating --path; "
                 "--path still gives the programmed path for the contour error");
  app.add_flag("--daemon-clamps", daemon_clamps,
               "apply the daemon's velocity and acceleration clamps to the command");
  app.add_flag("--command-applied", command_applied,
               "tell the controller the clamped command (ServoController::command_applied)");
  app.add_option("--csv", csv, "write the time series of the chosen controller");
  app.add_option("--plot", plot, "PNG of contour error vs time (gnuplot)");
  app.add_flag("--compare", compare, "run P, PID and CCC; plot them together");
  app.add_option("--settle-s", settle_s, "time simulated after the reference stops, s")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--model", model_name, "override control.model: circle | nearest | linear")
      ->check(CLI::IsMember({"circle", "nearest", "linear"}));
  app.add_option("--window-rule", window_rule, "override control.window_rule")
      ->check(CLI::IsMember({"multi_step", "literal"}));
  app.add_flag("--no-quantise", no_quantise, "measure the exact position (no BLU quantisation)");
  app.add_flag("--no-delay-compensation", no_delay_comp, "disable the Smith predictor");
  app.add_flag("--no-integrator-fix", no_integrator_fix,
               "keep the coupling integrator's along-path component (the paper's structure)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }

  if (config_path.empty()) config_path = default_config_path();
  config::Config cfg = config::load_config_file(config_path);
  if (cfg.machine.axes.size() != 3) {
    throw std::runtime_error(config_path + ": contour needs three axes (X, Y, Z)");
  }
  if (!model_name.empty()) {
    cfg.control.model = model_name == "nearest"  ? control::ModelKind::kNearestPoint
                        : model_name == "linear" ? control::ModelKind::kLinear
                                                 : control::ModelKind::kCircle;
  }
  if (!window_rule.empty()) {
    cfg.control.window_rule =
        window_rule == "literal" ? control::WindowRule::kLiteral : control::WindowRule::kMultiStep;
  }
  if (no_delay_comp) cfg.control.delay_compensation = false;
  if (no_integrator_fix) cfg.control.coupling.remove_tangential_integral = false;
  if (delay_cycles < 0) delay_cycles = cfg.machine.axes[0].drive.delay_cycles;
  if (plant_delay_cycles < 0) plant_delay_cycles = delay_cycles;
  if (model_blend_ms >= 0.0) cfg.control.derivative.model_blend_s = model_blend_ms / 1000.0;
  if (lowpass_ms >= 0.0) cfg.control.derivative.lowpass_s = lowpass_ms / 1000.0;
  if (!same_geometry.empty()) {
    cfg.control.derivative.same_geometry = same_geometry == "never" ? control::SameGeometry::kNever
                                           : same_geometry == "always"
                                               ? control::SameGeometry::kAlways
                                               : control::SameGeometry::kAhead;
  }

  const Program prog = load_program(path);
  const double feed_mm_s = feed_mm_min / 60.0;
  std::vector<control::ReferencePoint> ref;
  std::unique_ptr<control::CurveDistance> cd;
  std::unique_ptr<control::SegmentPathDistance> sd;
  if (prog.curve) {
    ref = control::sample_curve(*prog.curve->curve, feed_mm_s, cfg.machine.period_s);
    cd = std::make_unique<control::CurveDistance>(*prog.curve->curve, 20000);
  } else {
    ref = control::sample_polyline(prog.vertices, feed_mm_s, cfg.machine.period_s);
    sd = std::make_unique<control::SegmentPathDistance>(prog.segments);
  }
  if (!reference_csv.empty()) ref = load_reference_csv(reference_csv, cfg.machine.period_s);

  RunSetup setup;
  setup.cfg = &cfg;
  setup.prog = &prog;
  setup.ref = &ref;
  setup.curve_dist = cd.get();
  setup.seg_dist = sd.get();
  setup.delay_cycles = delay_cycles;
  setup.plant_delay_cycles = plant_delay_cycles;
  setup.daemon_clamps = daemon_clamps || command_applied;
  setup.command_applied = command_applied;
  setup.settle_s = settle_s;
  setup.blu_mm = 1.0 / cfg.machine.axes[0].counts_per_mm;
  setup.quantise = !no_quantise;
  setup.keep_trace = !csv.empty() || !plot.empty();

  const config::ControllerType chosen = config::parse_controller_type(controller);
  std::vector<RunResult> runs;
  if (compare) {
    for (auto t : {config::ControllerType::kP, config::ControllerType::kPid,
                   config::ControllerType::kCcc}) {
      runs.push_back(run_one(setup, t));
    }
  } else {
    runs.push_back(run_one(setup, chosen));
  }
  const RunResult* main_run = &runs.back();
  for (const auto& r : runs) {
    if (r.controller == controller) main_run = &r;
  }
  if (!csv.empty()) write_csv(csv, *main_run);
  if (!plot.empty()) {
    std::ostringstream title;
    title << prog.name << ", F" << feed_mm_min << " mm/min, delay " << delay_cycles << " cycle(s)";
    if (compare) {
      write_plot(plot, runs, title.str());
    } else {
      write_plot(plot, {*main_run}, title.str());
    }
  }

  // Stability margin of the coupled loop (normal direction) for the X drive.
  control::FeedDriveParams xd = cfg.machine.axes[0].drive;
  xd.period_s = cfg.machine.period_s;
  control::AxisGains xg;
  xg.kp = cfg.control.kp[0];
  const control::LoopMargin lm =
      control::loop_margin(xd, xg, cfg.control.coupling, delay_cycles,
                           cfg.control.delay_compensation);

  // Issue 16 stability check of the chosen controller against the drives as simulated here
  // (plant delay = --plant-delay-cycles): linear margins + closed-loop simulation at rest.
  control::LoopPlant plant = config::make_loop_plant(cfg.machine);
  for (int i = 0; i < plant.axes; ++i) {
    plant.axis[static_cast<std::size_t>(i)].delay_cycles = plant_delay_cycles;
    if (no_quantise) plant.axis[static_cast<std::size_t>(i)].blu_mm = 0.0;
  }
  std::array<control::FeedDriveParams, 3> sdp{};
  for (std::size_t i = 0; i < 3; ++i) {
    sdp[i] = cfg.machine.axes[i].drive;
    sdp[i].period_s = cfg.machine.period_s;
  }
  const control::StabilityVerdict verdict = control::check_loop_stability(
      config::make_servo_params(cfg.control, chosen, sdp, 3, cfg.machine.period_s, delay_cycles),
      plant);

  nlohmann::json j = to_json(*main_run);
  j["stability_check"] = {{"stable", verdict.stable},
                          {"reason", verdict.reason},
                          {"spectral_radius", verdict.spectral_radius},
                          {"rest_peak_to_peak_um", verdict.rest_peak_to_peak_um},
                          {"rest_clamps_per_s", verdict.rest_clamps_per_s}};
  j["path"] = path;
  j["feed_mm_min"] = feed_mm_min;
  j["delay_cycles"] = delay_cycles;
  j["plant_delay_cycles"] = plant_delay_cycles;
  j["derivative_model_blend_ms"] = cfg.control.derivative.model_blend_s * 1000.0;
  j["derivative_lowpass_ms"] = cfg.control.derivative.lowpass_s * 1000.0;
  j["delay_compensation"] = cfg.control.delay_compensation;
  j["coupled_loop_spectral_radius"] = lm.spectral_radius;
  j["coupled_loop_gain_margin"] = lm.gain_margin;
  bool ok = main_run->stable;
  if (compare) {
    nlohmann::json arr = nlohmann::json::array();
    for (const auto& r : runs) {
      arr.push_back(to_json(r));
      ok = ok && r.stable;
    }
    j["runs"] = arr;
    const double ccc = runs[2].max_contour_um;
    j["ratio_p_ccc"] = ccc > 0.0 ? runs[0].max_contour_um / ccc : 0.0;
    j["ratio_pid_ccc"] = ccc > 0.0 ? runs[1].max_contour_um / ccc : 0.0;
  }
  std::cout << j.dump() << std::endl;
  return ok ? 0 : 1;
}

}  // namespace contour::sim
