#include "tools/contourctl/plot.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "control/gcode.hpp"
#include "control/path.hpp"
#include "tools/common/gnuplot.hpp"

namespace contour::ctl {

namespace gp = contour::tools::gnuplot;
using nlohmann::json;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::size_t kMaxPlotPoints = 20000;  // per curve; a 10 min run at 1 kHz is 600k rows

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> out;
  std::string cell;
  std::stringstream ss(line);
  while (std::getline(ss, cell, ',')) out.push_back(cell);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

std::string fmt(double v) {
  if (!std::isfinite(v)) return "NaN";
  std::ostringstream o;
  o.precision(9);
  o << v;
  return o.str();
}

std::size_t stride(std::size_t n) { return std::max<std::size_t>(1, n / kMaxPlotPoints); }

std::string label_of(const PlotOptions& o, const std::vector<TelemetryCsv>& runs, std::size_t i) {
  if (i < o.labels.size()) return o.labels[i];
  return std::filesystem::path(runs[i].path).stem().string();
}

// Rows that belong to a program run (job != 0); all rows when none do (a recording of jogs).
std::vector<std::size_t> program_rows(const TelemetryCsv& c) {
  std::vector<std::size_t> rows;
  if (c.has("job")) {
    const auto& job = c.at("job");
    for (std::size_t i = 0; i < c.rows; ++i) {
      if (job[i] != 0.0) rows.push_back(i);
    }
  }
  if (rows.empty()) {
    for (std::size_t i = 0; i < c.rows; ++i) rows.push_back(i);
  }
  return rows;
}

// 1, 2, 5 x 10^k at or below x (x >= 1).
double nice_below(double x) {
  if (!(x >= 1.0)) return 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(x)));
  for (double m : {5.0, 2.0, 1.0}) {
    if (m * p <= x) return m * p;
  }
  return p;
}

std::string title_line(const PlotOptions& o, const std::string& main) {
  return "set title " + gp::dquote(o.title.empty() ? main : main + "\\n" + o.title) +
         " noenhanced\n";
}

}  // namespace

const std::vector<double>& TelemetryCsv::at(const std::string& name) const {
  auto it = col.find(name);
  if (it == col.end()) throw std::runtime_error(path + ": no column '" + name + "' in the header");
  return it->second;
}

std::string TelemetryCsv::find(const std::string& prefix, const std::string& contains,
                               const std::string& excluding) const {
  for (const auto& h : header) {
    if (h.rfind(prefix, 0) != 0) continue;
    if (!contains.empty() && h.find(contains) == std::string::npos) continue;
    if (!excluding.empty() && h.find(excluding) != std::string::npos) continue;
    return h;
  }
  return {};
}

TelemetryCsv read_telemetry_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open telemetry CSV");
  TelemetryCsv c;
  c.path = path;
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(path + ": empty file (no CSV header)");
  c.header = split_csv_line(line);
  for (const auto& h : c.header) c.col[h];
  if (!c.has("t_s"))
    throw std::runtime_error(path + ":1: not a contourd telemetry CSV (no t_s column)");
  std::size_t lineno = 1;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.empty()) continue;
    const auto cells = split_csv_line(line);
    if (cells.size() != c.header.size()) {
      // A recording stopped mid-write leaves a short last line; anything else is an error.
      if (in.peek() == std::char_traits<char>::eof()) break;
      throw std::runtime_error(path + ":" + std::to_string(lineno) + ": " +
                               std::to_string(cells.size()) + " cells, the header has " +
                               std::to_string(c.header.size()));
    }
    for (std::size_t k = 0; k < cells.size(); ++k) {
      double v = kNaN;
      if (!cells[k].empty()) {
        try {
          std::size_t used = 0;
          v = std::stod(cells[k], &used);
          if (used != cells[k].size()) throw std::invalid_argument(cells[k]);
        } catch (const std::exception&) {
          throw std::runtime_error(path + ":" + std::to_string(lineno) + ": column '" +
                                   c.header[k] + "': '" + cells[k] + "' is not a number");
        }
      }
      c.col[c.header[k]].push_back(v);
    }
    ++c.rows;
  }
  if (c.rows == 0)
    throw std::runtime_error(path + ": no samples (was the recording started before the run?)");
  return c;
}

