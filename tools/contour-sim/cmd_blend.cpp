// contour-sim blend: G-code -> blend planner -> FIR interpolator, with the true path error, the
// vertex error and the axis accelerations measured independently of the planner
// (control/path_meter.hpp: the same meter measures a trajectory from elsewhere with --measure,
// e.g. LinuxCNC's commanded position in tools/bench/tp_compare.sh).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <fstream>
#include <iostream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>

#include "config/config.hpp"
#include "config/interpolator_config.hpp"
#include "config/program_config.hpp"
#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"
#include "control/gcode_machine.hpp"
#include "control/path.hpp"
#include "control/path_meter.hpp"
#include "tools/contour-sim/commands.hpp"

namespace contour::sim {
namespace {

using control::BlendMethod;
using control::BlendMode;
using Eigen::Vector3d;

struct Options {
  std::string program;
  std::optional<double> tolerance_um;
  double fir_ms = 100.0;
  double fir2_ms = 0.0;
  std::string mode;  // empty: as programmed
  std::string method = "true";
  std::string rounding;  // empty: ceil, or floor with --paper
  bool paper = false;
  bool compare = false;
  double period_ms = 1.0;
  double override_percent = 100.0;
  std::string csv, plot, config, measure;
  std::size_t max_corners = 2000;
  double reach_mm = 0.0;
  double lookahead_mm = 0.0;
  std::string var_file, tbl_file;            // LinuxCNC .var / .tbl (mm), as contour-gcode-diff
  std::vector<std::string> subroutine_dirs;  // added to program.subroutine_path
};

struct CornerAcc {
  control::CornerReport r;
  double max_err_mm = 0.0;
};

struct Result {
  double duration_s = 0.0;   // plan time until the end (interpolator done)
  control::PathMeterResult m;
  bool nan = false;
  double max_feed_mm_min = 0.0;
  double max_programmed_feed_mm_min = 0.0;
  double plan_s = 0.0;
  std::int64_t moves = 0, cycles = 0, verifications = 0, segments = 0;
  control::PlannerStats stats;
  std::size_t holds = 0;
  nlohmann::json corners = nlohmann::json::array();
  std::size_t corner_count = 0;
};

struct Machine {
  config::InterpolatorConfig icfg;
  config::ProgramConfig pcfg;
  double period_s = 1e-3;
  Vector3d vmax = Vector3d::Constant(std::numeric_limits<double>::infinity());
  Vector3d amax = Vector3d::Constant(std::numeric_limits<double>::infinity());
};

Machine load_machine(const Options& o) {
  Machine m;
  m.period_s = o.period_ms * 1e-3;
  if (!o.config.empty()) {
    const auto cfg = config::load_config_file(o.config);
    m.icfg = cfg.interpolator;
    m.pcfg = cfg.program;
    m.period_s = cfg.machine.period_s;
    for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
      m.vmax[static_cast<int>(i)] = cfg.machine.axes[i].max_velocity_mm_min;
      m.amax[static_cast<int>(i)] = cfg.machine.axes[i].max_accel_mm_s2;
    }
  }
  for (const auto& d : o.subroutine_dirs) m.pcfg.subroutine_path.push_back(d);
  return m;
}

std::string read_text(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot open");
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// The parser's set-up: the config's program section, then --var/--tbl (the machine
// contour-gcode-diff runs both interpreters on) and --subroutines.
control::ProgramSetup program_setup(const Options& o, const Machine& mc) {
  control::ProgramSetup setup = config::to_program_setup(mc.pcfg, mc.icfg);
  if (!o.var_file.empty() || !o.tbl_file.empty()) {
    control::MachineContext machine;
    if (!o.var_file.empty())
      control::apply_var_file(machine, control::parse_var_file(read_text(o.var_file), o.var_file));
    if (!o.tbl_file.empty()) machine.tools = control::parse_tool_table(read_text(o.tbl_file), o.tbl_file);
    setup.machine = machine;
  }
  return setup;
}

// Path length the meter looks around its cursor: the path the FIR's window spans at the highest
// speed (how far a blend can cut across), at least 2 mm.
double reach_for(const Options& o, const Machine& mc, const control::ProgramSetup& setup, int taps) {
  if (o.reach_mm > 0.0) return o.reach_mm;
  double v = std::min(setup.rapid_mm_min, mc.vmax.maxCoeff());
  if (!std::isfinite(v)) v = setup.rapid_mm_min;
  return std::max(2.0, v / 60.0 * taps * mc.period_s);
}

nlohmann::json corner_json(const CornerAcc& c, double period_s) {
  return {{"block", c.r.line},
          {"prev_block", c.r.prev_line},
          {"angle_deg", c.r.angle_deg},
          {"overlap_ms", c.r.overlap_cycles * period_s * 1e3},
          {"corner_speed_mm_min", c.r.corner_speed_mm_min},
          {"max_error_um", c.max_err_mm * 1e3},
          {"model_error_um", c.r.model_error_mm * 1e3},
          {"vertex", {c.r.vertex_mm.x(), c.r.vertex_mm.y(), c.r.vertex_mm.z()}}};
}

Result run(const Options& o, BlendMethod method, bool floor_rounding, std::ofstream* csv,
           std::vector<Vector3d>* path_out, std::vector<Vector3d>* vertices_out) {
  const Machine mc = load_machine(o);
  control::ProgramSetup setup = program_setup(o, mc);
  const double period_s = mc.period_s;
  control::PlannerParams pp;
  pp.period_s = period_s;
  pp.fir_taps = std::max(1, config::fir_taps(o.fir_ms, period_s));
  pp.fir2_taps = config::fir_taps(o.fir2_ms, period_s);
  pp.floor_rounding = floor_rounding;
  pp.method = method;
  pp.arc_chord_fraction = mc.icfg.arc_chord_fraction;
  pp.default_tolerance_mm = mc.icfg.tolerance_um * 1e-3;
  pp.max_velocity_mm_min = mc.vmax;
  pp.max_accel_mm_s2 = mc.amax;
  pp.rapid_mm_min = setup.rapid_mm_min;
  pp.lookahead_mm = o.lookahead_mm;
  if (!o.mode.empty()) pp.force_mode = config::parse_blend_mode(o.mode);
  if (o.tolerance_um) {
    pp.force_tolerance_mm = *o.tolerance_um * 1e-3;
    pp.default_tolerance_mm = *o.tolerance_um * 1e-3;
  }
  std::ifstream in(o.program);
  if (!in) throw std::runtime_error(o.program + ": cannot open");
  control::GcodeParser parser(setup, o.program);
  control::BlendPlanner planner(pp, setup.start_mm);
  control::Interpolator interp;
  control::InterpolatorParams ip;
  ip.fir_taps = pp.fir_taps;
  ip.fir2_taps = pp.fir2_taps;
  ip.period_s = period_s;
  ip.override_max = mc.icfg.feed_override_max_percent / 100.0;
  ip.capacity = static_cast<std::size_t>(mc.icfg.queue_capacity);
  interp.configure(ip, setup.start_mm);
  const int tail = planner.fir_length() - 1;
  // The meter's cursor stays on the pass within the tolerance being checked (a later pass crossing
  // it cannot take it early).
  control::PathMeter meter(period_s, reach_for(o, mc, setup, planner.fir_length()), 10,
                           std::max(1e-3, pp.default_tolerance_mm));

  Result r;
  std::deque<CornerAcc> corners;
  planner.on_corner([&](const control::CornerReport& c) { corners.push_back({c, 0.0}); });

  std::vector<control::Block> blocks;
  std::string text;
  std::int64_t last_start = -1;
  double max_feed_seen = 0.0;
  double plan_s = 0.0;
  double tau = 0.0;
  auto refill = [&]() {
    const auto t0 = std::chrono::steady_clock::now();
    control::PlannedSegment seg;
    while (true) {
      while (interp.free_slots() > 0 && planner.pop(seg)) {
        interp.push(seg);
        last_start = std::max(last_start, seg.start_cycle);
        if (seg.kind == control::SegmentKind::kMotion)
          max_feed_seen = std::max(max_feed_seen, seg.feed_mm_min);
      }
      if (interp.free_slots() == 0 || planner.ended()) break;
      if (last_start > static_cast<std::int64_t>(tau) + 3 * tail + 10 && planner.ready() == 0) break;
      if (!std::getline(in, text)) {
        parser.finish(blocks);
      } else {
        parser.parse_line(text, blocks);
      }
      for (const auto& b : blocks) {
        if (b.kind == control::BlockKind::kMotion) {
          meter.add_segment(b.seg, b.line);
          if (vertices_out && control::segment_length_mm(b.seg) > 1e-9)
            vertices_out->push_back(b.seg.end);
        }
        planner.push(b);
      }
      blocks.clear();
    }
    plan_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };

  Vector3d prev = setup.start_mm;
  if (path_out) path_out->push_back(prev);
  meter.add_sample(prev);
  control::InterpOutput out;
  std::int64_t cycles = 0;
  const double ovr = o.override_percent / 100.0;
  const double reach = reach_for(o, mc, setup, planner.fir_length());
  auto retire = [&](const CornerAcc& c) {
    if (c.r.line == c.r.prev_line && c.r.angle_deg < 1e-9) return;
    ++r.corner_count;
    if (r.corners.size() < o.max_corners) r.corners.push_back(corner_json(c, period_s));
  };
  while (true) {
    refill();
    const auto st = interp.step(ovr, out);
    tau = out.plan_time_cycles;
    ++cycles;
    if (st == control::InterpStatus::kHolding) {
      ++r.holds;
      interp.resume();
      continue;
    }
    if (st == control::InterpStatus::kSpindleWait) {  // no spindle here: at speed at once
      interp.resume();
      continue;
    }
    const Vector3d p = out.position_mm;
    if (!p.allFinite()) r.nan = true;
    meter.add_sample(p);
    const double e_pt = meter.last_error_mm();
    r.max_feed_mm_min = std::max(r.max_feed_mm_min, (p - prev).norm() / period_s * 60.0);
    // Corner attribution: nearest pending corner vertex.
    if (!corners.empty()) {
      CornerAcc* best = nullptr;
      double bd = 1e300;
      for (std::size_t ci = 0; ci < corners.size() && ci < 64; ++ci) {
        auto& c = corners[ci];
        const double d = (c.r.vertex_mm - p).norm();
        if (d < bd) {
          bd = d;
          best = &c;
        }
      }
      if (best && bd < reach) best->max_err_mm = std::max(best->max_err_mm, e_pt);
      while (corners.size() > 1 &&
             (((corners.front().r.vertex_mm - p).norm() > reach &&
               (corners[1].r.vertex_mm - p).norm() < (corners.front().r.vertex_mm - p).norm()) ||
              corners.size() > 256)) {
        retire(corners.front());
        corners.pop_front();
      }
    }
    if (csv) {
      *csv << static_cast<double>(cycles) * period_s << ',' << p.x() << ',' << p.y() << ','
           << p.z() << ',' << out.path_progress_mm << ',' << out.line << ',' << e_pt * 1e3 << '\n';
    }
    if (path_out) path_out->push_back(p);
    prev = p;
    if (st == control::InterpStatus::kDone) break;
    if (st == control::InterpStatus::kStarved && planner.ended() && planner.ready() == 0) break;
  }
  meter.finish();
  for (auto& c : corners) retire(c);
  r.m = meter.result();
  r.cycles = cycles;
  r.duration_s = out.plan_time_cycles * period_s;
  r.plan_s = plan_s;
  r.stats = planner.stats();
  r.moves = r.stats.moves;
  r.verifications = r.stats.verifications;
  r.max_programmed_feed_mm_min = max_feed_seen;
  return r;
}

nlohmann::json meter_json(const control::PathMeterResult& m) {
  auto v3 = [](const Vector3d& v) { return nlohmann::json{v.x(), v.y(), v.z()}; };
  return {{"motion_s", m.duration_s},
          {"max_path_error_um", m.max_path_error_mm * 1e3},
          {"max_vertex_error_um", m.max_vertex_error_mm * 1e3},
          {"vertices_checked", m.vertices},
          {"worst_point", v3(m.worst_point_mm)},
          {"worst_line", m.worst_line},
          {"worst_sample", m.worst_sample},
          {"worst_vertex", v3(m.worst_vertex_mm)},
          {"worst_vertex_line", m.worst_vertex_line},
          {"peak_accel_10ms_mm_s2", v3(m.peak_accel_mm_s2)},
          {"peak_accel_mm_s2", v3(m.peak_accel_raw_mm_s2)},
          {"peak_speed_mm_min", m.peak_speed_mm_s * 60.0},
          {"path_length_mm", m.length_mm}};
}

nlohmann::json summary(const Result& r) {
  nlohmann::json j = meter_json(r.m);
  j["duration_s"] = r.duration_s;
  j["max_feed_mm_min_reached"] = r.max_feed_mm_min;
  j["planning_s"] = r.plan_s;
  j["moves"] = r.moves;
  j["nan"] = r.nan;
  return j;
}

// --measure: a trajectory from elsewhere, one sample per period ("x y z ..." or "x,y,z,...";
// lines that do not start with a number are skipped), against the program's path.
int run_measure(const Options& o) {
  const Machine mc = load_machine(o);
  control::ProgramSetup setup = program_setup(o, mc);
  control::GcodeParser parser(setup, o.program);
  std::ifstream in(o.program);
  if (!in) throw std::runtime_error(o.program + ": cannot open");
  control::PathMeter meter(mc.period_s,
                           reach_for(o, mc, setup, config::fir_taps(o.fir_ms, mc.period_s) + 1), 10,
                           std::max(1e-3, o.tolerance_um.value_or(mc.icfg.tolerance_um) * 1e-3));
  std::vector<control::Block> blocks;
  std::string text;
  while (!parser.ended()) {
    if (std::getline(in, text)) {
      parser.parse_line(text, blocks);
    } else {
      parser.finish(blocks);
    }
    for (const auto& b : blocks)
      if (b.kind == control::BlockKind::kMotion) meter.add_segment(b.seg, b.line);
    blocks.clear();
  }
  std::ifstream tr(o.measure);
  if (!tr) throw std::runtime_error(o.measure + ": cannot open");
  bool nan = false;
  while (std::getline(tr, text)) {
    for (char& ch : text)
      if (ch == ',' || ch == '\t') ch = ' ';
    std::istringstream ls(text);
    double x = 0, y = 0, z = 0;
    if (!(ls >> x >> y >> z)) continue;
    const Vector3d p(x, y, z);
    if (!p.allFinite()) nan = true;
    meter.add_sample(p);
  }
  meter.finish();
  nlohmann::json j = meter_json(meter.result());
  j["nan"] = nan;
  j["samples"] = meter.result().samples;
  std::cout << j.dump() << std::endl;
  return 0;
}

}  // namespace

int run_blend(int argc, char** argv) {
  CLI::App app{"FIR interpolation and corner blending of a part program (seed 004)", "contour-sim blend"};
  Options o;
  app.add_option("--program", o.program, "RS274/NGC part program")->required();
  app.add_option("--tolerance-um", o.tolerance_um, "blend tolerance (overrides G64 P), um");
  app.add_option("--fir-ms", o.fir_ms,
                 "FIR acc/dec time t_A, ms (t_A/T + 1 taps); default: interpolator.fir_ms of --config, "
                 "else 100");
  app.add_option("--fir2-ms", o.fir2_ms,
                 "second FIR stage (jerk limit), ms; 0 = off; default: interpolator.fir2_ms of --config");
  app.add_option("--mode", o.mode, "g61 | g64 | limited (overrides the program); default: as programmed")
      ->check(CLI::IsMember({"g61", "g64", "limited"}));
  app.add_option("--method", o.method,
                 "blend planner: true (seed 004 overlap per corner, verified on the true path) | "
                 "lookahead (experimental look-ahead velocity plan, verified) | exhaustive | paper")
      ->check(CLI::IsMember({"true", "lookahead", "exhaustive", "paper"}));
  app.add_flag("--paper", o.paper, "the paper's own method and conventions (two-block incremental search, floor-rounded sample counts)");
  app.add_option("--rounding", o.rounding, "block sample counts: ceil | floor")->check(CLI::IsMember({"ceil", "floor"}));
  app.add_flag("--compare", o.compare, "also run the paper's method and the exhaustive search; report both");
  app.add_option("--period-ms", o.period_ms, "interpolation period, ms");
  app.add_option("--override-percent", o.override_percent, "feed override, %");
  app.add_option("--config", o.config, "contourd YAML (interpolator:, program:, machine axis limits)");
  app.add_option("--csv", o.csv, "write t_s,x,y,z,progress_mm,line,error_um per cycle");
  app.add_option("--plot", o.plot, "PNG of programmed vs interpolated path (gnuplot)");
  app.add_option("--max-corners", o.max_corners, "corners listed in the JSON");
  app.add_option("--measure", o.measure,
                 "measure this trajectory (one 'x y z ...' row per period, e.g. LinuxCNC's "
                 "commanded position) against the program instead of planning it");
  app.add_option("--reach-mm", o.reach_mm, "path length the meter searches around its cursor (0: auto)");
  app.add_option("--var", o.var_file, "LinuxCNC parameter file (mm) the program starts from");
  app.add_option("--tbl", o.tbl_file, "LinuxCNC tool table (mm)");
  app.add_option("--subroutines", o.subroutine_dirs, "subroutine directory (o<name> call), repeatable");
  app.add_option("--lookahead-mm", o.lookahead_mm, "look-ahead planner: path held ahead (0: auto)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  // The FIR times of --config (interpolator.fir_ms / fir2_ms, what contourd runs) unless given
  // on the command line; without --config the seed-004 default of 100 ms.
  if (!o.config.empty() && (app.count("--fir-ms") == 0 || app.count("--fir2-ms") == 0)) {
    try {
      const Machine mc = load_machine(o);
      if (app.count("--fir-ms") == 0) o.fir_ms = mc.icfg.fir_ms;
      if (app.count("--fir2-ms") == 0) o.fir2_ms = mc.icfg.fir2_ms;
    } catch (const std::exception&) {
      // reported with file and line by the run below
    }
  }
  if (!o.measure.empty()) {
    try {
      return run_measure(o);
    } catch (const std::exception& e) {
      std::cerr << "contour-sim blend: " << e.what() << '\n';
      std::cout << nlohmann::json{{"error", e.what()}}.dump() << std::endl;
      return 2;
    }
  }
  const BlendMethod method = o.paper ? BlendMethod::kPaper
                             : o.method == "paper" ? BlendMethod::kPaper
                             : o.method == "exhaustive" ? BlendMethod::kExhaustive
                             : o.method == "lookahead" ? BlendMethod::kLookahead : BlendMethod::kTrue;
  const bool floor_rounding = o.rounding.empty() ? method == BlendMethod::kPaper : o.rounding == "floor";
  nlohmann::json j;
  try {
    std::ofstream csv;
    if (!o.csv.empty()) {
      csv.open(o.csv);
      csv << "t_s,x_mm,y_mm,z_mm,progress_mm,line,error_um\n";
    }
    std::vector<Vector3d> path, verts;
    const bool want_plot = !o.plot.empty();
    Result r = run(o, method, floor_rounding, o.csv.empty() ? nullptr : &csv, want_plot ? &path : nullptr,
                   want_plot ? &verts : nullptr);
    j = summary(r);
    j["corners"] = r.corners;
    j["corner_count"] = r.corner_count;
    j["method"] = method == BlendMethod::kPaper ? "paper"
                  : method == BlendMethod::kExhaustive ? "exhaustive"
                  : method == BlendMethod::kLookahead ? "lookahead" : "true";
    j["rounding"] = floor_rounding ? "floor" : "ceil";
    j["fir_taps"] = config::fir_taps(o.fir_ms, o.period_ms * 1e-3);
    j["verifications"] = r.verifications;
    j["max_window_moves"] = r.stats.max_window;
    j["segments"] = r.stats.segments;
    j["plans"] = r.stats.plans;
    j["tolerance_repairs"] = r.stats.tolerance_repairs;
    j["accel_repairs"] = r.stats.accel_repairs;
    j["fallbacks"] = r.stats.fallbacks;
    j["holds_resumed"] = r.holds;
    j["max_programmed_feed_mm_min"] = r.max_programmed_feed_mm_min;
    if (r.plan_s > 0) {
      j["planning_moves_per_s"] = static_cast<double>(r.moves) / r.plan_s;
      j["planning_realtime_factor"] = r.duration_s / r.plan_s;
    }
    // Axis limits (from --config): the raw per-period acceleration of the output must hold them.
    const Machine mc = load_machine(o);
    bool accel_ok = true;
    for (int i = 0; i < 3; ++i)
      if (std::isfinite(mc.amax[i]) && r.m.peak_accel_raw_mm_s2[i] > mc.amax[i] * (1.0 + 1e-6)) accel_ok = false;
    j["accel_within_limits"] = accel_ok;
    if (o.compare) {
      const Result rp = run(o, BlendMethod::kPaper, true, nullptr, nullptr, nullptr);
      const Result re = run(o, BlendMethod::kExhaustive, floor_rounding, nullptr, nullptr, nullptr);
      j["paper"] = summary(rp);
      j["paper"]["corners"] = rp.corners;
      j["exhaustive"] = summary(re);
      j["time_ratio_vs_exhaustive"] = r.duration_s / re.duration_s;
    }
    if (want_plot) {
      const std::string dat = o.plot + ".path.dat", vdat = o.plot + ".prog.dat";
      {
        std::ofstream f(dat);
        for (const auto& p : path) f << p.x() << ' ' << p.y() << '\n';
        std::ofstream g(vdat);
        Vector3d s0 = Vector3d::Zero();
        g << s0.x() << ' ' << s0.y() << '\n';
        for (const auto& p : verts) g << p.x() << ' ' << p.y() << '\n';
      }
      const std::string script = "set terminal pngcairo size 1200,800\nset output '" + o.plot +
                                 "'\nset size ratio -1\nset grid\nset xlabel 'X (mm)'\nset ylabel 'Y (mm)'\n"
                                 "set title 'contour-sim blend: " + o.program + "' noenhanced\nplot '" + vdat +
                                 "' w lp lw 1 pt 7 ps 0.6 title 'programmed', '" + dat +
                                 "' w l lw 2 title 'interpolated (1 ms samples)'\n";
      FILE* gp = popen("gnuplot", "w");
      if (gp != nullptr) {
        std::fputs(script.c_str(), gp);
        pclose(gp);
      }
      std::remove(dat.c_str());
      std::remove(vdat.c_str());
    }
    std::cout << j.dump() << std::endl;
    if (r.nan) return 1;
    if ((method == BlendMethod::kTrue || method == BlendMethod::kLookahead) && !accel_ok) return 1;
    if (method != BlendMethod::kPaper && (o.mode == "limited" || o.mode.empty()) && o.tolerance_um &&
        (r.m.max_path_error_mm > *o.tolerance_um * 1e-3 + 1e-9 ||
         r.m.max_vertex_error_mm > *o.tolerance_um * 1e-3 + 1e-9))
      return 1;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "contour-sim blend: " << e.what() << '\n';
    std::cout << nlohmann::json{{"error", e.what()}}.dump() << std::endl;
    return 2;
  }
}

}  // namespace contour::sim
