// contourd — the real-time servo daemon.
//   contourd --config FILE [--socket PATH]     run (systemd Type=notify)
//   contourd --config FILE --check-config      validate, print every error, exit 78 on errors
//   contourd --protocol                        print the command protocol (daemon/PROTOCOL.md)
//   contourd --latency-test SECONDS            RT set-up and wake-up lateness without drives
//   contourd --config FILE --probe modbus|can|gpio [--count N] [--scan]
//                                              commissioning probe: JSON lines, no loop (probe.hpp)
// Signals (daemon.hpp): SIGTERM/SIGINT controlled stop and exit, SIGHUP reload, SIGUSR1 E-stop,
// SIGUSR2 hold (out of band: not through the command socket).
#include <pthread.h>
#include <signal.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <string>

#include "config/config.hpp"
#include "daemon/command_table.hpp"
#include "daemon/daemon.hpp"
#include "daemon/latency_test.hpp"
#include "daemon/probe.hpp"

int main(int argc, char** argv) {
  CLI::App app{"contourd: real-time CNC servo daemon"};
  std::string config_path;
  std::string socket_path;
  bool check_only = false;
  double latency_s = 0.0;
  contour::daemon::LatencyTestOptions lat;
  app.add_option("--config", config_path, "YAML configuration file");
  app.add_option("--socket", socket_path, "command socket path (overrides socket.path)");
  app.add_flag("--check-config", check_only, "validate the configuration and exit (78 on errors)");
  app.add_option("--latency-test", latency_s,
                 "run the RT loop set-up without drives for SECONDS and report wake-up lateness")
      ->check(CLI::Range(0.01, 86400.0));
  app.add_option("--priority", lat.rt.priority, "SCHED_FIFO priority for --latency-test")
      ->check(CLI::Range(0, 99));
  app.add_option("--cpu", lat.rt.cpu, "CPU for --latency-test (-1: any)");
  app.add_option("--plot", lat.plot_png, "PNG histogram for --latency-test");
  std::string probe_kind;
  contour::daemon::ProbeOptions probe;
  app.add_option("--probe", probe_kind,
                 "talk to the configured devices without starting the loop and print JSON lines: "
                 "modbus (dynamometer samples), can (nodes, NMT state, identity), gpio (lines)");
  app.add_option("--count", probe.count,
                 "--probe: samples (modbus, default 10 at the poll rate) or rounds (can, gpio: 1)")
      ->check(CLI::Range(1, 1000000));
  app.add_flag("--scan", probe.scan, "--probe can: also scan node-ids 1..127");
  bool protocol = false;
  app.add_flag("--protocol", protocol,
               "print the command protocol (Markdown, daemon/PROTOCOL.md) from the command table");
  CLI11_PARSE(app, argc, argv);

  if (protocol) {
    std::fputs(contour::daemon::protocol_markdown().c_str(), stdout);
    return 0;
  }

  if (latency_s > 0.0) {
    lat.seconds = latency_s;
    return contour::daemon::run_latency_test(lat);
  }
  if (!probe_kind.empty()) {
    const auto k = contour::daemon::parse_probe_kind(probe_kind);
    if (!k) {
      std::fprintf(stderr, "contourd: --probe: unknown kind '%s' (expected modbus, can or gpio)\n",
                   probe_kind.c_str());
      return 2;
    }
    probe.kind = *k;
  } else if (probe.count != 0 || probe.scan) {
    std::fprintf(stderr, "contourd: --count and --scan go with --probe\n");
    return 2;
  }
  if (config_path.empty()) {
    std::fprintf(stderr, "contourd: --config FILE is required\n");
    return 2;
  }
  if (!check_only && probe_kind.empty()) {
    // SIGUSR1 (E-stop) and SIGUSR2 (hold) are taken by Daemon::run with sigtimedwait; blocked from
    // here so that one sent during start-up is applied once the loop runs instead of killing the
    // process (their default action).
    sigset_t oob;
    sigemptyset(&oob);
    sigaddset(&oob, SIGUSR1);
    sigaddset(&oob, SIGUSR2);
    pthread_sigmask(SIG_BLOCK, &oob, nullptr);
  }
  contour::config::Config cfg;
  try {
    cfg = contour::config::load_config_file(config_path);
  } catch (const contour::config::ConfigError& e) {
    for (const auto& m : e.errors()) std::fprintf(stderr, "%s\n", m.c_str());
    std::fprintf(stderr, "contourd: %zu configuration error(s)\n", e.errors().size());
    return 78;  // EX_CONFIG
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", config_path.c_str(), e.what());
    return 78;
  }
  if (check_only) {
    std::printf("%s: configuration OK (%zu axes)\n", config_path.c_str(), cfg.machine.axes.size());
    return 0;
  }
  if (!probe_kind.empty()) {
    try {
      return contour::daemon::run_probe(cfg, probe, stdout);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "contourd: probe: %s\n", e.what());
      return 1;
    }
  }
  contour::daemon::DaemonOptions opt;
  opt.config_path = config_path;
  if (!socket_path.empty()) opt.socket_path = socket_path;
  try {
    contour::daemon::Daemon d(std::move(cfg), opt);
    return d.run();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contourd: %s\n", e.what());
    return 1;
  }
}