PlotKind parse_plot_kind(const std::string& s) {
  if (s == "error") return PlotKind::kError;
  if (s == "path") return PlotKind::kPath;
  if (s == "path3d") return PlotKind::kPath3d;
  if (s == "force") return PlotKind::kForce;
  if (s == "timing") return PlotKind::kTiming;
  throw std::invalid_argument("--kind must be error, path, path3d, force or timing, got '" + s +
                              "'");
}

namespace {

std::string plot_error(const std::vector<TelemetryCsv>& runs, const std::string& png,
                       const PlotOptions& o) {
  gp::TempData data(png);
  double max_all = 0.0;
  for (const auto& c : runs) {
    const auto rows = program_rows(c);
    const auto& t = c.at("t_s");
    const bool has_true = c.has("true_contour_error_um");
    const double t0 = t[rows.front()];
    for (std::size_t k = 0; k < rows.size(); k += stride(rows.size())) {
      const std::size_t i = rows[k];
      double model = kNaN;
      if (c.has("eps_x_um")) {
        model = std::hypot(c.at("eps_x_um")[i], c.at("eps_y_um")[i], c.at("eps_z_um")[i]);
      }
      const double tru = has_true ? c.at("true_contour_error_um")[i] : kNaN;
      if (std::isfinite(tru)) max_all = std::max(max_all, tru);
      data.out() << fmt(t[i] - t0) << ' ' << fmt(tru) << ' ' << fmt(model) << '\n';
    }
    data.out() << "\n\n";
  }
  data.close();
  std::string script = gp::png_preamble(png) + title_line(o, "Contour error vs time") +
                       "set xlabel 'time since program start (s)'\n"
                       "set ylabel 'contour error ({/Symbol m}m)'\n"
                       "set yrange [0:*]\n";
  script += "plot ";
  const char* colors[] = {"#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e"};
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const std::string lab = label_of(o, runs, r);
    const std::string col = colors[r % 5];
    if (r > 0) script += ", ";
    script += gp::quote(data.path()) + " index " + std::to_string(r) +
              " using 1:2 with lines lw 2 lc rgb '" + col + "' title " +
              gp::quote(lab + ": true distance to the planned path") + " noenhanced";
    script += ", " + gp::quote(data.path()) + " index " + std::to_string(r) +
              " using 1:3 with lines lw 1 dt 2 lc rgb '" +
              (runs.size() == 1 ? std::string("#555555") : col) + "' title " +
              gp::quote(gp::enhanced_escape(lab) + ": model |{/Symbol e}| (eq 7)");
  }
  script += "\n";
  gp::run(script, png);
  std::ostringstream d;
  d << "contour error vs time, " << runs.size() << " run(s), max " << fmt(max_all) << " um";
  return d.str();
}

// Programmed path of `file` from `start` as a polyline (arcs as chords within 1 um).
std::vector<Eigen::Vector3d> programmed_path(const std::string& file,
                                             const Eigen::Vector3d& start) {
  contour::control::ProgramSetup setup;
  setup.start_mm = start;
  contour::control::GcodeParser parser(setup, file);
  std::ifstream in(file);
  if (!in) throw std::runtime_error(file + ": cannot read the program");
  std::vector<contour::control::Block> blocks;
  std::string l;
  while (std::getline(in, l) && !parser.ended()) parser.parse_line(l, blocks);
  parser.finish(blocks);
  std::vector<Eigen::Vector3d> pts{start};
  for (const auto& b : blocks) {
    if (b.kind != contour::control::BlockKind::kMotion) continue;
    if ((pts.back() - b.seg.start).norm() > 1e-9) pts.push_back(b.seg.start);
    contour::control::chord_points(b.seg, 1e-3, pts);
  }
  return pts;
}

