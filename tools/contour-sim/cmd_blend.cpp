// contour-sim blend: G-code -> blend planner -> FIR interpolator, with the true path error measured
// independently of the planner (seed 004 reproduction + the guaranteed tolerance of issue 3).
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <string>

#include "config/config.hpp"
#include "config/interpolator_config.hpp"
#include "config/program_config.hpp"
#include "control/blend_planner.hpp"
#include "control/fir_interpolator.hpp"
#include "control/gcode.hpp"
#include "control/path.hpp"
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
  std::string csv, plot, config;
  std::size_t max_corners = 2000;
};

struct Geo {
  control::PathSegment seg;
  int line;
  double s0 = 1e300, s1 = -1e300;  // planner progress range (chord lengths)
};

struct CornerAcc {
  control::CornerReport r;
  double max_err_mm = 0.0;
};

struct Result {
  double duration_s = 0.0;
  double max_path_error_mm = 0.0;
  double max_vertex_error_mm = 0.0;
  double max_feed_mm_min = 0.0;
  double max_programmed_feed_mm_min = 0.0;
  double plan_s = 0.0;
  std::int64_t moves = 0, cycles = 0, verifications = 0;
  std::size_t max_window = 0;
  std::size_t holds = 0;
  nlohmann::json corners = nlohmann::json::array();
  std::size_t corner_count = 0;
  double tolerance_mm = 0.0;
  bool limited = false;
};

// Max distance from the chord [a, b] to the programmed segments: ends, the crossing of the two
// nearest segments (see BlendPlanner::chord_max) and 8 interior points (arcs are not convex sets).
double chord_error(const Vector3d& a, const Vector3d& b, const std::deque<Geo>& geo) {
  auto dist = [&](const Vector3d& x, std::size_t* arg) {
    double best = 1e300;
    for (std::size_t i = 0; i < geo.size(); ++i) {
      const double d = control::distance_to_segment(x, geo[i].seg);
      if (d < best) {
        best = d;
        if (arg) *arg = i;
      }
    }
    return best;
  };
  std::size_t ia = 0, ib = 0;
  double worst = std::max(dist(a, &ia), dist(b, &ib));
  if ((b - a).norm() < 1e-12) return worst;
  for (int k = 1; k < 8; ++k) worst = std::max(worst, dist(a + (b - a) * (k / 8.0), nullptr));
  if (ia != ib) {
    double lo = 0.0, hi = 1.0;
    for (int it = 0; it < 40; ++it) {
      const double mid = 0.5 * (lo + hi);
      const Vector3d x = a + mid * (b - a);
      if (control::distance_to_segment(x, geo[ia].seg) <= control::distance_to_segment(x, geo[ib].seg)) lo = mid; else hi = mid;
    }
    worst = std::max(worst, dist(a + 0.5 * (lo + hi) * (b - a), nullptr));
  }
  return worst;
}

