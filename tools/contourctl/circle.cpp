#include "tools/contourctl/circle.hpp"

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <thread>

#include "control/circle_test.hpp"
#include "tools/common/gnuplot.hpp"
#include "tools/contourctl/plot.hpp"

namespace contour::ctl {

using nlohmann::json;
namespace cc = contour::control::circle;
namespace fs = std::filesystem;

namespace {

constexpr double kPi = 3.14159265358979323846;

std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.6f", v);
  return b;
}

// Restores the gains saved at the start unless released (after --apply or a clean restore).
class GainsGuard {
 public:
  GainsGuard(Client& c, json saved) : c_(c), saved_(std::move(saved)) {}
  ~GainsGuard() {
    if (!armed_) return;
    try {
      restore();
    } catch (const std::exception& e) {
      std::cerr << "contourctl: circle-test: could not restore the gains: " << e.what()
                << "\n  set them again with: contourctl gains set kp=" << saved_["kp"].dump()
                << " coupling=" << (saved_.value("coupling", false) ? "true" : "false") << '\n';
    }
  }
  GainsGuard(const GainsGuard&) = delete;
  GainsGuard& operator=(const GainsGuard&) = delete;
  void restore() {
    armed_ = false;
    c_.call(
        {{"cmd", "gains"},
         {"set", {{"kp", saved_["kp"]}, {"ff", saved_["ff"]}, {"coupling", saved_["coupling"]}}}});
  }
  void release() { armed_ = false; }

