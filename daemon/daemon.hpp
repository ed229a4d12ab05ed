#pragma once
// contourd composition root: config -> bus (sim; socketcan not wired yet) -> ServoLoop on the RT
// thread, planner thread, telemetry writer, event logger, command socket; signals and systemd.
//
// Threads: main (signals via sigtimedwait, systemd watchdog), RT loop (RtThread, SCHED_FIFO when
// permitted), planner (per program), telemetry writer, event logger, command server, spdlog's
// async worker. All non-RT threads are created from main, which stays SCHED_OTHER.
// Signals: SIGTERM/SIGINT -> controlled stop, drives disabled, files flushed, exit 0;
// SIGUSR1 -> E-stop, SIGUSR2 -> hold (out of band: main thread posts to the loop, no socket);
// SIGHUP -> re-read the config file and compare it with the running one key by key
// (daemon/config_reload.hpp): every changed key is either applied at a cycle boundary (gains, the
// live safety limits incl. soft limits, velocity/acceleration/override/jog limits; log.level at
// once) or refused naming it ("needs restart", or why), in the log, the `events` stream and
// `status.config`; nothing is silently dropped.
// I/O: IoChannels (io_channels.hpp) owns the dynamometer reader and the GPIO lines; the loop
// reads them through RtIo; IoChannels' supervisor thread applies the loop's GPIO outputs.
// systemd: READY=1 once the drives are enabled and the loop runs; WATCHDOG=1 only while the loop's
// cycle counter advances.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "config/config.hpp"
#include "daemon/axis_bus.hpp"
#include "daemon/command_server.hpp"
#include "daemon/command_table.hpp"
#include "daemon/config_reload.hpp"
#include "daemon/event_log.hpp"
#include "daemon/io_channels.hpp"
#include "daemon/machine_data.hpp"
#include "daemon/planner.hpp"
#include "daemon/rt_timing.hpp"
#include "daemon/servo_loop.hpp"
#include "daemon/telemetry.hpp"

namespace contour::daemon {

struct DaemonOptions {
  std::string config_path;
  std::optional<std::string> socket_path;  // --socket overrides socket.path
};

// A start-up problem with a configured path (socket directory missing, socket or telemetry
// directory inside a private /tmp): Daemon::run() logs it and returns 78 (EX_CONFIG), which the
// unit's RestartPreventExitStatus= does not restart.
class StartupConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// True when `path` lies under a mount point of `mountinfo` (the text of /proc/self/mountinfo) that
// systemd's PrivateTmp= made: its root is a "systemd-private-*" directory. Such a /tmp or /var/tmp
// is the service's own, invisible to clients.
bool in_private_tmp(const std::string& path, const std::string& mountinfo);

// "${VAR:-default}" / "${VAR}" expansion for paths in the config (socket.path, telemetry.directory).
std::string expand_env(const std::string& s);

class Daemon {
 public:
  Daemon(config::Config cfg, DaemonOptions opt);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Runs until shutdown (signal or `shutdown` command). Returns the process exit code.
  int run();
  void request_shutdown() { shutdown_.store(true); }

  // Command socket handler (daemon/commands.cpp). Throws CommandError for error replies.
  nlohmann::json handle(const nlohmann::json& req, const ClientInfo& client);

