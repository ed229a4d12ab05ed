#include "daemon/daemon.hpp"
#include "daemon/gains_check.hpp"

#include <signal.h>
#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "daemon/bus_factory.hpp"

namespace contour::daemon {

std::string expand_env(const std::string& s) {
  std::string out;
  std::size_t i = 0;
  while (i < s.size()) {
    if (s[i] == '$' && i + 1 < s.size() && s[i + 1] == '{') {
      const std::size_t end = s.find('}', i);
      if (end == std::string::npos) break;
      std::string expr = s.substr(i + 2, end - i - 2);
      std::string def;
      const std::size_t dash = expr.find(":-");
      if (dash != std::string::npos) {
        def = expr.substr(dash + 2);
        expr = expr.substr(0, dash);
      }
      const char* v = std::getenv(expr.c_str());
      out += (v != nullptr && *v != '\0') ? std::string(v) : def;
      i = end + 1;
    } else {
      out += s[i++];
    }
  }
  if (i < s.size()) out += s.substr(i);
  return out;
}

bool in_private_tmp(const std::string& path, const std::string& mountinfo) {
  // Fields: id parent major:minor root mount-point ... (proc(5)). The deepest mount point holding
  // `path` wins; of equal ones the later line (mounted on top).
  std::istringstream in(mountinfo);
  std::string line, best_mp, best_root;
  bool found = false;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string id, parent, dev, root, mp;
    if (!(ls >> id >> parent >> dev >> root >> mp)) continue;
    const bool under = mp == "/" || path == mp ||
                       (path.size() > mp.size() && path.compare(0, mp.size(), mp) == 0 &&
                        path[mp.size()] == '/');
    if (under && (!found || mp.size() >= best_mp.size())) {
      found = true;
      best_mp = mp;
      best_root = root;
    }
  }
  return found && best_root.find("/systemd-private-") != std::string::npos;
}

namespace {

std::filesystem::path normal_absolute(const std::string& p) {
  auto n = std::filesystem::absolute(p).lexically_normal();
  if (!n.has_filename() && n.has_parent_path() && n != n.root_path()) n = n.parent_path();
  return n;
}

}  // namespace

// Before anything starts (no drive is enabled yet): every path a client relies on is checked here,
// so a wrong one is a configuration error (exit 78, not restarted) instead of exit 1 and a restart
// loop, or a command that "succeeds" into a directory no client can see.
void Daemon::check_paths() {
  namespace fs = std::filesystem;
  std::string mountinfo;
  {
    std::ifstream in("/proc/self/mountinfo");
    std::stringstream ss;
    ss << in.rdbuf();
    mountinfo = ss.str();
  }
  const std::string file = opt_.config_path;
  const std::string sock_key = opt_.socket_path ? "--socket" : file + ": socket.path";
  const fs::path sock = normal_absolute(expand_env(opt_.socket_path ? *opt_.socket_path : cfg_.socket.path));
  std::error_code ec;
  if (!fs::is_directory(sock.parent_path(), ec)) {
    throw StartupConfigError(sock_key + ": the directory " + sock.parent_path().string() +
                             " of the command socket " + sock.string() +
                             " does not exist (create it; the systemd unit's RuntimeDirectory=contourd "
                             "creates /run/contourd)");
  }
  if (in_private_tmp(sock.string(), mountinfo)) {
    throw StartupConfigError(sock_key + ": " + sock.string() +
                             " is inside this service's private /tmp (PrivateTmp=yes), where no "
                             "client can reach it; use /run/contourd/contourd.sock");
  }
  const fs::path tel = normal_absolute(expand_env(cfg_.telemetry.directory));
  const std::string tel_key = file + ": telemetry.directory: ";
  if (in_private_tmp(tel.string(), mountinfo)) {
    throw StartupConfigError(tel_key + tel.string() +
                             " is inside this service's private /tmp (PrivateTmp=yes), where no "
                             "client can read the records; use /var/lib/contourd/records "
                             "(StateDirectory=contourd)");
  }
  // Not fatal: the loop runs without recording (e.g. config/hil.yaml's default
  // /var/lib/contourd/records for a developer who is not root); `record` then refuses, naming it.
  fs::create_directories(tel, ec);
  if (ec || !fs::is_directory(tel)) {
    telemetry_error_ = tel_key + "cannot create " + tel.string() + " (" +
                       (ec ? ec.message() : std::string("not a directory")) + ")";
  } else if (::access(tel.c_str(), W_OK | X_OK) != 0) {
    telemetry_error_ = tel_key + tel.string() + " is not writable by uid " + std::to_string(::getuid());
  }
  if (!telemetry_error_.empty()) spdlog::warn("{}: `record` will refuse", telemetry_error_);
  telemetry_dir_ = tel.string();
}