Result run(const Options& o, BlendMethod method, bool floor_rounding, std::ofstream* csv,
           std::vector<Vector3d>* path_out, std::vector<Vector3d>* vertices_out) {
  config::InterpolatorConfig icfg;
  config::ProgramConfig pcfg;
  double period_s = o.period_ms * 1e-3;
  Vector3d vmax = Vector3d::Constant(std::numeric_limits<double>::infinity());
  Vector3d amax = vmax;
  if (!o.config.empty()) {
    const auto cfg = config::load_config_file(o.config);
    icfg = cfg.interpolator;
    pcfg = cfg.program;
    period_s = cfg.machine.period_s;
    for (std::size_t i = 0; i < cfg.machine.axes.size() && i < 3; ++i) {
      vmax[static_cast<int>(i)] = cfg.machine.axes[i].max_velocity_mm_min;
      amax[static_cast<int>(i)] = cfg.machine.axes[i].max_accel_mm_s2;
    }
  }
  control::ProgramSetup setup = config::to_program_setup(pcfg, icfg);
  control::PlannerParams pp;
  pp.period_s = period_s;
  pp.fir_taps = config::fir_taps(o.fir_ms, period_s);
  if (pp.fir_taps < 1) pp.fir_taps = 1;
  pp.fir2_taps = config::fir_taps(o.fir2_ms, period_s);
  pp.floor_rounding = floor_rounding;
  pp.method = method;
  pp.arc_chord_fraction = icfg.arc_chord_fraction;
  pp.default_tolerance_mm = icfg.tolerance_um * 1e-3;
  pp.max_velocity_mm_min = vmax;
  pp.max_accel_mm_s2 = amax;
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
  ip.override_max = icfg.feed_override_max_percent / 100.0;
  ip.capacity = static_cast<std::size_t>(icfg.queue_capacity);
  interp.configure(ip, setup.start_mm);
  const int tail = planner.fir_length() - 1;

  Result r;
  std::deque<Geo> geo;
  std::deque<CornerAcc> corners;
  struct Vtx {
    Vector3d p;
    double s;  // progress at the vertex
    double best = 1e300;
  };
  std::deque<Vtx> vtx;
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
        if (seg.kind == control::SegmentKind::kMotion) {
          for (auto& g : geo)
            if (g.line == seg.line) {
              g.s0 = std::min(g.s0, seg.path_start_mm);
              g.s1 = std::max(g.s1, seg.path_start_mm + seg.length_mm);
            }
          max_feed_seen = std::max(max_feed_seen, seg.feed_mm_min);
        }
      }
      if (interp.free_slots() == 0 || planner.ended()) break;
      if (last_start > static_cast<std::int64_t>(tau) + 3 * tail + 10 && planner.ready() == 0) break;
      if (!std::getline(in, text)) {
        parser.finish(blocks);
      } else {
        parser.parse_line(text, blocks);
      }
      for (const auto& b : blocks) {
        if (b.kind == control::BlockKind::kMotion && (b.seg.end - b.seg.start).norm() > 1e-9) {
          geo.push_back({b.seg, b.line});
          if (vertices_out) vertices_out->push_back(b.seg.end);
        }
        planner.push(b);
      }
      blocks.clear();
    }
    plan_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };

  const double margin = 1.0;
  Vector3d prev = setup.start_mm;
  if (path_out) path_out->push_back(prev);
  control::InterpOutput out;
  std::int64_t cycles = 0;
  const double ovr = o.override_percent / 100.0;
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
    // Geometry window around the current progress.
    const double s = out.path_progress_mm;
    const double reach = margin + 2.0 * max_feed_seen / 60.0 * (tail + 1) * period_s;
    while (geo.size() > 1 && geo.front().s1 < s - reach) geo.pop_front();
    std::deque<Geo> near;
    for (const auto& g : geo) {
      if (g.s0 > s + reach && g.s0 < 1e299) break;
      if (g.s0 > 1e299) continue;
      near.push_back(g);
    }
    if (near.empty()) near = geo;
    const double e_pt = near.empty() ? 0.0 : chord_error(prev, p, near);
    r.max_path_error_mm = std::max(r.max_path_error_mm, e_pt);
    r.max_feed_mm_min = std::max(r.max_feed_mm_min, (p - prev).norm() / period_s * 60.0);
    // Vertices: every programmed block end except the last, two-sided check.
    for (const auto& g : near) {
      if (g.s1 < -1e299) continue;
      bool known = false;
      for (const auto& v : vtx) if ((v.p - g.seg.end).norm() < 1e-12 && std::abs(v.s - g.s1) < 1e-9) known = true;
      if (!known && g.s1 > -1e299) vtx.push_back({g.seg.end, g.s1});
    }
    for (auto& v : vtx) v.best = std::min(v.best, control::distance_point_segment(v.p, prev, p));
    while (!vtx.empty() && vtx.front().s < s - reach) {
      r.max_vertex_error_mm = std::max(r.max_vertex_error_mm, vtx.front().best);
      vtx.pop_front();
    }
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
      // Retire the oldest corner once a newer one is nearer and it is out of reach (bounded).
      while (corners.size() > 1 &&
             (((corners.front().r.vertex_mm - p).norm() > reach &&
               (corners[1].r.vertex_mm - p).norm() < (corners.front().r.vertex_mm - p).norm()) ||
              corners.size() > 256)) {
        auto& c = corners.front();
        if (c.r.line != c.r.prev_line) {
          ++r.corner_count;
          if (r.corners.size() < o.max_corners)
            r.corners.push_back({{"block", c.r.line}, {"prev_block", c.r.prev_line}, {"angle_deg", c.r.angle_deg},
                                 {"overlap_ms", c.r.overlap_cycles * period_s * 1e3}, {"max_error_um", c.max_err_mm * 1e3},
                                 {"model_error_um", c.r.model_error_mm * 1e3}, {"vertex", {c.r.vertex_mm.x(), c.r.vertex_mm.y(), c.r.vertex_mm.z()}}});
        }
        corners.pop_front();
      }
    }
    if (csv) *csv << static_cast<double>(cycles) * period_s << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << s << ',' << out.line << ',' << e_pt * 1e3 << '\n';
    if (path_out) path_out->push_back(p);
    prev = p;
    if (st == control::InterpStatus::kDone) break;
    if (st == control::InterpStatus::kStarved && planner.ended() && planner.ready() == 0) break;
  }
  // Remaining vertices (the final point is exact; its distance is 0).
  for (const auto& v : vtx) r.max_vertex_error_mm = std::max(r.max_vertex_error_mm, v.best);
  for (auto& c : corners) {
    if (c.r.line == c.r.prev_line) continue;
    ++r.corner_count;
    if (r.corners.size() < o.max_corners)
      r.corners.push_back({{"block", c.r.line}, {"prev_block", c.r.prev_line}, {"angle_deg", c.r.angle_deg},
                           {"overlap_ms", c.r.overlap_cycles * period_s * 1e3}, {"max_error_um", c.max_err_mm * 1e3},
                           {"model_error_um", c.r.model_error_mm * 1e3}, {"vertex", {c.r.vertex_mm.x(), c.r.vertex_mm.y(), c.r.vertex_mm.z()}}});
  }
  r.cycles = cycles;
  r.duration_s = out.plan_time_cycles * period_s;
  r.plan_s = plan_s;
  r.moves = planner.stats().moves;
  r.verifications = planner.stats().verifications;
  r.max_window = planner.stats().max_window;
  r.max_programmed_feed_mm_min = max_feed_seen;
  return r;
}