std::string plot_path(const TelemetryCsv& c, const std::string& png, const PlotOptions& o,
                      bool three_d) {
  const auto rows = program_rows(c);
  const auto &rx = c.at("rx_mm"), &ry = c.at("ry_mm"), &rz = c.at("rz_mm");
  const auto &px = c.at("px_mm"), &py = c.at("py_mm"), &pz = c.at("pz_mm");
  const bool has_eps = c.has("eps_x_um");
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  double max_err_mm = 0.0;
  std::vector<double> eps_mm;
  for (std::size_t i : rows) {
    const double r[3] = {rx[i], ry[i], rz[i]};
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], r[a]);
      hi[a] = std::max(hi[a], r[a]);
    }
    if (has_eps) {
      const double e =
          1e-3 * std::hypot(c.at("eps_x_um")[i], c.at("eps_y_um")[i], c.at("eps_z_um")[i]);
      if (std::isfinite(e)) eps_mm.push_back(e);
      max_err_mm = std::max(max_err_mm, e);
    }
  }
  // Scale by the 99.9th percentile: one start-up transient must not shrink the rest to nothing,
  // while the corner peaks (~0.5 % of Table 2's samples) still set it.
  double p99_err_mm = 0.0;
  if (!eps_mm.empty()) {
    const auto k = static_cast<std::ptrdiff_t>(0.999 * static_cast<double>(eps_mm.size() - 1));
    std::nth_element(eps_mm.begin(), eps_mm.begin() + k, eps_mm.end());
    p99_err_mm = eps_mm[static_cast<std::size_t>(k)];
  }
  const double extent =
      std::max({hi[0] - lo[0], hi[1] - lo[1], three_d ? hi[2] - lo[2] : 0.0, 1e-6});
  // Automatic: that error drawn at about 5 % of the path's extent.
  double n = o.magnify;
  if (!(n > 0.0)) n = p99_err_mm > 0.0 ? nice_below(0.05 * extent / p99_err_mm) : 1.0;
  gp::TempData data(png);
  for (std::size_t k = 0; k < rows.size(); k += stride(rows.size())) {
    const std::size_t i = rows[k];
    data.out() << fmt(rx[i]) << ' ' << fmt(ry[i]) << ' ' << fmt(rz[i]) << '\n';
  }
  data.out() << "\n\n";
  for (std::size_t k = 0; k < rows.size(); k += stride(rows.size())) {
    const std::size_t i = rows[k];
    // eps = K - P (model's nearest path point minus actual): drawn point K - n eps, i.e. the
    // contour error magnified n times; without eps columns the actual position itself.
    double q[3] = {px[i], py[i], pz[i]};
    if (has_eps) {
      const double e[3] = {1e-3 * c.at("eps_x_um")[i], 1e-3 * c.at("eps_y_um")[i],
                           1e-3 * c.at("eps_z_um")[i]};
      for (int a = 0; a < 3; ++a) q[a] = q[a] + e[a] - n * e[a];
    }
    data.out() << fmt(q[0]) << ' ' << fmt(q[1]) << ' ' << fmt(q[2]) << '\n';
  }
  data.out() << "\n\n";
  if (!o.program.empty()) {
    const std::size_t i0 = rows.front();
    for (const auto& q : programmed_path(o.program, Eigen::Vector3d(rx[i0], ry[i0], rz[i0]))) {
      data.out() << fmt(q.x()) << ' ' << fmt(q.y()) << ' ' << fmt(q.z()) << '\n';
    }
  }
  data.close();
  const std::string prog_curve =
      o.program.empty()
          ? std::string()
          : ", " + gp::quote(data.path()) + " index 2 using 1:2" + (three_d ? ":3" : "") +
                " with lines lw 1 dt 2 lc rgb '#000000' title 'programmed'";
  std::ostringstream nn;
  nn << n;
  const std::string act_title = has_eps ? "actual, contour error magnified x" + nn.str() : "actual";
  std::string script = gp::png_preamble(png, 1100, 1000);
  // A flat (2.5-D) part: give Z a tenth of the XY extent so its axis stays readable.
  std::string zrange;
  if (hi[2] - lo[2] < 0.1 * extent) {
    const double zc = 0.5 * (hi[2] + lo[2]);
    zrange = "set zrange [" + fmt(zc - 0.05 * extent) + ":" + fmt(zc + 0.05 * extent) + "]\n";
  }
  if (three_d) {
    script += title_line(o, "Tool path in 3-D: reference vs actual (error x" + nn.str() + ")") +
              "set xlabel 'X (mm)'\nset ylabel 'Y (mm)'\nset zlabel 'Z (mm)' rotate parallel\n"
              "set view 55,30\nset ticslevel 0\nset view equal xy\nset key top right\n" +
              zrange + "splot " + gp::quote(data.path()) +
              " index 0 using 1:2:3 with lines lw 2 lc rgb '#1f77b4' "
              "title 'reference (interpolated program)', " +
              gp::quote(data.path()) +
              " index 1 using 1:2:3 with lines lw 1 lc rgb '#d62728' title " +
              gp::quote(act_title) + prog_curve + "\n";
  } else {
    script += title_line(o, "Tool path XY: reference vs actual (error x" + nn.str() + ")") +
              "set xlabel 'X (mm)'\nset ylabel 'Y (mm)'\nset size ratio -1\nset key outside below "
              "vertical maxrows 3\n"
              "set offsets graph 0.05, graph 0.05, graph 0.05, graph 0.05\n"
              "plot " +
              gp::quote(data.path()) +
              " index 0 using 1:2 with lines lw 2 lc rgb '#1f77b4' "
              "title 'reference (interpolated program)', " +
              gp::quote(data.path()) +
              " index 1 using 1:2 with lines lw 1 lc rgb '#d62728' title " + gp::quote(act_title) +
              prog_curve + "\n";
  }
  gp::run(script, png);
  return std::string(three_d ? "3-D" : "XY") + " path, contour error magnified x" + nn.str() +
         ", max model error " + fmt(max_err_mm * 1e3) + " um";
}