Daemon::Daemon(config::Config cfg, DaemonOptions opt) : cfg_(std::move(cfg)), opt_(std::move(opt)) {}

Daemon::~Daemon() { stop_components(); }

void Daemon::on_event(const RtEvent& e, const std::string& text) {
  if (e.kind == EventKind::kFault) {
    std::lock_guard lk(jobs_mu_);
    recent_faults_.push_back(text);
    if (recent_faults_.size() > 32) recent_faults_.erase(recent_faults_.begin());
    auto it = jobs_.find(e.job);
    if (it != jobs_.end()) it->second.faults.push_back(text);
  }
  if (server_) server_->publish("events", {{"event", "log"}, {"text", text}});
}

// Bus messages come from the bus's own non-RT event thread (CANopen: EMCY, heartbeat loss,
// missed-TPDO faults, NMT changes, start-up/stop). Fault-like ones also go into the fault lists of
// `status` and of the running job, next to the loop's own fault (which names the cause).
void Daemon::on_bus_message(const std::string& text) {
  const bool faultish = text.find("EMCY") != std::string::npos ||
                        text.find("fault") != std::string::npos ||
                        text.find("heartbeat lost") != std::string::npos ||
                        text.find("missed") != std::string::npos;
  if (!faultish) {
    spdlog::info("{}", text);
    return;
  }
  spdlog::warn("{}", text);
  // loop_ and server_ are assigned on the main thread after the bus starts: use them only once
  // start_components has published them.
  const bool ready = components_ready_.load(std::memory_order_acquire);
  // The job the message belongs to: the running one, or the one that ended (e.g. by this very
  // fault) less than a second of cycles ago: the bus's event thread reports within ~20 ms.
  std::uint64_t job = 0;
  if (ready) {
    const auto st = loop_->status();
    const auto recent = static_cast<std::uint64_t>(1.0 / loop_->period_s());
    job = st.attached_job != 0                                        ? st.attached_job
          : st.finished_job != 0 && st.cycle < st.finished_cycle + recent ? st.finished_job
                                                                          : 0;
  }
  {
    std::lock_guard lk(jobs_mu_);
    recent_faults_.push_back(text);
    if (recent_faults_.size() > 32) recent_faults_.erase(recent_faults_.begin());
    auto it = jobs_.find(job);
    if (it != jobs_.end()) it->second.faults.push_back(text);
  }
  if (ready) server_->publish("events", {{"event", "log"}, {"text", text}});
}