nlohmann::json summary(const Result& r) {
  return {{"duration_s", r.duration_s}, {"max_path_error_um", r.max_path_error_mm * 1e3},
          {"max_vertex_error_um", r.max_vertex_error_mm * 1e3}, {"max_feed_mm_min_reached", r.max_feed_mm_min},
          {"planning_s", r.plan_s}, {"moves", r.moves}};
}

}  // namespace

int run_blend(int argc, char** argv) {
  CLI::App app{"FIR interpolation and corner blending of a part program (seed 004)", "contour-sim blend"};
  Options o;
  app.add_option("--program", o.program, "RS274/NGC part program")->required();
  app.add_option("--tolerance-um", o.tolerance_um, "blend tolerance (overrides G64 P), um");
  app.add_option("--fir-ms", o.fir_ms, "FIR acc/dec time t_A, ms (t_A/T + 1 taps)");
  app.add_option("--fir2-ms", o.fir2_ms, "second FIR stage (jerk limit), ms; 0 = off");
  app.add_option("--mode", o.mode, "g61 | g64 | limited (overrides the program); default: as programmed")
      ->check(CLI::IsMember({"g61", "g64", "limited"}));
  app.add_option("--method", o.method, "limited-blend search: true | exhaustive | paper")
      ->check(CLI::IsMember({"true", "exhaustive", "paper"}));
  app.add_flag("--paper", o.paper, "the paper's own method and conventions (two-block incremental search, floor-rounded sample counts)");
  app.add_option("--rounding", o.rounding, "block sample counts: ceil | floor")->check(CLI::IsMember({"ceil", "floor"}));
  app.add_flag("--compare", o.compare, "also run the paper's method and the exhaustive search; report both");
  app.add_option("--period-ms", o.period_ms, "interpolation period, ms");
  app.add_option("--override-percent", o.override_percent, "feed override, %");
  app.add_option("--config", o.config, "contourd YAML (interpolator:, program:, machine axis limits)");
  app.add_option("--csv", o.csv, "write t_s,x,y,z,progress_mm,line,error_um per cycle");
  app.add_option("--plot", o.plot, "PNG of programmed vs interpolated path (gnuplot)");
  app.add_option("--max-corners", o.max_corners, "corners listed in the JSON");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  const BlendMethod method = o.paper ? BlendMethod::kPaper
                             : o.method == "paper" ? BlendMethod::kPaper
                             : o.method == "exhaustive" ? BlendMethod::kExhaustive : BlendMethod::kTrue;
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
    j["method"] = method == BlendMethod::kPaper ? "paper" : (method == BlendMethod::kExhaustive ? "exhaustive" : "true");
    j["rounding"] = floor_rounding ? "floor" : "ceil";
    j["fir_taps"] = config::fir_taps(o.fir_ms, o.period_ms * 1e-3);
    j["verifications"] = r.verifications;
    j["max_window_moves"] = r.max_window;
    j["holds_resumed"] = r.holds;
    j["max_programmed_feed_mm_min"] = r.max_programmed_feed_mm_min;
    if (r.plan_s > 0) j["planning_moves_per_s"] = static_cast<double>(r.moves) / r.plan_s;
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
    if (method != BlendMethod::kPaper && (o.mode == "limited" || o.mode.empty()) && o.tolerance_um &&
        (r.max_path_error_mm > *o.tolerance_um * 1e-3 + 1e-9 || r.max_vertex_error_mm > *o.tolerance_um * 1e-3 + 1e-9))
      return 1;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "contour-sim blend: " << e.what() << '\n';
    std::cout << nlohmann::json{{"error", e.what()}}.dump() << std::endl;
    return 2;
  }
}

}  // namespace contour::sim