 private:
  Client& c_;
  json saved_;
  bool armed_ = true;
};

json wait_job(Client& c, std::uint64_t job, double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    const json st = c.call({{"cmd", "status"}});
    if (job_ended(st, job)) break;
    if (std::chrono::steady_clock::now() > until)
      throw ErrorReply("circle-test: timed out waiting for the circle");
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return c.call({{"cmd", "result"}, {"job", job}});
}

struct DirectionRun {
  std::string name;
  cc::Circle circle;
  cc::FitResult fit;
  std::vector<double> angle_rad, dev_um;  // radial deviation of the actual path (polar plot)
  json result;
  std::string csv;  // the recording, where the daemon says it wrote it
};

DirectionRun run_direction(Client& c, const CircleTestOptions& o, bool cw,
                           const std::string& csv_name, const Eigen::Vector3d& start) {
  DirectionRun d;
  d.name = cw ? "CW" : "CCW";
  d.circle.radius_mm = o.radius_mm;
  d.circle.feed_mm_min = o.feed_mm_min;
  d.circle.direction = cw ? cc::Direction::kCw : cc::Direction::kCcw;
  // Start at the current position, centre R to the -X side (the paper's eq 1 layout).
  d.circle.center_mm = Eigen::Vector2d(start.x() - o.radius_mm, start.y());
  d.circle.z_mm = start.z();
  std::ostringstream prog;
  prog << "(contourctl circle-test " << d.name << " R" << o.radius_mm << " F" << o.feed_mm_min
       << ")\n"
       << "G21 G90 G17\n"
       << (cw ? "G2" : "G3") << " X" << num(start.x()) << " Y" << num(start.y()) << " I"
       << num(-o.radius_mm) << " J0 P" << o.turns << " F" << num(o.feed_mm_min) << "\nM2\n";
  // The daemon writes into its own telemetry directory and names the file (under systemd its /tmp
  // is not ours): read the CSV from the path in the reply.
  const std::string csv_path =
      c.call({{"cmd", "record"}, {"action", "start"}, {"name", csv_name}}).at("path").get<std::string>();
  d.csv = csv_path;
  json run;
  try {
    run = c.call({{"cmd", "run"}, {"program", prog.str()}, {"name", "circle-test " + d.name}});
  } catch (...) {
    try {
      c.call({{"cmd", "record"}, {"action", "stop"}});
    } catch (const std::exception&) {
    }
    throw;
  }
  const auto job = run.at("job").get<std::uint64_t>();
  const double rev_s = 2.0 * kPi * o.radius_mm / (o.feed_mm_min / 60.0);
  d.result = wait_job(c, job, 60.0 + 4.0 * rev_s * o.turns);
  c.call({{"cmd", "record"}, {"action", "stop"}});
  if (!d.result.value("completed", false)) {
    throw ErrorReply("circle-test " + d.name + ": the circle did not complete (state " +
                     d.result.value("state", std::string("?")) + ", faults " +
                     d.result["faults"].dump() + ")");
  }
  const TelemetryCsv csv = read_telemetry_csv(csv_path);
  const auto &jobc = csv.at("job"), &prog_mm = csv.at("progress_mm"), &t = csv.at("t_s");
  const auto &rx = csv.at("rx_mm"), &ry = csv.at("ry_mm"), &px = csv.at("px_mm"),
             &py = csv.at("py_mm");
  const double len = 2.0 * kPi * o.radius_mm;
  cc::MachineRecord rec;
  for (std::size_t i = 0; i < csv.rows; ++i) {
    if (jobc[i] != static_cast<double>(job)) continue;
    if (prog_mm[i] < len || prog_mm[i] > (o.turns - 0.5) * len) continue;
    rec.t_s.push_back(t[i]);
    rec.command_mm[0].push_back(rx[i]);
    rec.command_mm[1].push_back(ry[i]);
    rec.encoder_mm[0].push_back(px[i]);
    rec.encoder_mm[1].push_back(py[i]);
    d.angle_rad.push_back(
        std::atan2(py[i] - d.circle.center_mm.y(), px[i] - d.circle.center_mm.x()));
    d.dev_um.push_back(
        1e3 *
        (std::hypot(px[i] - d.circle.center_mm.x(), py[i] - d.circle.center_mm.y()) - o.radius_mm));
  }
  if (rec.t_s.size() < 100) {
    throw std::runtime_error(csv_path + ": only " + std::to_string(rec.t_s.size()) +
                             " samples in the analysis window (job " + std::to_string(job) + ")");
  }
  // The planner may run the arc slower than F (the interpolator's radial-error and acceleration
  // limits: 27.1 of 33.3 mm/s at R 10 mm, F 2000 on config/sim.yaml), and eq 2's sine fit needs
  // the true angular speed: the slope of the reference's unwrapped angle over the window.
  {
    const std::size_t n = rec.t_s.size();
    double st = 0.0, sa = 0.0, stt = 0.0, sta = 0.0, prev = 0.0, unwrap = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double a = std::atan2(rec.command_mm[1][i] - d.circle.center_mm.y(),
                                  rec.command_mm[0][i] - d.circle.center_mm.x());
      if (i > 0) unwrap += std::remainder(a - prev, 2.0 * kPi);
      prev = a;
      const double tt = rec.t_s[i] - rec.t_s[0];
      st += tt;
      sa += unwrap;
      stt += tt * tt;
      sta += tt * unwrap;
    }
    const double dn = static_cast<double>(n);
    const double w = std::abs((dn * sta - st * sa) / (dn * stt - st * st));
    if (!(w > 0.0) || !std::isfinite(w))
      throw std::runtime_error(csv_path + ": the reference does not turn");
    d.circle.feed_mm_min = w * o.radius_mm * 60.0;
  }
  d.fit = cc::fit_machine_record(d.circle, rec);
  if (o.delay_compensation && o.delay_cycles > 0) {
    // With the Smith predictor (control.delay_compensation, the default) the position loop acts
    // on the predicted, delay-free position: the delay sits OUTSIDE the loop, as a pure lag of
    // the encoder record behind the command. Eq 3 assumes a loop without it; fitting it anyway
    // gave k 67.2 1/s, tau 29.4 ms on config/sim.yaml (true: 72 1/s, 30.5 ms) = a 72 1/s loop
    // seen through a 1 ms delay. Remove the lag w d T from each phase before eq 3.
    const double dt = (rec.t_s.back() - rec.t_s.front()) / static_cast<double>(rec.t_s.size() - 1);
    const double period_s = o.period_s > 0.0 ? o.period_s : dt;
    for (std::size_t a = 0; a < 2; ++a) {
      d.fit.response[a].phi_rad += d.circle.omega_rad_s() * o.delay_cycles * period_s;
      d.fit.dynamics[a] =
          cc::dynamics_from_response(d.fit.response[a], d.circle.radius_mm, d.circle.omega_rad_s());
    }
  }
  return d;
}