void Daemon::start_components() {
  bus_ = make_axis_bus(cfg_, [this](const std::string& m) { on_bus_message(m); });
  bus_->start();
  io_ = std::make_unique<IoChannels>(cfg_, [](const std::string& m) { spdlog::info("{}", m); });
  if (!io_->has_estop_input() && cfg_.bus.type != "sim") {
    spdlog::warn("no gpio E-stop input configured: the software does not see the machine's "
                 "E-stop chain (the hardware chain still acts on the drives)");
  }
  LoopOptions lopt;
  lopt.force_stale_faults = cfg_.force.stale_faults;  // force.fallback: fault
  loop_ = std::make_unique<ServoLoop>(cfg_, *bus_, 4096, io_.get(), lopt);
  if (cfg_.plc.present) {
    // Soft PLC (issue 20): its GPIO signals share the daemon's simulated backend (gpio.backend:
    // sim); on real lines it opens its own. Scanned in the loop's `logic` stage.
    plc_ = std::make_unique<PlcEngine>(cfg_, io_->sim_gpio(),
                                       [](const std::string& m) { spdlog::info("plc: {}", m); });
    loop_->attach_plc(plc_.get());
    plc_->start();
  }
  io_->start([this] {
    const auto st = loop_->status();
    return IoOutputs{st.out_drive_enable, st.out_spindle_enable, st.out_mist, st.out_flood, st.cycle};
  });
  writer_ = std::make_unique<TelemetryWriter>(loop_->telemetry(), loop_->period_s());
  // Every sample the loop produces goes to the `telemetry` subscribers, in batches (issue 21:
  // the scope needs all of them; a client asks for decimation itself).
  writer_->set_batch_stream([this](std::span<const StreamSample> batch) {
    if (components_ready_.load(std::memory_order_acquire)) {
      server_->publish_stream("telemetry", make_stream_chunk(batch, writer_->dropped()));
    }
  });
  writer_->start();
  logger_ = std::make_unique<EventLogger>(loop_->events(),
                                          [this](const RtEvent& e, const std::string& t) { on_event(e, t); });
  logger_->set_describer([this](const RtEvent& e) -> std::string {
    // A fault the PLC engine latched (detail: its kind) names what it is about: a stale coupler
    // by name and endpoint, not "axis <index>". The index is in the loop's PLC cause, noted in
    // the event's cycle and kept until a reset (FAULT takes no other engine fault).
    if (e.kind == EventKind::kFault && e.cause == FaultCause::kPlcFault && e.detail != 0) {
      const auto kind = static_cast<PlcFaultKind>(e.detail);
      std::ostringstream o;
      o << "cycle " << e.cycle << ": FAULT " << to_string(e.cause) << ": " << to_string(kind);
      if (kind == PlcFaultKind::kIoStale) {
        // The loop publishes its status at the end of the event's cycle: wait for that (bounded).
        LoopStatus st = loop_->status();
        for (int k = 0; k < 100 && st.cycle < e.cycle; ++k) {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
          st = loop_->status();
        }
        const PlcStopCause c = st.plc_cause;
        const auto i = static_cast<std::size_t>(c.axis);
        if (c.action == PlcAction::kEngineFault && c.engine == kind && c.axis >= 0 &&
            i < cfg_.plc.modbus.size()) {
          const auto& dev = cfg_.plc.modbus[i];
          o << ": coupler " << dev.name << " ("
            << (dev.transport.transport == drivers::modbus::Transport::kTcp
                    ? dev.transport.host + ":" + std::to_string(dev.transport.port)
                    : dev.transport.device)
            << ")";
        }
        o << ", inputs " << e.value << " s old > stale_ms " << e.limit * 1e3;
      } else if (kind == PlcFaultKind::kMcodeTimeout || kind == PlcFaultKind::kToolChangeTimeout) {
        o << " after " << e.limit << " s";
      }
      return o.str();
    }
    // A programmed pause names its line and what it waits for (M6: the tool to load). Pauses
    // happen only in programs, which the planner (created below) planned.
    if (e.kind != EventKind::kProgramPause || planner_ == nullptr) return {};
    const std::string msg = planner_->message(e.job, e.axis);
    const ProgramPlanner::HoldSite at = planner_->message_site(e.job, e.axis);
    if (at.line == 0) return {};
    return "program paused at line " + std::to_string(at.line) + ": " +
           (msg.empty() ? std::string("program stop (M0/M1)") : msg);
  });
  logger_->start();
  planner_ = std::make_unique<ProgramPlanner>(cfg_);
  planner_->set_machine_data(machine_data_.get());

  RtSetupRequest req;
  req.priority = cfg_.loop.priority;
  req.cpu = cfg_.loop.cpu;
  req.lock_memory = cfg_.loop.lock_memory;
  req.require_realtime = cfg_.loop.require_realtime;
  if (req.priority == 0) req.require_realtime = false;
  rt_report_ = rt_.start(req, [this] { loop_->run(rt_stop_); });
  config_warnings_ = config::identification_warnings(cfg_.machine);
  for (const auto& w : config_warnings_) spdlog::warn("config: {}", w);
  for (const auto& w : rt_report_.warnings) {
    spdlog::warn("REAL-TIME NOT AVAILABLE: {} (the loop runs, but its timing is not guaranteed; "
                 "set loop.require_realtime: true to refuse)", w);
  }
  spdlog::info("RT loop: {} period {} us, {}, memory {}", bus_->describe(), cfg_.loop.period_us,
               rt_report_.realtime ? "SCHED_FIFO" : "SCHED_OTHER", rt_report_.memory_locked ? "locked" : "not locked");

  CommandServerOptions so;
  so.path = expand_env(opt_.socket_path ? *opt_.socket_path : cfg_.socket.path);
  so.mode = static_cast<mode_t>(cfg_.socket.mode);
  so.group = cfg_.socket.group;
  so.max_clients = static_cast<std::size_t>(cfg_.socket.max_clients);
  so.max_line_bytes = static_cast<std::size_t>(cfg_.socket.max_line_bytes);
  so.idle_timeout_s = cfg_.socket.idle_timeout_s;
  so.max_requests_per_s = cfg_.socket.max_requests_per_s;
  so.max_backlog_bytes = static_cast<std::size_t>(cfg_.socket.max_buffered_bytes);
  server_ = std::make_unique<CommandServer>(
      so, [this](const nlohmann::json& r, const ClientInfo& c) { return handle(r, c); },
      [this](const ServerNotice& n) {
        // Server thread, no server lock held: log it and tell the `events` subscribers.
        spdlog::warn("{}", n.text);
        server_->publish("events", {{"event", "socket"},
                                    {"action", to_string(n.kind)},
                                    {"client", {{"id", n.client.id}, {"pid", n.client.pid},
                                                {"uid", n.client.uid}, {"fd", n.client.fd}}},
                                    {"text", n.text}});
      });
  server_->on_disconnect([this](const ClientInfo& c) { jog_deadman(c.id, "its client disconnected"); });
  server_->start();
  components_ready_.store(true, std::memory_order_release);
  spdlog::info("command socket {}", so.path);
}