 private:
  struct JobRecord {
    std::shared_ptr<ProgramJob> job;
    std::string name;
    std::vector<std::string> faults;
    std::uint64_t overruns_at_start = 0;
    std::size_t motion_blocks = 0;
    double length_mm = 0.0;
  };
  void start_components();
  void stop_components();
  void controlled_shutdown();
  void reload_config();
  // The loop's servo parameters for a control section on this machine (start-up, SIGHUP, gains).
  [[nodiscard]] control::ServoParams servo_params_for(const config::ControlConfig& control) const;
  void out_of_band_signal(int sig, pid_t from_pid, uid_t from_uid);
  void on_event(const RtEvent& e, const std::string& text);
  void on_bus_message(const std::string& text);
  void free_released_jobs();
  nlohmann::json status_json();
  nlohmann::json counters_json(const LoopStatus& st) const;
  nlohmann::json result_json(std::uint64_t job);
  MachineState post_and_wait(const LoopCommand& c, MachineState from, double timeout_s);
  nlohmann::json cmd_load(const nlohmann::json& req);
  // cmd_load after its arguments; preview: also the whole-program figures (ProgramSummary).
  nlohmann::json load_source(const ProgramText& src, bool preview = false);
  nlohmann::json cmd_upload(const nlohmann::json& req, const ClientInfo& client);  // commands_files.cpp
  void check_paths();  // socket directory, telemetry directory: StartupConfigError
  nlohmann::json cmd_gains(const nlohmann::json& req);
  nlohmann::json cmd_jog(const nlohmann::json& req, const ClientInfo& client);
  // Continuous jog dead-man (safety.jog_deadman_ms): the connection that owns the jog (0: none),
  // when it last sent a request (steady_clock ns); braked on its disconnect (server thread) or
  // silence (main thread, every 100 ms). `why` goes to the log.
  std::atomic<std::uint64_t> jog_owner_{0};
  std::atomic<std::int64_t> jog_renewed_ns_{0};
  void jog_deadman(std::uint64_t client_id, const char* why);
  void check_jog_deadman();
  nlohmann::json cmd_set_position(const nlohmann::json& req);
  nlohmann::json cmd_home(const nlohmann::json& req);
  // Homing (issue 18): the names of the axes not homed while homing is required ("" when none
  // or machine.allow_unhomed), and the refusal of `what` (run, mdi) with them.
  [[nodiscard]] std::string unhomed_axes() const;
  void require_homed(const char* what) const;
  nlohmann::json cmd_record(const nlohmann::json& req);
  nlohmann::json cmd_force(const nlohmann::json& req);
  // A run-time argument range of the command table (the configuration): {lo, hi}.
  [[nodiscard]] std::pair<double, double> bound(Bound b, const nlohmann::json& req) const;
  nlohmann::json cmd_sim_gpio(const nlohmann::json& req);
  nlohmann::json cmd_io(const nlohmann::json& req);          // commands_plc.cpp
  nlohmann::json cmd_plc_status(const nlohmann::json& req);  // commands_plc.cpp
  nlohmann::json plc_brief_json(const LoopStatus& st);       // commands_plc.cpp: status.plc
  nlohmann::json force_json();
  nlohmann::json gpio_json();
  // Issue 18 (daemon/commands_offsets.cpp): program.var_file / tool_table loaded (throws
  // StartupConfigError naming file:line), the socket commands and the status fields.
  void open_machine_data();
  nlohmann::json cmd_offsets(const nlohmann::json& req);
  nlohmann::json cmd_tools(const nlohmann::json& req);
  nlohmann::json cmd_touch_off(const nlohmann::json& req);
  nlohmann::json cmd_mdi(const nlohmann::json& req);
  void add_machine_status(nlohmann::json& j, const LoopStatus& st) const;
  std::unique_ptr<MachineData> machine_data_;
  std::unique_ptr<control::GcodeParser> mdi_parser_;  // command thread only
  std::uint64_t mdi_generation_ = 0;

  config::Config cfg_;
  DaemonOptions opt_;
  std::unique_ptr<AxisBus> bus_;
  std::unique_ptr<IoChannels> io_;  // before loop_: the loop holds a pointer to it
  std::unique_ptr<PlcEngine> plc_;  // soft PLC (plc: section; null without); before loop_
  std::unique_ptr<ServoLoop> loop_;
  std::unique_ptr<TelemetryWriter> writer_;
  std::unique_ptr<EventLogger> logger_;
  std::unique_ptr<ProgramPlanner> planner_;
  // A waiting handler gives way to another client's estop/hold/stop (CommandServer).
  [[nodiscard]] bool safety_request_waiting() const {
    return server_ != nullptr && server_->safety_request_waiting();
  }
  std::unique_ptr<CommandServer> server_;
  RtThread rt_;
  RtSetupReport rt_report_;
  std::atomic<bool> rt_stop_{false};
  std::atomic<std::uint64_t> reloads_{0};           // SIGHUP reloads applied
  std::atomic<std::uint64_t> reloads_rejected_{0};  // SIGHUP with a config that did not load
  std::atomic<bool> shutdown_{false};
  // SIGHUP (issue 16): the file as last loaded (YAML tree), the keys whose file value is not the
  // running one (refused: needs restart; key -> running value) and what the last reload did.
  YAML::Node running_yaml_;
  std::map<std::string, std::string> pending_restart_;
  ReloadReport last_reload_;
  mutable std::mutex reload_mu_;  // pending_restart_, last_reload_ (main thread vs status)
  nlohmann::json reload_json() const;
  // Start-up warnings about the configuration (issue 16: a measured drive model, machine.axes[].
  // identified, that contradicts the one the controller uses); status.config.warnings.
  std::vector<std::string> config_warnings_;
  // The last `identify` result per axis name since start (gain_per_s, tau_ms, delay_cycles, date):
  // the `gains` reply carries them as "identified", and `contourctl gains save` stores them.
  mutable std::mutex identified_mu_;
  nlohmann::json identified_ = nlohmann::json::object();
  std::atomic<bool> components_ready_{false};  // loop_/server_ published (bus event thread reads)

  std::mutex jobs_mu_;  // command thread vs logger thread
  std::map<std::uint64_t, JobRecord> jobs_;
  std::uint64_t next_job_ = 1;
  std::uint64_t loaded_job_ = 0;
  std::vector<std::string> recent_faults_;

  // Telemetry files go only here (absolute; created by check_paths()): `record` refuses any other
  // directory, since a client's path may not be the daemon's (PrivateTmp=yes).
  std::string telemetry_dir_;
  std::string telemetry_error_;  // why telemetry_dir_ is unusable ("" when it is usable)
  // The one chunked upload in progress (command thread only): bounded by
  // socket.max_program_bytes; a new upload from another connection replaces it only when idle.
  struct Upload {
    std::uint64_t client = 0;
    pid_t pid = 0;
    std::string name;
    std::string text;
    std::chrono::steady_clock::time_point last;
  };
  std::optional<Upload> upload_;
};

}  // namespace contour::daemon