std::string plot_force(const TelemetryCsv& c, const std::string& png, const PlotOptions& o) {
  // Force columns are not in the CSV yet (the force channel is not wired into contourd); accept
  // any "force*"/"f_*" column, the one containing "ref" being the reference.
  std::string f_ref = c.find("force", "ref");
  std::string f_meas = c.find("force", "", "ref");
  if (f_meas.empty()) f_meas = c.find("f_", "", "ref");
  if (f_ref.empty()) f_ref = c.find("f_", "ref");
  const bool has_force = !f_meas.empty();
  const bool has_ovr = c.has("override");
  if (!has_force && !has_ovr) {
    throw std::runtime_error(c.path + ": no force and no override columns to plot");
  }
  const auto rows = program_rows(c);
  const auto& t = c.at("t_s");
  const double t0 = t[rows.front()];
  gp::TempData data(png);
  for (std::size_t k = 0; k < rows.size(); k += stride(rows.size())) {
    const std::size_t i = rows[k];
    data.out() << fmt(t[i] - t0) << ' ' << fmt(has_force ? c.at(f_meas)[i] : kNaN) << ' '
               << fmt(!f_ref.empty() ? c.at(f_ref)[i] : kNaN) << ' '
               << fmt(has_ovr ? 100.0 * c.at("override")[i] : kNaN) << '\n';
  }
  data.close();
  // Room above the (usually flat 100 %) override line so it does not hide under the border.
  double ovr_max = 100.0;
  if (has_ovr) {
    for (double v : c.at("override")) {
      if (std::isfinite(v)) ovr_max = std::max(ovr_max, 100.0 * v);
    }
  }
  const std::string ovr_range = "set yrange [0:" + fmt(1.15 * ovr_max) + "]\n";
  const std::string d = gp::quote(data.path());
  std::string script = gp::png_preamble(png, 1200, has_force ? 1000 : 600);
  if (has_force) {
    script +=
        "set multiplot layout 2,1 title " +
        gp::dquote(std::string("Cutting force and feed override") +
                   (o.title.empty() ? "" : "\\n" + o.title)) +
        " noenhanced\n"
        "set title 'force vs reference'\nset xlabel 'time since program start (s)'\nset ylabel "
        "'force (N)'\n"
        "plot " +
        d + " using 1:2 with lines lw 2 lc rgb '#d62728' title " +
        gp::quote("measured (" + f_meas + ")") + " noenhanced" +
        (f_ref.empty() ? ""
                       : ", " + d + " using 1:3 with lines lw 2 dt 2 lc rgb '#1f77b4' title " +
                             gp::quote("reference (" + f_ref + ")") + " noenhanced") +
        "\n"
        "set title 'feed override'\nset ylabel 'feed override (%)'\n" +
        ovr_range +
        ""
        "plot " +
        d +
        " using 1:4 with lines lw 2 lc rgb '#2ca02c' title 'applied feed override'\n"
        "unset multiplot\n";
  } else {
    script += title_line(o,
                         "Feed override vs time (no force columns in this recording: the force "
                         "channel is not wired into contourd yet)") +
              "set xlabel 'time since program start (s)'\nset ylabel 'feed override (%)'\n" +
              ovr_range + "plot " + d +
              " using 1:4 with lines lw 2 lc rgb '#2ca02c' title 'applied feed override'\n";
  }
  gp::run(script, png);
  return has_force ? "force (" + f_meas + ") and feed override vs time"
                   : "feed override vs time (no force columns in " + c.path + ")";
}

}  // namespace