void polar_plot(const std::string& png, const std::vector<DirectionRun>& before,
                const std::vector<DirectionRun>& after, const CircleTestOptions& o) {
  double maxdev = 1.0;
  for (const auto* v : {&before, &after}) {
    for (const auto& r : *v) {
      for (double x : r.dev_um) maxdev = std::max(maxdev, std::abs(x));
    }
  }
  const double base = 2.0 * maxdev;
  namespace gp = contour::tools::gnuplot;
  gp::TempData data(png);
  std::string plots = "plot " + std::to_string(base) +
                      " w l lc rgb 'gray' dt 2 t 'nominal radius (0 {/Symbol m}m)'";
  int index = 0;
  const char* colors[] = {"#d62728", "#ff7f0e", "#1f77b4", "#2ca02c"};
  for (const auto* v : {&before, &after}) {
    for (const auto& r : *v) {
      const std::size_t step = std::max<std::size_t>(1, r.dev_um.size() / 3000);
      for (std::size_t i = 0; i < r.dev_um.size(); i += step) {
        data.out() << r.angle_rad[i] << ' ' << base + r.dev_um[i] << '\n';
      }
      data.out() << "\n\n";
      plots += ", " + gp::quote(data.path()) + " index " + std::to_string(index) +
               " w l lw 2 lc rgb '" + colors[(v == &before ? 0 : 2) + (r.name == "CW" ? 0 : 1)] +
               "' t '" + r.name + (v == &before ? " before" : " after matched gains") + "'";
      ++index;
    }
  }
  data.close();
  const double step = std::max(1.0, std::round(maxdev / 2.0));
  std::string tics;
  for (int k = -2; k <= 2; ++k) {
    tics += (tics.empty() ? "" : ", ") + std::string("\"") +
            std::to_string(static_cast<int>(k * step)) + " um\" " + std::to_string(base + k * step);
  }
  std::ostringstream title;
  title
      << "Circle test on the machine: R " << o.radius_mm << " mm, F " << o.feed_mm_min
      << " mm/min programmed, " << std::lround(before.front().circle.feed_mm_min)
      << " mm/min run\\nradial deviation of the encoder path (servo lag + interpolator FIR shrink)";
  const std::string script =
      gp::png_preamble(png, 1000, 1000) +
      "set polar\nset size square\nset angles radians\n"
      "unset border\nunset xtics\nunset ytics\nunset grid\nset grid polar pi/6\nset rtics (" +
      tics + ")\nset rrange [0:" + std::to_string(base + maxdev * 1.2) + "]\nset title " +
      gp::dquote(title.str()) + "\nset key bottom right\n" + plots + "\n";
  gp::run(script, png);
}

json axis_json(const cc::FitResult& f, std::size_t a, double kp_ctl, double delay_s) {
  const auto& dyn = f.dynamics[a];
  return {{"loop_gain_per_s", dyn.kp_per_s},
          {"loop_tau_ms", dyn.tau_s * 1e3},
          {"drive_gain_per_s", kp_ctl > 0.0 ? dyn.kp_per_s / kp_ctl : 0.0},
          {"drive_tau_ms", (dyn.tau_s - delay_s) * 1e3},
          {"amplitude_ratio", f.response[a].m_mm},
          {"phase_deg", f.response[a].phi_rad * 180.0 / kPi}};
}

}  // namespace