void Daemon::jog_deadman(std::uint64_t client_id, const char* why) {
  std::uint64_t owner = client_id;
  if (client_id == 0 || !jog_owner_.compare_exchange_strong(owner, 0)) return;
  // Harmless when the jog has already ended (the loop brakes only an active jog; a newer jog
  // would have taken the ownership away).
  loop_->post({CommandKind::kJogBrake});
  spdlog::warn("continuous jog braked: {} (client {}, dead-man safety.jog_deadman_ms {})", why,
               client_id, cfg_.safety.jog_deadman_ms);
}

void Daemon::check_jog_deadman() {
  const std::uint64_t owner = jog_owner_.load();
  if (owner == 0) return;
  if (!loop_->status().jogging) {
    // Ended (soft limit, `stop`, a state change): the connection owns nothing any more (the owner
    // is set only once the loop jogs).
    std::uint64_t o = owner;
    jog_owner_.compare_exchange_strong(o, 0);
    return;
  }
  const auto age_ns = std::chrono::steady_clock::now().time_since_epoch().count() - jog_renewed_ns_.load();
  if (static_cast<double>(age_ns) > cfg_.safety.jog_deadman_ms * 1e6) {
    jog_deadman(owner, "no request from its client within safety.jog_deadman_ms");
  }
}

void Daemon::stop_components() {
  components_ready_.store(false, std::memory_order_release);
  if (server_) server_->stop();
  if (planner_) planner_->abort_and_join();
  if (rt_.joinable()) {
    rt_stop_.store(true, std::memory_order_release);
    rt_.join();
  }
  if (plc_) plc_->stop();  // after the loop: PLC outputs to their defaults
  if (io_) io_->stop();  // after the loop: outputs to their safe state
  if (bus_) bus_->stop();
  if (writer_) writer_->stop();
  if (logger_) logger_->stop();
  server_.reset();
  spdlog::default_logger()->flush();
}