std::string plot_csv(PlotKind kind, const std::vector<TelemetryCsv>& runs, const std::string& png,
                     const PlotOptions& o) {
  if (runs.empty()) throw std::runtime_error("plot: no telemetry CSV given");
  switch (kind) {
    case PlotKind::kError:
      return plot_error(runs, png, o);
    case PlotKind::kPath:
      return plot_path(runs.front(), png, o, false);
    case PlotKind::kPath3d:
      return plot_path(runs.front(), png, o, true);
    case PlotKind::kForce:
      return plot_force(runs.front(), png, o);
    case PlotKind::kTiming:
      break;
  }
  throw std::runtime_error("plot: --kind timing reads the daemon's status, not a CSV");
}

std::string plot_timing(const json& status, const std::string& png, const PlotOptions& o) {
  const json tm = status.value("timing", json::object());
  const double cycles = tm.value("cycles", 0.0);
  std::ostringstream sub;
  sub << "cycles " << static_cast<unsigned long long>(cycles) << ", overruns "
      << tm.value("overruns", 0) << ", realtime " << (tm.value("realtime", false) ? "yes" : "NO")
      << ", memory locked " << (tm.value("memory_locked", false) ? "yes" : "NO");
  gp::TempData data(png);
  std::string script = gp::png_preamble(png, 1200, 700);
  if (tm.contains("lateness_histogram") && tm["lateness_histogram"].contains("bin_low_us") &&
      tm["lateness_histogram"].contains("count")) {
    const auto& lo = tm["lateness_histogram"]["bin_low_us"];
    const auto& n = tm["lateness_histogram"]["count"];
    if (!lo.is_array() || !n.is_array() || lo.size() != n.size()) {
      throw std::runtime_error(
          "status.timing.lateness_histogram: bin_low_us and count differ in length");
    }
    for (std::size_t i = 0; i < lo.size(); ++i) {
      if (n[i].get<double>() > 0.0)
        data.out() << lo[i].get<double>() << ' ' << n[i].get<double>() << '\n';
    }
    data.close();
    script += title_line(o, "Servo loop wake-up lateness histogram\\n" + sub.str()) +
              "set xlabel 'wake-up lateness ({/Symbol m}s)'\nset ylabel 'cycles'\nset logscale y\n"
              "set style fill solid 0.6\n"
              "plot " +
              gp::quote(data.path()) +
              " using 1:2 with boxes lc rgb '#1f77b4' title 'cycles per bin'\n";
    gp::run(script, png);
    return "loop lateness histogram (" + sub.str() + ")";
  }
  // No histogram in status: the summary figures it does report.
  const std::pair<const char*, const char*> rows[] = {{"lateness mean", "lateness_mean_us"},
                                                      {"lateness p99", "lateness_p99_us"},
                                                      {"lateness max", "lateness_max_us"},
                                                      {"compute last", "compute_last_us"},
                                                      {"compute max", "compute_max_us"}};
  int k = 0;
  for (const auto& [name, key] : rows) {
    data.out() << k++ << " \"" << name << "\" " << tm.value(key, 0.0) << '\n';
  }
  data.close();
  script +=
      title_line(o, "Servo loop timing (summary: this daemon reports no lateness histogram)\\n" +
                        sub.str()) +
      "set ylabel 'time ({/Symbol m}s, log scale)'\nset style fill solid 0.6\nset boxwidth 0.6\n"
      "set logscale y\nset yrange [0.1:*]\nset xrange [-0.6:4.6]\nunset key\n"
      "plot " +
      gp::quote(data.path()) +
      " using 1:3:xtic(2) with boxes lc rgb '#1f77b4', '' using 1:3:"
      "(sprintf('%.1f', $3)) with labels offset 0,1 notitle\n";
  gp::run(script, png);
  return "loop timing summary (" + sub.str() + ")";
}