json run_circle_test(Client& c, const CircleTestOptions& o) {
  if (!(o.radius_mm > 0.0) || !(o.feed_mm_min > 0.0))
    throw std::invalid_argument("circle-test: radius and feed must be > 0");
  if (o.turns < 2)
    throw std::invalid_argument(
        "circle-test: --turns must be >= 2 (the first revolution is skipped)");
  const json st = c.call({{"cmd", "status"}});
  if (st.value("state", std::string()) != "READY" || st.value("jogging", false)) {
    throw ErrorReply("circle-test needs state READY and no jog in progress (state " +
                     st.value("state", std::string("?")) + ")");
  }
  const json saved = c.call({{"cmd", "gains"}});
  if (saved.value("law", std::string()) != "p") {
    throw ErrorReply("circle-test: eq 3 models a P position loop; the daemon runs law '" +
                     saved.value("law", std::string()) + "' (use controller p or ccc)");
  }
  const Eigen::Vector3d start(st["ref_mm"][0].get<double>(), st["ref_mm"][1].get<double>(),
                              st.at("ref_mm").size() > 2 ? st["ref_mm"][2].get<double>() : 0.0);
  const std::string tag = "contourctl-circle-" + std::to_string(::getpid()) + "-";

  GainsGuard guard(c, saved);
  json zero_ff = json::array();
  for (std::size_t i = 0; i < saved["kp"].size(); ++i) zero_ff.push_back(0.0);
  c.call({{"cmd", "gains"}, {"set", {{"coupling", false}, {"ff", zero_ff}}}});

  const double period_s = 1e-3;  // refined from the CSV below
  std::vector<DirectionRun> runs;
  std::vector<bool> dirs;
  if (o.cw) dirs.push_back(true);
  if (o.ccw) dirs.push_back(false);
  for (bool cw : dirs) {
    const std::string csv = tag + (cw ? "cw" : "ccw") + ".csv";
    if (o.verbose)
      std::cerr << "circle-test: running " << (cw ? "CW" : "CCW") << ", " << o.turns
                << " turns...\n";
    runs.push_back(run_direction(c, o, cw, csv, start));
  }
  // Sample period from the recording (t_s column).
  double t_period = period_s;
  {
    const TelemetryCsv csv = read_telemetry_csv(runs.front().csv);
    const auto& t = csv.at("t_s");
    if (csv.rows > 10) t_period = (t[csv.rows - 1] - t[0]) / static_cast<double>(csv.rows - 1);
  }
  // What eq 3's tau holds beyond the drive lag: the hold's T/2, plus the transport delay when it is
  // inside the loop (no delay compensation).
  const double delay_s = ((o.delay_compensation ? 0 : o.delay_cycles) + 0.5) * t_period;
  double w = 0.0;
  for (const auto& r : runs) w += r.circle.omega_rad_s() / static_cast<double>(runs.size());
  json report;
  report["radius_mm"] = o.radius_mm;
  report["feed_mm_min"] = o.feed_mm_min;
  report["omega_rad_s"] = w;
  report["sample_period_ms"] = t_period * 1e3;
  report["assumed_delay_cycles"] = o.delay_cycles;
  report["assumed_delay_compensation"] = o.delay_compensation;
  report["gains_during_test"] = {{"kp", saved["kp"]}, {"coupling", false}, {"ff", zero_ff}};
  // Combined estimate: mean over the directions (the encoder record holds no geometric error,
  // so CW and CCW should agree; their difference is reported as a consistency check).
  cc::FitResult mean = runs.front().fit;
  for (std::size_t a = 0; a < 2; ++a) {
    double kp = 0.0, tau = 0.0, m = 0.0, phi = 0.0;
    for (const auto& r : runs) {
      kp += r.fit.dynamics[a].kp_per_s;
      tau += r.fit.dynamics[a].tau_s;
      m += r.fit.response[a].m_mm;
      phi += r.fit.response[a].phi_rad;
    }
    const auto n = static_cast<double>(runs.size());
    mean.dynamics[a] = {kp / n, tau / n};
    mean.response[a] = {m / n, phi / n};
  }
  json per_dir = json::array();
  for (const auto& r : runs) {
    json pd{{"direction", r.name},
            {"effective_feed_mm_min", r.circle.feed_mm_min},
            {"omega_rad_s", r.circle.omega_rad_s()},
            {"max_contour_error_um", r.result.value("max_contour_error_um", 0.0)},
            {"rms_residual_um", r.fit.rms_residual_um}};
    for (std::size_t a = 0; a < 2; ++a) {
      pd[a == 0 ? "X" : "Y"] = axis_json(r.fit, a, saved["kp"][a].get<double>(), delay_s);
    }
    per_dir.push_back(pd);
  }
  report["runs"] = per_dir;
  for (std::size_t a = 0; a < 2; ++a) {
    report[a == 0 ? "X" : "Y"] = axis_json(mean, a, saved["kp"][a].get<double>(), delay_s);
  }
  const cc::GainMatch match = cc::match_y_to_x(mean, w);
  json proposed = saved["kp"];
  proposed[1] = saved["kp"][1].get<double>() * match.ratio_y;
  report["match"] = {{"rule", "eq 4: Y loop gain matched to X's phase at this speed"},
                     {"kp_target_y_loop_per_s", match.kp_target_y_per_s},
                     {"ratio_y", match.ratio_y}};
  report["proposed_kp"] = proposed;
  // Restore (or apply) before plotting.
  if (o.apply) {
    guard.release();
    c.call({{"cmd", "gains"},
            {"set", {{"kp", proposed}, {"ff", saved["ff"]}, {"coupling", saved["coupling"]}}}});
    report["applied"] = true;
  } else {
    guard.restore();
    report["applied"] = false;
  }
  std::vector<DirectionRun> after_runs;
  if (!o.plot_png.empty()) {
    std::vector<DirectionRun>& after = after_runs;
    if (o.apply) {
      // Re-run with the matched gains (uncoupled, as before) to show the effect.
      GainsGuard g2(c, c.call({{"cmd", "gains"}}));
      c.call({{"cmd", "gains"}, {"set", {{"coupling", false}, {"ff", zero_ff}}}});
      for (bool cw : dirs) {
        const std::string csv = tag + (cw ? "cw" : "ccw") + "_after.csv";
        if (o.verbose)
          std::cerr << "circle-test: re-running " << (cw ? "CW" : "CCW")
                    << " with the matched gains...\n";
        after.push_back(run_direction(c, o, cw, csv, start));
      }
    }
    polar_plot(o.plot_png, runs, after, o);
    report["plot"] = o.plot_png;
  }
  json csvs = json::array();
  for (const auto* set : {&runs, &after_runs}) {
    for (const auto& r : *set) csvs.push_back(r.csv);
  }
  if (o.keep_csv) {
    report["csv"] = csvs;
  } else {
    // Best effort: the telemetry directory is the daemon's (group-writable under the unit's
    // UMask=0007 for members of its group).
    for (const auto& f : csvs) {
      std::error_code ec;
      fs::remove(f.get<std::string>(), ec);
    }
  }
  return report;
}

