#pragma once
// Plots from contourd's telemetry CSV (daemon/telemetry.cpp writes it: header line, one row per
// recorded cycle; columns cycle, t_s, state, job, line, progress_mm, rx/ry/rz_mm (reference),
// px/py/pz_mm (actual), eps_x/y/z_um (contour-error model vector K - P), true_contour_error_um
// (distance to the planned path; empty outside a program), vx/vy/vz_mm_s, override, and possibly
// force columns added later). Columns are found by header name, so added columns do not break it.
// Non-RT tool code: allocates; bad input throws std::runtime_error naming the file, line and
// column.
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace contour::ctl {

struct TelemetryCsv {
  std::string path;
  std::vector<std::string> header;
  std::map<std::string, std::vector<double>> col;  // NaN for empty cells
  std::size_t rows = 0;

  [[nodiscard]] bool has(const std::string& name) const { return col.count(name) != 0; }
  // Throws naming the file and the missing column.
  [[nodiscard]] const std::vector<double>& at(const std::string& name) const;
  // First column whose name starts with prefix and contains `contains` (may be empty); "" if none.
  [[nodiscard]] std::string find(const std::string& prefix, const std::string& contains = "",
                                 const std::string& excluding = "") const;
};

TelemetryCsv read_telemetry_csv(const std::string& path);

enum class PlotKind { kError, kPath, kPath3d, kForce, kTiming };
PlotKind parse_plot_kind(const std::string& s);  // throws std::invalid_argument listing the kinds

struct PlotOptions {
  std::vector<std::string> labels;  // one per CSV (default: file stem)
  double magnify = 0.0;             // path plots: error magnification (0: automatic)
  std::string title;                // extra title line
  // Path plots: the part program, drawn as the programmed path (parsed here with the default
  // program setup, starting where the recording's reference starts; work offsets from the
  // daemon's config are not applied).
  std::string program;
};

// error / path / path3d / force from one or more CSVs (error overlays several runs; the others
// use the first). Returns a one-line description of what was plotted.
std::string plot_csv(PlotKind kind, const std::vector<TelemetryCsv>& runs, const std::string& png,
                     const PlotOptions& o);

// Loop timing from a status reply: the wake-up lateness histogram when the daemon reports one
// (status.timing.lateness_histogram {bin_low_us: [...], count: [...]}), else a bar chart of the
// summary figures (mean / p99 / max lateness, last / max compute time).
std::string plot_timing(const nlohmann::json& status, const std::string& png, const PlotOptions& o);

// Toolpath preview (`load --preview` reply: path_mm in machine coordinates): 3-D when the path
// moves in Z, else the XY plane; rapids are not told apart (the reply's path is points only).
std::string plot_preview(const nlohmann::json& reply, const std::string& png, const PlotOptions& o);

// Drive identification (`identify` reply): the recorded position (um from the start) and the
// velocity target (mm/s) over time, the fitted model in the title.
std::string plot_identify(const nlohmann::json& reply, const std::string& png, const PlotOptions& o);

}  // namespace contour::ctl