std::string plot_identify(const json& r, const std::string& png, const PlotOptions& o) {
  const json rec = r.value("record", json::object());
  if (!rec.contains("v_cmd_mm_s") || !rec.contains("position_mm") || !rec["v_cmd_mm_s"].is_array() ||
      !rec["position_mm"].is_array() || rec["v_cmd_mm_s"].size() != rec["position_mm"].size() ||
      rec["position_mm"].empty()) {
    throw std::runtime_error("identify reply: record.v_cmd_mm_s / record.position_mm missing or of different length");
  }
  const double T = rec.value("period_s", 0.001);
  const auto& v = rec["v_cmd_mm_s"];
  const auto& x = rec["position_mm"];
  const double x0 = x[0].get<double>();
  gp::TempData data(png);
  for (std::size_t k = 0; k < x.size(); ++k) {
    data.out() << static_cast<double>(k) * T << ' ' << (x[k].get<double>() - x0) * 1e3 << ' '
               << v[k].get<double>() << '\n';
  }
  data.close();
  std::ostringstream sub;
  sub << "axis " << r.value("axis", std::string("?")) << ": K " << r.value("gain_per_s", 0.0)
      << " 1/s, tau " << r.value("tau_ms", 0.0) << " ms, delay " << r.value("delay_cycles", 0)
      << " cycles (configured " << r["configured"].value("gain_per_s", 0.0) << " / "
      << r["configured"].value("tau_ms", 0.0) << " / " << r["configured"].value("delay_cycles", 0)
      << ")";
  std::string script = gp::png_preamble(png, 1200, 700);
  script += title_line(o, "Drive identification\\n" + sub.str()) +
            "set xlabel 'time (s)'\nset ylabel 'position from start ({/Symbol m}m)'\n"
            "set y2label 'velocity target (mm/s)'\nset ytics nomirror\nset y2tics\n"
            "plot " + gp::quote(data.path()) +
            " using 1:2 with lines lw 2 lc rgb '#1f77b4' title 'position read', " +
            gp::quote(data.path()) +
            " using 1:3 axes x1y2 with steps lc rgb '#d62728' title 'velocity target written'\n";
  gp::run(script, png);
  return "drive identification (" + sub.str() + ")";
}

std::string plot_preview(const json& r, const std::string& png, const PlotOptions& o) {
  const json path = r.value("path_mm", json::array());
  if (!path.is_array() || path.empty()) throw std::runtime_error("load reply: no path_mm (not a preview, or no motion)");
  double zmin = 1e300, zmax = -1e300;
  gp::TempData data(png);
  for (const auto& p : path) {
    const double z = p[2].get<double>();
    zmin = std::min(zmin, z);
    zmax = std::max(zmax, z);
    data.out() << p[0].get<double>() << ' ' << p[1].get<double>() << ' ' << z << '\n';
  }
  data.close();
  const bool three_d = zmax - zmin > 1e-6;
  std::ostringstream sub;
  sub << r.value("name", std::string("program")) << ": " << r.value("motion_blocks", 0L) << " moves, "
      << r.value("length_mm", 0.0) << " mm, ~" << r.value("estimated_time_s", 0.0) << " s";
  std::string script = gp::png_preamble(png, 1000, 900);
  script += title_line(o, "Toolpath preview (machine coordinates)\\n" + sub.str());
  if (three_d) {
    script += "set xlabel 'X (mm)'\nset ylabel 'Y (mm)'\nset zlabel 'Z (mm)'\nset view equal xy\n"
              "splot " + gp::quote(data.path()) + " using 1:2:3 with lines lc rgb '#1f77b4' notitle\n";
  } else {
    script += "set xlabel 'X (mm)'\nset ylabel 'Y (mm)'\nset size ratio -1\n"
              "plot " + gp::quote(data.path()) + " using 1:2 with lines lc rgb '#1f77b4' notitle\n";
  }
  gp::run(script, png);
  return std::string(three_d ? "3-D" : "XY") + " toolpath, " + std::to_string(path.size()) + " points";
}

}  // namespace contour::ctl