std::string format_circle_report(const json& r) {
  std::ostringstream o;
  char b[256];
  std::snprintf(b, sizeof b,
                "circle test: R %.3g mm, F %.0f mm/min programmed, %.0f mm/min run by the planner "
                "(w %.3f rad/s);\n"
                "coupling and ff off during the test\n",
                r["radius_mm"].get<double>(), r["feed_mm_min"].get<double>(),
                r["omega_rad_s"].get<double>() * r["radius_mm"].get<double>() * 60.0,
                r["omega_rad_s"].get<double>());
  o << b;
  for (const auto& d : r["runs"]) {
    std::snprintf(b, sizeof b,
                  "  %-3s  X: k %.2f 1/s, tau %.2f ms   Y: k %.2f 1/s, tau %.2f ms   (fit residual "
                  "%.2f um)\n",
                  d["direction"].get<std::string>().c_str(),
                  d["X"]["loop_gain_per_s"].get<double>(), d["X"]["loop_tau_ms"].get<double>(),
                  d["Y"]["loop_gain_per_s"].get<double>(), d["Y"]["loop_tau_ms"].get<double>(),
                  d["rms_residual_um"].get<double>());
    o << b;
  }
  const bool comp = r.value("assumed_delay_compensation", true);
  o << "axis  loop gain (1/s)  loop tau (ms)  drive gain K (1/s)  drive tau (ms, loop tau - "
    << (comp ? 0 : r["assumed_delay_cycles"].get<int>()) << ".5 T)\n";
  if (comp) {
    o << "(delay compensation assumed on: the " << r["assumed_delay_cycles"].get<int>()
      << "-cycle bus delay was removed from the phase; --no-delay-compensation if the config turns "
         "it off)\n";
  }
  for (const char* ax : {"X", "Y"}) {
    const auto& a = r[ax];
    std::snprintf(b, sizeof b, "%-4s  %15.3f  %13.3f  %18.3f  %8.3f\n", ax,
                  a["loop_gain_per_s"].get<double>(), a["loop_tau_ms"].get<double>(),
                  a["drive_gain_per_s"].get<double>(), a["drive_tau_ms"].get<double>());
    o << b;
  }
  std::snprintf(b, sizeof b, "matched gains (eq 4, Y to X): Y ratio %.4f -> kp %s %s\n",
                r["match"]["ratio_y"].get<double>(), r["proposed_kp"].dump().c_str(),
                r["applied"].get<bool>() ? "(applied)" : "(not applied; --apply sets them)");
  o << b;
  if (r.contains("plot")) o << "plot: " << r["plot"].get<std::string>() << '\n';
  if (r.contains("csv")) {
    for (const auto& f : r["csv"]) o << "CSV: " << f.get<std::string>() << '\n';
  }
  return o.str();
}

}  // namespace contour::ctl
