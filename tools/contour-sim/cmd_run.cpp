// contour-sim run: a part program through contourd's own loop code, offline and deterministic.
//   contour-sim run --config FILE --program FILE.ngc [--csv FILE] [--max-s S]
// The same ServoLoop, planner and telemetry statistics as the daemon (daemon/offline_run.hpp),
// driven cycle by cycle without sleeping, on the simulated drives. With `bus.type: socketcan` the
// drives are modelled as the CANopen drives see it (integer counts and counts/s, daemon/sim_bus),
// so `contourd` against contour-machine-sim over (v)CAN must give these figures exactly (HIL test
// DaemonCanopen.Table2OverVcanGivesTheOfflineFigures). The last stdout line is one JSON object.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <string>

#include "config/config.hpp"
#include "daemon/offline_run.hpp"
#include "tools/contour-sim/commands.hpp"

namespace contour::sim {

int run_run(int argc, char** argv) {
  CLI::App app{"contour-sim run: a part program through contourd's loop code, offline"};
  std::string config_path, program_path, csv_path;
  double max_s = 3600.0;
  app.add_option("--config", config_path, "contourd YAML configuration")->required();
  app.add_option("--program", program_path, "part program (G-code)")->required();
  app.add_option("--csv", csv_path, "telemetry CSV (the daemon's columns)");
  app.add_option("--max-s", max_s, "bound on the simulated time in seconds")
      ->check(CLI::Range(0.001, 1e6));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  config::Config cfg;
  try {
    cfg = config::load_config_file(config_path);
  } catch (const config::ConfigError& e) {
    for (const auto& m : e.errors()) std::fprintf(stderr, "%s\n", m.c_str());
    return 2;
  }
  const auto max_cycles = static_cast<std::uint64_t>(max_s / cfg.machine.period_s);
  const daemon::OfflineResult r =
      daemon::run_offline(cfg, {program_path, program_path, ""}, max_cycles, csv_path);
  std::printf("%s: %s after %.3f s, max contour error %.6f um, RMS %.6f um%s\n",
              program_path.c_str(), r.state.c_str(), r.duration_s, r.stats.max_contour_error_um,
              r.stats.rms_contour_error_um(), r.finished_ok ? "" : " (did not finish)");
  const nlohmann::json j{{"state", r.state},
                         {"cause", r.cause},
                         {"finished_ok", r.finished_ok},
                         {"bus", cfg.bus.type},
                         {"duration_s", r.duration_s},
                         {"samples", r.stats.samples},
                         {"max_contour_error_um", r.stats.max_contour_error_um},
                         {"rms_contour_error_um", r.stats.rms_contour_error_um()},
                         {"velocity_clamps", r.velocity_clamps},
                         {"underruns", r.underruns}};
  std::printf("%s\n", j.dump().c_str());
  return r.finished_ok ? 0 : 1;
}

}  // namespace contour::sim