MachineState Daemon::post_and_wait(const LoopCommand& c, MachineState from, double timeout_s) {
  const std::uint64_t c0 = loop_->status().cycle;
  if (!loop_->post(c)) throw CommandError("command queue full; retry");
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  // Give the loop at least two cycles to take the command, then until the state changes.
  while (std::chrono::steady_clock::now() < until) {
    const auto st = loop_->status();
    if (st.cycle >= c0 + 2 && st.state != from) return st.state;
    if (st.cycle >= c0 + 2 && c.kind != CommandKind::kEnable && c.kind != CommandKind::kReset &&
        c.kind != CommandKind::kStop) {
      return st.state;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return loop_->status().state;
}

void Daemon::controlled_shutdown() {
  spdlog::info("shutdown: controlled stop, drives disabled");
  auto st = loop_->status();
  if (st.state == MachineState::kRunning || st.state == MachineState::kHold) {
    loop_->post({CommandKind::kStop});
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < until) {
      st = loop_->status();
      if (st.state != MachineState::kRunning && st.state != MachineState::kHold) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  loop_->post({CommandKind::kDisable});
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (std::chrono::steady_clock::now() < until) {
    st = loop_->status();
    if (!st.drives_enabled && st.state != MachineState::kFault) break;
    if (!st.drives_enabled && st.cmd_mm_s == std::array<double, 3>{}) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  st = loop_->status();
  spdlog::info("shutdown: state {}, drives {}", to_string(st.state),
               st.drives_enabled ? "STILL ENABLED" : "disabled");
}

namespace {

std::string change_text(const KeyChange& c) { return c.key + ": " + c.old_value + " -> " + c.new_value; }

}  // namespace

nlohmann::json Daemon::reload_json() const {
  std::lock_guard lk(reload_mu_);
  nlohmann::json pending = nlohmann::json::array();
  for (const auto& [k, v] : pending_restart_) pending.push_back(k);
  return {{"file", opt_.config_path},
          {"warnings", config_warnings_},
          {"reloads", reloads_.load()},
          {"reloads_rejected", reloads_rejected_.load()},
          {"pending_restart", pending},
          {"last_reload",
           {{"cycle", last_reload_.cycle},
            {"applied", last_reload_.applied},
            {"refused", last_reload_.refused}}}};
}

// SIGHUP (issue 16: "every change is applied or refused, never ignored"). The new file must load
// as a whole (else nothing changes); then each changed key is applied or refused on its own.
void Daemon::reload_config() {
  spdlog::info("SIGHUP: reloading {}", opt_.config_path);
  config::Config n;
  YAML::Node tree;
  try {
    tree = config::load_yaml_file(opt_.config_path);
    n = config::load_config_file(opt_.config_path);
  } catch (const config::ConfigError& e) {
    for (const auto& m : e.errors()) spdlog::error("SIGHUP: {}", m);
    spdlog::error("SIGHUP: configuration rejected; nothing changed");
    ++reloads_rejected_;
    return;
  } catch (const std::exception& e) {
    spdlog::error("SIGHUP: {}; nothing changed", e.what());
    ++reloads_rejected_;
    return;
  }
  const std::vector<KeyChange> changes = diff_config(running_yaml_, tree);
  ReloadReport rep;
  auto applied = [&](const KeyChange& c) { rep.applied.push_back(change_text(c)); };
  auto refused = [&](const KeyChange& c, const std::string& why) {
    rep.refused.push_back(change_text(c) + ": " + why);
  };
  const bool same_axes = n.machine.axes.size() == cfg_.machine.axes.size();
  bool any_gains = false, any_limits = false;
  for (const auto& c : changes) {
    any_gains = any_gains || c.cls == ReloadClass::kGains;
    any_limits = any_limits || (c.cls == ReloadClass::kLimits && same_axes);
  }

  // Gains: the whole control section through the same checks as `gains set`.
  std::string gains_error;
  if (any_gains) {
    try {
      const auto p = servo_params_for(n.control);
      const control::StabilityVerdict v = check_gains(p, cfg_.machine);
      if (!v.stable) throw std::runtime_error(v.reason);
      const auto gen = loop_->stage_gains(p);
      cfg_.control = n.control;
      spdlog::info("SIGHUP: control gains staged (generation {}, state {})", gen,
                   to_string(loop_->status().state));
    } catch (const std::exception& e) {
      gains_error = e.what();
    }
  }

  // Live limits: the running values, with each changed live key taken from the new file unless a
  // rule refuses it (a soft limit that would put an axis outside it while it stands there).
  std::map<std::string, std::string> limit_refusals;
  if (any_limits) {
    config::Config c = cfg_;
    c.safety.ferror_mm = n.safety.ferror_mm;
    c.safety.min_ferror_mm = n.safety.min_ferror_mm;
    c.safety.contour_error_limit_mm = n.safety.contour_error_limit_mm;
    c.safety.stop_decel_mm_s2 = n.safety.stop_decel_mm_s2;
    c.safety.standstill_velocity_mm_s = n.safety.standstill_velocity_mm_s;
    c.safety.standstill_time_s = n.safety.standstill_time_s;
    c.safety.standstill_timeout_s = n.safety.standstill_timeout_s;
    c.safety.jog_max_velocity_mm_min = n.safety.jog_max_velocity_mm_min;
    c.interpolator.feed_override_max_percent = n.interpolator.feed_override_max_percent;
    c.interpolator.rapid_override_max_percent = n.interpolator.rapid_override_max_percent;
    c.spindle.override_min_percent = n.spindle.override_min_percent;
    c.spindle.override_max_percent = n.spindle.override_max_percent;
    const auto st = loop_->status();
    for (std::size_t i = 0; i < c.machine.axes.size(); ++i) {
      auto& a = c.machine.axes[i];
      const auto& b = n.machine.axes[i];
      a.max_velocity_mm_min = b.max_velocity_mm_min;
      a.max_accel_mm_s2 = b.max_accel_mm_s2;
      const double pos = st.act_mm[i];
      const std::string key = "machine.axes[" + std::to_string(i) + "].";
      auto soft = [&](double& dst, double v, const char* name, bool is_min) {
        if (dst == v) return;
        if (is_min ? pos < v : pos > v) {
          limit_refusals[key + name] = "axis " + a.name + " is at " + std::to_string(pos) +
                                       " mm, outside the new limit (move it inside first)";
          return;
        }
        dst = v;
      };
      soft(a.min_mm, b.min_mm, "min_mm", true);
      soft(a.max_mm, b.max_mm, "max_mm", false);
    }
    try {
      const LiveLimits l = live_limits_from(c);
      if (!(l == loop_->active_limits())) {
        const auto gen = loop_->stage_limits(l);
        spdlog::info("SIGHUP: safety limits staged (generation {})", gen);
      }
      cfg_.safety = c.safety;
      cfg_.interpolator.feed_override_max_percent = c.interpolator.feed_override_max_percent;
      cfg_.interpolator.rapid_override_max_percent = c.interpolator.rapid_override_max_percent;
      cfg_.spindle.override_min_percent = c.spindle.override_min_percent;
      cfg_.spindle.override_max_percent = c.spindle.override_max_percent;
      cfg_.machine = c.machine;
      planner_->set_live(cfg_);
    } catch (const std::exception& e) {
      limit_refusals["*"] = e.what();
    }
  }

  std::lock_guard lk(reload_mu_);
  for (const auto& c : changes) {
    // A key back at its running value is no longer pending (reported as such).
    const auto pend = pending_restart_.find(c.key);
    if (pend != pending_restart_.end() && pend->second == c.new_value) {
      pending_restart_.erase(pend);
      rep.applied.push_back(change_text(c) + " (back to the running value)");
      continue;
    }
    switch (c.cls) {
      case ReloadClass::kGains:
        if (gains_error.empty()) applied(c);
        else refused(c, "gains refused: " + gains_error);
        break;
      case ReloadClass::kLimits: {
        if (!same_axes) {
          refused(c, "needs restart (the number of axes changed)");
          break;
        }
        auto r = limit_refusals.find(c.key);
        if (r == limit_refusals.end()) r = limit_refusals.find("*");
        if (r != limit_refusals.end()) refused(c, "refused: " + r->second);
        else applied(c);
        break;
      }
      case ReloadClass::kLog:
        spdlog::set_level(spdlog::level::from_str(n.log.level));
        cfg_.log.level = n.log.level;
        applied(c);
        break;
      case ReloadClass::kCompanion:
        refused(c, "not used by contourd: restart contour-web / contour-bridge to apply it");
        break;
      case ReloadClass::kRestart:
        refused(c, "needs restart");
        if (pend == pending_restart_.end()) pending_restart_[c.key] = c.old_value;
        break;
    }
  }
  rep.cycle = loop_->status().cycle;
  for (const auto& a : rep.applied) spdlog::info("SIGHUP: applied {}", a);
  for (const auto& r : rep.refused) spdlog::warn("SIGHUP: {}", r);
  if (changes.empty()) spdlog::info("SIGHUP: no key changed");
  if (server_) {
    server_->publish("events", {{"event", "reload"}, {"applied", rep.applied}, {"refused", rep.refused}});
  }
  last_reload_ = std::move(rep);
  running_yaml_ = tree;
  // Counted only now, under reload_mu_ with last_reload_: a client that sees the count go up
  // sees this reload's report with it.
  ++reloads_;
}

control::ServoParams Daemon::servo_params_for(const config::ControlConfig& control) const {
  std::array<control::FeedDriveParams, 3> dp{};
  int delay = 0;
  for (std::size_t i = 0; i < cfg_.machine.axes.size() && i < 3; ++i) {
    dp[i] = cfg_.machine.axes[i].drive;
    dp[i].period_s = cfg_.machine.period_s;
    delay = std::max(delay, dp[i].delay_cycles);
  }
  return config::make_servo_params(control, control.controller, dp,
                                   static_cast<int>(cfg_.machine.axes.size()),
                                   cfg_.machine.period_s, delay);
}

// SIGUSR1 = E-stop, SIGUSR2 = hold: the out-of-band path that does not go through the command
// socket or its thread (a client stuck in a long handler, a full or flooded socket cannot delay
// it). Main thread, after sigtimedwait: posting to the loop's command ring is all it does besides
// logging; the loop applies it at the next cycle.
void Daemon::out_of_band_signal(int sig, pid_t from_pid, uid_t from_uid) {
  const bool estop = sig == SIGUSR1;
  const char* name = estop ? "SIGUSR1" : "SIGUSR2";
  const auto st = loop_->status();
  std::string text;
  if (estop) {
    if (!loop_->post({CommandKind::kEstop})) {
      // The ring is full only if the loop stopped taking commands: the hardware chain is the
      // answer then; say so loudly.
      text = std::string("E-STOP by ") + name + " from pid " + std::to_string(from_pid) + " uid " +
             std::to_string(from_uid) + " NOT POSTED: loop command queue full";
      spdlog::critical("{}", text);
    } else {
      text = std::string("E-STOP by ") + name + " from pid " + std::to_string(from_pid) + " uid " +
             std::to_string(from_uid) + " (state " + std::string(to_string(st.state)) + ")";
      spdlog::warn("{}", text);
    }
  } else if (st.state == MachineState::kRunning) {
    const bool posted = loop_->post({CommandKind::kHold});
    text = std::string("hold by ") + name + " from pid " + std::to_string(from_pid) + " uid " +
           std::to_string(from_uid) + (posted ? "" : " NOT POSTED: loop command queue full");
    spdlog::warn("{}", text);
  } else {
    text = std::string("hold by ") + name + " from pid " + std::to_string(from_pid) + " uid " +
           std::to_string(from_uid) + " ignored: nothing running (state " +
           std::string(to_string(st.state)) + ")";
    spdlog::info("{}", text);
  }
  if (server_) server_->publish("events", {{"event", "log"}, {"text", text}});
}

int Daemon::run() {
  setup_logging(cfg_.log);
  // Signals are handled synchronously on the main thread; every thread inherits the mask.
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGHUP);
  sigaddset(&set, SIGUSR1);
  sigaddset(&set, SIGUSR2);
  sigaddset(&set, SIGPIPE);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  try {
    running_yaml_ = config::load_yaml_file(opt_.config_path);
  } catch (const std::exception& e) {
    spdlog::warn("cannot re-read {} for SIGHUP comparisons: {}", opt_.config_path, e.what());
  }
  try {
    check_paths();
    open_machine_data();
    // The configured gains against the loop this machine runs (daemon/gains_check.hpp): a set
    // that would oscillate is a configuration error, before any drive is enabled.
    {
      const control::StabilityVerdict v = check_gains(servo_params_for(cfg_.control), cfg_.machine);
      if (!v.stable) {
        throw StartupConfigError(opt_.config_path + ": control: gains refused by the stability check: " +
                                 v.reason);
      }
    }
    start_components();
  } catch (const StartupConfigError& e) {
    spdlog::critical("start-up failed: {}", e.what());
    stop_components();
    return 78;  // EX_CONFIG: RestartPreventExitStatus=78
  } catch (const std::exception& e) {
    spdlog::critical("start-up failed: {}", e.what());
    stop_components();
    return 1;
  }
  // Enable the drives; READY=1 once they are enabled and the loop runs.
  loop_->post({CommandKind::kEnable});
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (std::chrono::steady_clock::now() < until && loop_->status().state != MachineState::kReady) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const LoopStatus first = loop_->status();
  if (first.state == MachineState::kFault || first.state == MachineState::kEstop) {
    // A latched fault or E-stop at power-up (E-stop pressed, a machine-logic fault such as a
    // coupler not answering yet, a drive fault): the machine comes up in FAULT/ESTOP with the
    // cause in status, as a control does, and `reset` brings it to READY once the cause is gone.
    // Exiting instead would hide the cause and make systemd restart the daemon in a loop.
    spdlog::error("started in {} (cause {}): the loop runs with the drives disabled; reset once "
                  "the cause is gone", to_string(first.state), to_string(first.cause));
    sd_notify(0, "READY=1\nSTATUS=FAULT or ESTOP at start-up, loop running: reset once the cause is gone");
  } else if (first.state != MachineState::kReady) {
    spdlog::critical("drives did not enable within 5 s (state {})", to_string(first.state));
    stop_components();
    return 1;
  } else {
    sd_notify(0, "READY=1\nSTATUS=drives enabled, loop running");
    spdlog::info("ready: drives enabled, loop running");
  }
  std::uint64_t wd_usec = 0;
  const bool watchdog = sd_watchdog_enabled(0, &wd_usec) > 0;
  std::uint64_t last_cycle = loop_->status().cycle;
  auto last_wd = std::chrono::steady_clock::now();
  sigdelset(&set, SIGPIPE);
  while (!shutdown_.load()) {
    timespec ts{0, 100'000'000};
    siginfo_t info{};
    const int sig = sigtimedwait(&set, &info, &ts);
    if (sig == SIGTERM || sig == SIGINT) {
      spdlog::info("signal {}: shutting down", sig == SIGTERM ? "SIGTERM" : "SIGINT");
      break;
    }
    if (sig == SIGHUP) reload_config();
    if (sig == SIGUSR1 || sig == SIGUSR2) out_of_band_signal(sig, info.si_pid, info.si_uid);
    free_released_jobs();
    check_jog_deadman();
    if (watchdog) {
      const auto now = std::chrono::steady_clock::now();
      const std::uint64_t c = loop_->status().cycle;
      // Only while the loop's cycle counter advances: a stuck loop stops the pings.
      if (c != last_cycle && now - last_wd > std::chrono::microseconds(wd_usec / 4)) {
        sd_notify(0, "WATCHDOG=1");
        last_wd = now;
        last_cycle = c;
      }
    }
  }
  sd_notify(0, "STOPPING=1");
  controlled_shutdown();
  stop_components();
  return 0;
}

}  // namespace contour::daemon
