// Command socket handlers (Daemon::handle). Every argument is validated with a clear error; a
// command that is illegal in the current state gets an error reply naming the state.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <limits>
#include <thread>

#include <cstdio>

#include "daemon/command_table.hpp"
#include "daemon/commands.hpp"
#include "daemon/identify.hpp"
#include "daemon/sim_bus.hpp"
#include "daemon/daemon.hpp"
#include "daemon/gains_check.hpp"

namespace contour::daemon {

namespace {

using nlohmann::json;

const json& arg(const json& req, const char* key) {
  if (!req.contains(key)) throw CommandError(std::string("missing argument '") + key + "'");
  return req.at(key);
}

json arr3(const std::array<double, 3>& a, int axes) {
  json j = json::array();
  for (int i = 0; i < axes; ++i) j.push_back(a[static_cast<std::size_t>(i)]);
  return j;
}

}  // namespace

int axis_index(const json& v, const config::MachineConfig& m) {
  if (v.is_number_integer()) {
    const auto i = v.get<long>();
    if (i < 0 || i >= static_cast<long>(m.axes.size())) throw CommandError("axis index out of range");
    return static_cast<int>(i);
  }
  if (v.is_string()) {
    const auto s = v.get<std::string>();
    for (std::size_t i = 0; i < m.axes.size(); ++i) {
      if (m.axes[i].name == s || (s.size() == 1 && m.axes[i].name.size() == 1 &&
                                  std::toupper(static_cast<unsigned char>(s[0])) == m.axes[i].name[0])) {
        return static_cast<int>(i);
      }
    }
    throw CommandError("unknown axis '" + s + "'");
  }
  throw CommandError("argument 'axis' must be an axis name or index");
}

json Daemon::counters_json(const LoopStatus& st) const {
  json faults = json::object();
  for (std::size_t c = 1; c < kFaultCauseCount; ++c)
    faults[std::string(to_string(static_cast<FaultCause>(c)))] = st.fault_counts[c];
  json j{{"faults", faults},
         {"resets", st.resets},
         {"emcy_frames", st.emcy_frames},
         {"missed_tpdos", st.missed_tpdos},
         {"reloads", reloads_.load()},
         {"reloads_rejected", reloads_rejected_.load()}};
  if (server_) {
    const auto s = server_->stats();
    j["socket"] = {{"connections", s.connections},
                   {"requests", s.requests},
                   {"errors", s.errors},
                   {"dropped_clients", s.dropped_clients},
                   {"dropped_idle", s.dropped_idle},
                   {"evicted_idle", s.evicted_idle},
                   {"rate_limited", s.rate_limited},
                   {"oversize_buffer", s.oversize_buffer},
                   {"notices_suppressed", s.notices_suppressed},
                   {"stream_samples_sent", s.stream_samples_sent},
                   {"stream_dropped", s.stream_dropped},
                   {"clients", s.clients}};
  }
  return j;
}

namespace {

std::string homing_failure_status(const LoopStatus& st, const config::MachineConfig& m) {
  std::string t = homing_failure_text(st.homing_failure);
  const auto a = static_cast<std::size_t>(st.homing_failure_axis);
  if (st.homing_failure_axis >= 0 && a < m.axes.size()) {
    t = m.axes[a].name + ": " + t;
    const auto v = static_cast<std::uint32_t>(st.homing_failure_value);
    char buf[96];
    if (st.homing_failure == 11) {
      std::snprintf(buf, sizeof buf, " (node %d, object 0x%04X:%02X)", m.axes[a].node_id,
                    static_cast<unsigned>(v >> 8), static_cast<unsigned>(v & 0xFFu));
      t += buf;
    } else if (st.homing_failure == 10) {
      std::snprintf(buf, sizeof buf, " (node %d, statusword 0x%04X)", m.axes[a].node_id, static_cast<unsigned>(v));
      t += buf;
    } else if (st.homing_failure == 9) {
      std::snprintf(buf, sizeof buf, " (%.1f s)", st.homing_failure_value);
      t += buf;
    }
  }
  return t;
}

}  // namespace

json Daemon::status_json() {
  const auto st = loop_->status();
  const int axes = loop_->axes();
  auto& cs = loop_->stats();
  const auto& h = cs.wake_lateness;
  json homed = json::object();
  json phases = json::object();
  json shifts = json::object();
  for (int i = 0; i < axes; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const std::string& n = cfg_.machine.axes[a].name;
    homed[n] = (st.homed_mask >> i & 1u) != 0;
    phases[n] = to_string(static_cast<HomingSource::Phase>(st.home_phase[a]));
    shifts[n] = st.home_shift_mm[a];
  }
  json j{{"state", to_string(st.state)},
         {"cause", to_string(st.cause)},
         {"homed", homed},
         {"homing", {{"active", st.homing},
                     {"phase", phases},
                     {"required", !cfg_.machine.allow_unhomed},
                     {"runs", st.homing_runs},
                     {"failure", st.homing_failure == 0 ? json() : json(homing_failure_status(st, cfg_.machine))},
                     {"machine_minus_encoder_mm", shifts}}},
         {"source", to_string(st.source)},
         {"cycle", st.cycle},
         {"ref_mm", arr3(st.ref_mm, axes)},
         {"act_mm", arr3(st.act_mm, axes)},
         {"cmd_mm_s", arr3(st.cmd_mm_s, axes)},
         {"contour_error_um", st.eps_norm_mm * 1e3},
         {"progress_mm", st.progress_mm},
         {"line", st.line},
         {"override", st.override_applied},
         {"feed_override", st.feed_override},
         {"rapid_override", st.rapid_override},
         {"spindle_override", st.spindle_override},
         {"on_rapid", st.on_rapid},
         {"switches",
          {{"block_delete", planner_->block_delete()},
           {"optional_stop", st.optional_stop},
           {"single_block", st.single_block}}},
         {"job", st.attached_job},
         {"loaded_job", loaded_job_},
         {"finished_job", st.finished_job},
         {"finished_ok", st.finished_ok},
         {"jogging", st.jogging},
         {"program_hold", st.interp_holding},
         {"drives_enabled", st.drives_enabled},
         {"recording", writer_->recording()},
         {"gains_generation", st.gains_generation},
         {"gains_cycle", st.gains_cycle},
         {"underruns", st.underruns},
         {"missed_tpdos", st.missed_tpdos},
         {"velocity_clamps", st.velocity_clamps},
         {"accel_clamps", st.accel_clamps},
         {"chatter",
          {{"level", st.chatter_level == 2 ? "fault" : st.chatter_level == 1 ? "warning" : "ok"},
           {"window_mm_s", arr3(st.chatter_window_mm_s, axes)},
           {"window_clamps_per_s", arr3(st.chatter_window_clamps_per_s, axes)},
           {"job", st.chatter_job},
           {"job_rms_mm_s", arr3(st.job_chatter_rms_mm_s, axes)},
           {"job_max_mm_s", arr3(st.job_chatter_max_mm_s, axes)}}},
         {"limits_generation", st.limits_generation},
         {"stop", to_string(st.stop_phase)},
         {"soft_limits_mm", {{"min", arr3(st.soft_min_mm, axes)}, {"max", arr3(st.soft_max_mm, axes)}}},
         {"spindle_rpm_cmd", st.spindle_rpm_cmd},
         {"counters", counters_json(st)},
         {"config", reload_json()},
         {"spindle",
          {{"present", st.spindle_present},
           {"feedback", st.spindle_feedback},
           {"target_rpm", st.spindle_target_rpm},
           {"command_rpm", st.spindle_rpm_cmd},
           {"actual_rpm", st.spindle_actual_rpm},
           {"at_speed", st.spindle_at_speed},
           {"waiting", st.spindle_waiting},
           {"waits", st.spindle_waits},
           {"last_wait_s", st.spindle_last_wait_s}}},
         {"force", force_json()},
         {"gpio", gpio_json()},
         {"plc", plc_brief_json(st)},
         {"telemetry_dropped", writer_->dropped()},
         {"events_dropped", logger_->dropped()},
         {"timing",
          {{"cycles", cs.cycles.load()},
           {"overruns", cs.overruns.load()},
           {"skipped_periods", cs.skipped_periods.load()},
           {"compute_max_us", static_cast<double>(cs.compute_max_ns.load()) / 1e3},
           {"compute_last_us", static_cast<double>(cs.compute_last_ns.load()) / 1e3},
           {"lateness_max_us", static_cast<double>(h.max_ns()) / 1e3},
           {"lateness_mean_us", h.mean_us()},
           {"lateness_p99_us", h.quantile_us(0.99)},
           {"realtime", rt_report_.realtime},
           {"memory_locked", rt_report_.memory_locked}}}};
  {
    // Non-empty bins only (1 us wide up to 20 ms): what `contourctl plot --kind timing` draws.
    json lows = json::array(), counts = json::array();
    for (int i = 0; i < LatencyHistogram::kBins; ++i) {
      if (h.bin_count(i) == 0) continue;
      lows.push_back(LatencyHistogram::bin_low_us(i));
      counts.push_back(h.bin_count(i));
    }
    j["timing"]["lateness_p999_us"] = h.quantile_us(0.999);
    j["timing"]["lateness_histogram"] = {{"bin_low_us", lows}, {"count", counts}};
  }
  if (const std::uint64_t job = st.attached_job != 0 ? st.attached_job : loaded_job_; job != 0) {
    // The program being run (or last loaded): size, progress and its contour-error figures so far.
    std::lock_guard lk(jobs_mu_);
    auto it = jobs_.find(job);
    if (it != jobs_.end()) {
      const RunStats rs = writer_->stats(job);
      const double len = it->second.length_mm;
      j["program"] = {{"job", job},
                      {"name", it->second.name},
                      {"motion_blocks", it->second.motion_blocks},
                      {"length_mm", len},
                      {"progress_pct", len > 0.0 && st.attached_job == job
                                           ? std::min(100.0, 100.0 * st.progress_mm / len)
                                           : 0.0},
                      {"max_contour_error_um", rs.max_contour_error_um},
                      {"rms_contour_error_um", rs.rms_contour_error_um()}};
    }
  }
  add_machine_status(j, st);
  if (st.fault_axis >= 0 || st.cause != FaultCause::kNone) {
    j["fault"] = {{"cause", to_string(st.cause)}, {"axis", st.fault_axis},
                  {"value", st.fault_value}, {"limit", st.fault_limit}};
    // A heartbeat loss and an I/O-module fault name a CANopen node, not an axis: "axis" carries
    // its node-id (as before), and "node" says so; an axis cause gets the axis' name.
    if (st.cause == FaultCause::kHeartbeatLost || st.cause == FaultCause::kIoModule) {
      j["fault"]["node"] = st.fault_axis;
    } else if (st.fault_axis >= 0 && st.fault_axis < axes) {
      j["fault"]["axis_name"] = cfg_.machine.axes[static_cast<std::size_t>(st.fault_axis)].name;
    }
    // A missed-TPDO streak: which inputs stopped ("position": TPDO1, "digital_inputs": 0x60FD).
    if (st.cause == FaultCause::kMissedTpdo) {
      j["fault"]["pdo"] = st.fault_detail == static_cast<std::uint8_t>(MissedPdo::kDigitalInputs)
                              ? "digital_inputs"
                              : "position";
    }
  }
  // A programmed pause (M0, M1, M6): what it waits for. An M6 is a manual tool change.
  if (st.interp_holding) {
    const std::string msg = planner_->message(st.attached_job, st.hold_message_id);
    const ProgramPlanner::HoldSite at = planner_->message_site(st.attached_job, st.hold_message_id);
    const int line = at.line != 0 ? at.line : st.hold_line;
    j["hold"] = {{"line", line}, {"message", st.hold_single_block ? std::string("single block") : msg}};
    if (msg.rfind("manual tool change", 0) == 0) {
      j["tool_change"] = {{"tool", at.line != 0 ? at.tool : st.hold_tool}, {"line", line},
                          {"message", msg}};
    }
  }
  // The in-process simulated machine only: where the plant really is (tests compare the machine
  // position after homing with it; published at each SYNC).
  if (const auto* sb = dynamic_cast<const SimBus*>(bus_.get())) {
    json t = json::array();
    for (int i = 0; i < axes; ++i) t.push_back(sb->published_true_position_mm(i));
    j["sim_true_mm"] = t;
  }
  return j;
}

json Daemon::force_json() {
  const auto st = loop_->status();
  json j{{"available", st.force_available},
         {"state", drivers::modbus::to_string(st.force_state)},
         {"fx_n", st.force_xyz_N[0]},
         {"fy_n", st.force_xyz_N[1]},
         {"fz_n", st.force_xyz_N[2]},
         {"force_n", st.force_N},
         {"age_ms", st.force_age_s * 1e3},
         {"seq", st.force_seq},
         {"enabled", st.force_requested},
         {"active", st.force_active},
         {"status", control::to_string(st.force_status)},
         {"reference_n", st.force_ref_N},
         {"feed_override", st.force_override},
         {"fallback_active", st.force_fallback},
         {"fallbacks", st.force_fallbacks},
         {"fallback", cfg_.force.limits.fallback == control::ForceFallback::kHold ? "hold"
                                                                                   : "programmed_feed"}};
  if (io_) {
    if (const auto d = io_->dynamometer_status()) {
      j["dynamometer"] = {{"connected", d->connected},       {"polls", d->polls},
                          {"samples", d->samples},           {"timeouts", d->timeouts},
                          {"exceptions", d->exceptions},     {"protocol_errors", d->protocol_errors},
                          {"connection_errors", d->connection_errors},
                          {"reconnects", d->reconnects},     {"invalid", d->invalid},
                          {"last_error", d->last_error}};
    }
  }
  return j;
}

json Daemon::gpio_json() {
  const auto st = loop_->status();
  json j{{"enabled", io_ && io_->has_gpio()},
         {"estop_input", st.estop_input},
         {"requested",
          {{"drive_enable", st.out_drive_enable}, {"spindle_enable", st.out_spindle_enable},
           {"coolant_mist", st.out_mist}, {"coolant_flood", st.out_flood}}}};
  if (io_) {
    if (const auto g = io_->gpio_state()) {
      j["backend"] = cfg_.gpio.backend;
      j["lines"] = {{"estop_asserted", g->estop_asserted}, {"estop_tripped", g->estop_tripped},
                    {"drive_enable", g->drive_enable},     {"spindle_enable", g->spindle_enable},
                    {"coolant_mist", g->coolant_mist},     {"coolant_flood", g->coolant_flood},
                    {"alive", g->alive}};
      j["alive_toggles"] = io_->alive_toggles();
    }
  }
  return j;
}

json Daemon::cmd_force(const json& req) {
  if (!loop_->force_configured()) {
    throw CommandError("force: no force source (configure the `dynamometer:` section)");
  }
  int on = -1;
  if (req.contains("enable")) {
    if (!req["enable"].is_boolean()) throw CommandError("argument 'enable' must be true or false");
    on = req["enable"].get<bool>() ? 1 : 0;
  }
  if (req.contains("action")) {
    const json& a = req["action"];
    if (!a.is_string() || (a != "on" && a != "off")) {
      throw CommandError("argument 'action' must be \"on\" or \"off\"");
    }
    const int v = a == "on" ? 1 : 0;
    if (on >= 0 && on != v) throw CommandError("arguments 'enable' and 'action' disagree");
    on = v;
  }
  double ref = std::nan("");
  for (const char* k : {"reference_N", "reference_n"}) {
    if (req.contains(k)) ref = req.at(k).get<double>();  // range: Bound::kForceReference
  }
  if (on < 0 && std::isnan(ref)) {
    return force_json();  // query
  }
  const auto c0 = loop_->status().cycle;
  if (!loop_->post({CommandKind::kForce, on, ref, 0.0})) throw CommandError("command queue full; retry");
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (loop_->status().cycle < c0 + 2 && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return force_json();
}

json Daemon::cmd_sim_gpio(const json& req) {
  if (!io_ || io_->sim_gpio() == nullptr) {
    throw CommandError("sim_gpio: only with `gpio.backend: sim`");
  }
  const json& l = arg(req, "line");
  if (!l.is_string()) throw CommandError("argument 'line' must be a string (role or line name)");
  const json& v = arg(req, "level");
  bool high = false;
  if (v.is_boolean()) {
    high = v.get<bool>();
  } else if (v.is_number_integer() && (v.get<long>() == 0 || v.get<long>() == 1)) {
    high = v.get<long>() == 1;
  } else {
    throw CommandError("argument 'level' must be 0 or 1 (physical level)");
  }
  const std::string key = io_->sim_key(l.get<std::string>());
  if (key.empty()) throw CommandError("sim_gpio: unknown line '" + l.get<std::string>() + "'");
  if (key != io_->sim_key("estop")) throw CommandError("sim_gpio: '" + key + "' is not an input");
  io_->sim_gpio()->set_input_level(key, high);
  spdlog::warn("sim_gpio: {} set to physical level {}", key, high ? 1 : 0);
  return {{"line", key}, {"level", high ? 1 : 0}};
}

json Daemon::result_json(std::uint64_t job) {
  // Wait until the writer has seen the samples up to the program's end.
  const auto st = loop_->status();
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (st.finished_job == job && writer_->last_cycle() < st.finished_cycle &&
         std::chrono::steady_clock::now() < until && !safety_request_waiting()) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const RunStats rs = writer_->stats(job);
  json faults = json::array();
  std::uint64_t ov0 = 0;
  {
    std::lock_guard lk(jobs_mu_);
    auto it = jobs_.find(job);
    if (it != jobs_.end()) {
      for (const auto& f : it->second.faults) faults.push_back(f);
      ov0 = it->second.overruns_at_start;
    }
  }
  std::string state = std::string(to_string(st.state));
  if (st.attached_job == job) state = std::string(to_string(st.state));
  return {{"job", job},
          {"state", state},
          {"finished", st.finished_job == job},
          {"completed", st.finished_job == job && st.finished_ok},
          {"duration_s", rs.duration_s(loop_->period_s())},
          {"max_contour_error_um", rs.max_contour_error_um},
          {"rms_contour_error_um", rs.rms_contour_error_um()},
          {"max_model_error_um", rs.max_model_error_um},
          {"max_following_error_um", rs.max_following_error_um},
          {"end_overshoot_um", rs.end_overshoot_um},
          {"samples", rs.samples},
          {"telemetry_dropped", writer_->dropped()},
          {"faults", faults},
          {"overruns", loop_->stats().overruns.load() - ov0},
          // RMS / max of the cycle-to-cycle change of each axis' velocity command over the run
          // (issue 16; null once a later program has run).
          {"command_chatter_rms_mm_s", st.chatter_job == job ? arr3(st.job_chatter_rms_mm_s, loop_->axes()) : json()},
          {"command_chatter_max_mm_s", st.chatter_job == job ? arr3(st.job_chatter_max_mm_s, loop_->axes()) : json()}};
}

void Daemon::free_released_jobs() {
  const auto st = loop_->status();
  std::lock_guard lk(jobs_mu_);
  for (auto& [id, rec] : jobs_) {
    // The loop no longer touches a job once released or replaced; keep the record (faults) but
    // drop the interpolator and queue.
    if (rec.job && id != st.attached_job && id != loaded_job_ && id <= st.released_job) rec.job.reset();
  }
  while (jobs_.size() > 64) jobs_.erase(jobs_.begin());
}

json Daemon::cmd_load(const json& req) {
  ProgramText src;
  if (req.contains("path") == req.contains("program")) {
    throw CommandError("load needs exactly one of 'path' (file on the daemon's host) or 'program' (text)");
  }
  if (req.contains("path")) {
    if (!req["path"].is_string()) throw CommandError("argument 'path' must be a string");
    src.path = req["path"].get<std::string>();
    src.name = src.path;
  } else {
    if (!req["program"].is_string()) throw CommandError("argument 'program' must be a string");
    src.text = req["program"].get<std::string>();
    if (src.text.size() > static_cast<std::size_t>(cfg_.socket.max_program_bytes)) {
      throw CommandError("load: the program has " + std::to_string(src.text.size()) +
                         " bytes, more than socket.max_program_bytes = " +
                         std::to_string(cfg_.socket.max_program_bytes));
    }
    src.name = "<inline>";
    if (req.contains("name")) {
      if (!req["name"].is_string()) throw CommandError("argument 'name' must be a string");
      src.name = req["name"].get<std::string>();
    }
  }
  if (req.contains("start_line")) src.start_line = req.at("start_line").get<long>();
  return load_source(src, req.value("preview", false));
}

json Daemon::load_source(const ProgramText& src, bool preview) {
  const auto st = loop_->status();
  if (st.state != MachineState::kReady) {
    throw CommandError(std::string("load is not allowed in state ") + std::string(to_string(st.state)) +
                       " (needs READY)");
  }
  if (st.jogging) throw CommandError("load is not allowed while jogging");
  const Eigen::Vector3d start(st.ref_mm[0], st.ref_mm[1], st.ref_mm[2]);
  ProgramSummary sum;
  double estimated_s = 0.0;
  try {
    sum = planner_->validate(src, start, preview);
    if (src.start_line > sum.lines) {
      throw CommandError("load: start_line " + std::to_string(src.start_line) + " is past the end of " +
                         src.name + " (" + std::to_string(sum.lines) + " lines)");
    }
    if (preview) estimated_s = planner_->estimate_time_s(src, start);
  } catch (const ProgramError& e) {
    throw CommandError(std::string("load: ") + e.what());
  }
  std::uint64_t id = 0;
  {
    std::lock_guard lk(jobs_mu_);
    id = next_job_++;
  }
  writer_->begin_job(id);
  auto job = planner_->start(src, start, id, [this](std::uint64_t j, const control::PlannedSegment& s) {
    writer_->add_segment(j, s);
  });
  ProgramPlanner::wait_prefill(*job, 10.0);
  if (job->planner_failed.load()) throw CommandError("load: " + planner_->error());
  {
    std::lock_guard lk(jobs_mu_);
    jobs_[id] = JobRecord{job, src.name, {}, 0, static_cast<std::size_t>(sum.motion_blocks), sum.length_mm};
  }
  if (!loop_->post({CommandKind::kAttachJob, 0, 0.0, 0.0, job.get()})) {
    throw CommandError("command queue full; retry");
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (loop_->status().attached_job != id && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  if (loop_->status().attached_job != id) throw CommandError("load: the loop did not take the program");
  loaded_job_ = id;
  spdlog::info("loaded {} as job {} ({} lines, {} moves, {:.3f} mm)", src.name, id, sum.lines,
               sum.motion_blocks, sum.length_mm);
  json r{{"job", id}, {"name", src.name}, {"lines", sum.lines}, {"motion_blocks", sum.motion_blocks},
         {"length_mm", sum.length_mm}};
  if (preview) {
    json machine = json::object(), work = json::object();
    for (std::size_t i = 0; i < cfg_.machine.axes.size() && i < 3; ++i) {
      const std::string& n = cfg_.machine.axes[i].name;
      if (sum.has_motion) {
        machine[n] = {sum.machine_min_mm[i], sum.machine_max_mm[i]};
        work[n] = {sum.work_min_mm[i], sum.work_max_mm[i]};
      } else {
        machine[n] = nullptr;
        work[n] = nullptr;
      }
    }
    json path = json::array();
    for (const auto& p : sum.path_mm) path.push_back({p[0], p[1], p[2]});
    r["blocks"] = sum.blocks;
    r["tools"] = sum.tools;
    r["estimated_time_s"] = estimated_s;
    r["extents"] = {{"machine", machine}, {"work", work}};
    r["path_mm"] = std::move(path);
  }
  return r;
}

json Daemon::cmd_gains(const json& req) {
  auto params_json = [this]() {
    const control::ServoParams p = loop_->active_params();
    json kp = json::array(), ki = json::array(), kd = json::array(), ff = json::array();
    for (int i = 0; i < p.axes; ++i) {
      kp.push_back(p.axis[static_cast<std::size_t>(i)].kp);
      ki.push_back(p.axis[static_cast<std::size_t>(i)].ki_per_s);
      kd.push_back(p.axis[static_cast<std::size_t>(i)].kd_s);
      ff.push_back(p.axis[static_cast<std::size_t>(i)].ff);
    }
    const auto st = loop_->status();
    return json{{"law", p.law == control::AxisLaw::kPid ? "pid" : "p"},
                {"kp", kp}, {"ki_per_s", ki}, {"kd_s", kd}, {"ff", ff},
                {"coupling", p.coupling.enable}, {"cp", p.coupling.cp},
                {"ci_per_s", p.coupling.ci_per_s}, {"cd_s", p.coupling.cd_s},
                {"generation", st.gains_generation}, {"active_since_cycle", st.gains_cycle},
                {"identified", [this] {
                   std::lock_guard lk(identified_mu_);
                   return identified_;
                 }()}};
  };
  if (!req.contains("set")) return params_json();
  const json& set = req["set"];
  if (!set.is_object() || set.empty()) throw CommandError("'set' must be a non-empty object of gains");
  // Allowed in every state: the loop swaps with ServoController::set_gains at a cycle boundary,
  // keeping the controller state (integrators rescaled: bumpless integral contribution).
  control::ServoParams p = loop_->active_params();
  auto per_axis = [&](const std::string& key, double control::AxisGains::*field, double lo, double hi) {
    const json& v = set[key];
    std::vector<double> vals;
    if (v.is_number()) {
      vals.assign(static_cast<std::size_t>(p.axes), v.get<double>());
    } else if (v.is_array() && v.size() == static_cast<std::size_t>(p.axes)) {
      for (const auto& x : v) {
        if (!x.is_number()) throw CommandError("gain '" + key + "' entries must be numbers");
        vals.push_back(x.get<double>());
      }
    } else {
      throw CommandError("gain '" + key + "' must be a number or an array of " + std::to_string(p.axes));
    }
    for (std::size_t i = 0; i < vals.size(); ++i) {
      if (!std::isfinite(vals[i]) || vals[i] < lo || vals[i] > hi) {
        throw CommandError("gain '" + key + "' = " + std::to_string(vals[i]) + " out of range [" +
                           std::to_string(lo) + ", " + std::to_string(hi) + "]");
      }
      p.axis[i].*field = vals[i];
    }
  };
  auto scalar = [&](const std::string& key, double lo, double hi) {
    const json& v = set[key];
    if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < lo || v.get<double>() > hi) {
      throw CommandError("gain '" + key + "' must be a number in [" + std::to_string(lo) + ", " +
                         std::to_string(hi) + "]");
    }
    return v.get<double>();
  };
  for (auto it = set.begin(); it != set.end(); ++it) {
    const std::string& k = it.key();
    if (k == "kp") per_axis(k, &control::AxisGains::kp, 0.0, 100.0);
    else if (k == "ki_per_s") per_axis(k, &control::AxisGains::ki_per_s, 0.0, 1e4);
    else if (k == "kd_s") per_axis(k, &control::AxisGains::kd_s, 0.0, 10.0);
    else if (k == "ff") per_axis(k, &control::AxisGains::ff, 0.0, 1.0);
    else if (k == "cp") p.coupling.cp = scalar(k, 0.0, 1e3);
    else if (k == "ci_per_s") p.coupling.ci_per_s = scalar(k, 0.0, 1e5);
    else if (k == "cd_s") p.coupling.cd_s = scalar(k, 0.0, 100.0);
    else if (k == "coupling") {
      if (!it.value().is_boolean()) throw CommandError("gain 'coupling' must be true or false");
      p.coupling.enable = it.value().get<bool>();
    } else {
      throw CommandError("unknown gain '" + k + "' (kp, ki_per_s, kd_s, ff, cp, ci_per_s, cd_s, coupling)");
    }
  }
  // A gain the active law does not use is refused (it would be "accepted" and change nothing).
  for (auto it = set.begin(); it != set.end(); ++it) {
    const std::string why = inactive_gain_reason(it.key(), p);
    if (!why.empty()) throw CommandError("gains rejected: " + why);
  }
  // Stability check against the loop the daemon runs (daemon/gains_check.hpp): refused with the
  // verdict's reason (axis, case, figure); the running gains stay as they are.
  const control::StabilityVerdict v = check_gains(p, cfg_.machine);
  if (!v.stable) {
    spdlog::warn("gains rejected: {}", v.reason);
    throw CommandError("gains rejected: " + v.reason);
  }
  std::uint64_t gen = 0;
  try {
    gen = loop_->stage_gains(p);
  } catch (const std::exception& e) {
    throw CommandError(std::string("gains rejected: ") + e.what());
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (loop_->status().gains_generation < gen && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  spdlog::info("gains generation {} active", gen);
  return params_json();
}

namespace {

// The reply of a jog on an axis that is not homed (homing required): no soft limits, and the speed
// the loop really jogs at (home.unhomed_jog_mm_min at most).
void unhomed_jog_reply(json& r, const config::AxisConfig& ax, double v_mm_min) {
  r["not_homed"] = true;
  r["velocity_mm_min"] = std::min(v_mm_min, ax.home.unhomed_jog_mm_s * 60.0);
}

}  // namespace

json Daemon::cmd_jog(const json& req, const ClientInfo& client) {
  const int axis = axis_index(req.at("axis"), cfg_.machine);
  const double v = req.at("velocity_mm_min").get<double>();  // ranges: the command table
  const bool continuous = req.contains("continuous");
  if (continuous == req.contains("distance_mm")) {
    throw CommandError("jog: give exactly one of 'distance_mm' and 'continuous'");
  }
  const auto st = loop_->status();
  const LiveLimits live = loop_->active_limits();
  // Not homed while homing is required (issue 18): the axis' coordinates mean nothing yet, so its
  // soft limits do not apply; the loop jogs it at home.unhomed_jog_mm_min at most.
  const bool unhomed = !cfg_.machine.allow_unhomed && (st.homed_mask >> axis & 1u) == 0;
  double d = 0.0;
  if (continuous) {
    // Towards the soft limit (the loop's jog stops there); the dead-man brakes it before.
    // Unhomed: one full travel (max_mm - min_mm), which the dead-man or `stop` ends.
    const auto ai = static_cast<std::size_t>(axis);
    const double travel = live.max_mm[ai] - live.min_mm[ai];
    const bool plus = req.at("continuous").get<std::string>() == "+";
    d = unhomed ? (plus ? travel : -travel)
                : plus ? live.max_mm[ai] - st.ref_mm[ai] : live.min_mm[ai] - st.ref_mm[ai];
    if (std::abs(d) < 1e-6) {
      throw CommandError("jog: " + cfg_.machine.axes[ai].name + " is at its soft limit in that direction");
    }
  } else {
    d = req.at("distance_mm").get<double>();
  }
  if (d == 0.0) throw CommandError("argument 'distance_mm' must not be 0");
  if (st.state != MachineState::kReady || st.attached_job != 0 || st.jogging) {
    throw CommandError(std::string("jog is not allowed in state ") + std::string(to_string(st.state)) +
                       (st.attached_job != 0 ? " with a program loaded (stop unloads it)" : "") +
                       (st.jogging ? " while jogging" : ""));
  }
  const auto a = static_cast<std::size_t>(axis);
  const auto& ax = cfg_.machine.axes[a];
  const LiveLimits lim = loop_->active_limits();
  const double target = st.ref_mm[a] + d;
  if (!unhomed && (target < lim.min_mm[a] || target > lim.max_mm[a])) {
    throw CommandError("jog target " + std::to_string(target) + " mm outside the soft limits of " +
                       ax.name + " [" + std::to_string(lim.min_mm[a]) + ", " +
                       std::to_string(lim.max_mm[a]) + "]");
  }
  // Incremental jogs have no owner; a continuous one belongs to this connection from the cycle
  // the loop jogs until the jog ends.
  jog_owner_.store(0);
  loop_->post({CommandKind::kJog, axis, v / 60.0, d});
  if (continuous) {
    // Reply only once the loop jogs: a client that disconnects right after the reply must find a
    // jog to brake.
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
    while (!loop_->status().jogging && std::chrono::steady_clock::now() < until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (!loop_->status().jogging) {
      throw CommandError("jog refused by the loop (state " +
                         std::string(to_string(loop_->status().state)) + ")");
    }
    jog_renewed_ns_.store(std::chrono::steady_clock::now().time_since_epoch().count());
    jog_owner_.store(client.id);
    spdlog::info("continuous jog {} {} at {} mm/min by client {} (pid {}): dead-man {} ms", ax.name,
                 req.at("continuous").get<std::string>(), v, client.id, client.pid,
                 cfg_.safety.jog_deadman_ms);
    json r{{"axis", ax.name}, {"target_mm", target}, {"deadman_ms", cfg_.safety.jog_deadman_ms}};
    if (unhomed) unhomed_jog_reply(r, ax, v);
    return r;
  }
  json r{{"axis", ax.name}, {"target_mm", target}};
  if (unhomed) unhomed_jog_reply(r, ax, v);
  return r;
}

std::string Daemon::unhomed_axes() const {
  if (cfg_.machine.allow_unhomed) return "";
  const auto st = loop_->status();
  std::string names;
  for (std::size_t i = 0; i < cfg_.machine.axes.size(); ++i) {
    if ((st.homed_mask >> i & 1u) != 0) continue;
    names += (names.empty() ? "" : ", ") + cfg_.machine.axes[i].name;
  }
  return names;
}

void Daemon::require_homed(const char* what) const {
  const std::string names = unhomed_axes();
  if (names.empty()) return;
  throw CommandError(std::string(what) + ": not homed: " + names +
                     " (home the machine first: contourctl home --all; or set "
                     "machine.allow_unhomed: true)");
}

json Daemon::cmd_home(const json& req) {
  const auto st = loop_->status();
  if (st.state != MachineState::kReady) {
    throw CommandError("home is not allowed in state " + std::string(to_string(st.state)) + " (needs READY)");
  }
  if (st.attached_job != 0) throw CommandError("home: not while a program is loaded (stop it first)");
  if (st.jogging) throw CommandError("home: not while jogging");
  if (st.homing) throw CommandError("home: homing is already running (stop aborts it)");
  int axis = -1;
  json names = json::array();
  if (req.contains("axis")) {
    axis = axis_index(req.at("axis"), cfg_.machine);
    const auto& ax = cfg_.machine.axes[static_cast<std::size_t>(axis)];
    using M = config::HomeConfig::Method;
    if (ax.home.method == M::kAbsolute) {
      throw CommandError("home: " + ax.name + " has an absolute encoder (home.method absolute): it is "
                         "homed from the start, at home_offset_mm " + std::to_string(ax.home.home_offset_mm));
    }
    if (ax.home.method == M::kNone) {
      throw CommandError("home: " + ax.name + " has no homing method (machine.axes[].home)");
    }
    names.push_back(ax.name);
  } else {
    for (const auto& ax : cfg_.machine.axes) {
      using M = config::HomeConfig::Method;
      if (ax.home.method == M::kSwitch || ax.home.method == M::kDrive) names.push_back(ax.name);
    }
    if (names.empty()) {
      throw CommandError("home: no axis has a homing method that moves (machine.axes[].home.method switch or drive)");
    }
  }
  loop_->post({CommandKind::kHome, axis, 0.0, 0.0});
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (std::chrono::steady_clock::now() < until) {
    const auto s = loop_->status();
    if (s.homing) return {{"homing", names}};
    if (s.cycle > st.cycle + 2 && s.state != MachineState::kReady) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  throw CommandError("home refused by the loop (state " + std::string(to_string(loop_->status().state)) +
                     (loop_->status().homing ? "" : "; an inhibit_start from the soft PLC refuses it too") + ")");
}

json Daemon::cmd_set_position(const json& req) {
  const int axis = axis_index(req.at("axis"), cfg_.machine);
  const auto& ax = cfg_.machine.axes[static_cast<std::size_t>(axis)];
  const double pos = req.at("position_mm").get<double>();  // range: Bound::kAxisPosition
  const auto st = loop_->status();
  if ((st.state != MachineState::kReady && st.state != MachineState::kDisabled) || st.attached_job != 0 ||
      st.jogging) {
    throw CommandError(std::string("set-position is not allowed in state ") +
                       std::string(to_string(st.state)) + (st.attached_job != 0 ? " with a program loaded" : ""));
  }
  loop_->post({CommandKind::kSetPosition, axis, pos, 0.0});
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (std::chrono::steady_clock::now() < until) {
    const auto s = loop_->status();
    if (std::abs(s.act_mm[static_cast<std::size_t>(axis)] - pos) < 1e-3 && s.cycle > st.cycle + 2) {
      return {{"axis", ax.name}, {"position_mm", pos}};
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  throw CommandError("set-position: the bus did not accept the new position");
}

// Telemetry files are written only into telemetry_dir_ (telemetry.directory, checked at start-up):
// a client's path may not be the daemon's (PrivateTmp=yes gives the service its own /tmp), so a
// path elsewhere is refused instead of "succeeding" where no client looks. The reply names the
// absolute path of the file.
json Daemon::cmd_record(const json& req) {
  namespace fs = std::filesystem;
  const json& a = arg(req, "action");
  if (!a.is_string()) throw CommandError("argument 'action' must be \"start\" or \"stop\"");
  if (a == "start") {
    if (req.contains("path") && req.contains("name")) {
      throw CommandError("record start takes 'name' (a file name) or 'path', not both");
    }
    std::string name = "contourd-" + std::to_string(loop_->status().cycle) + ".csv";
    if (req.contains("path")) {
      if (!req["path"].is_string()) throw CommandError("argument 'path' must be a string");
      const fs::path p = fs::path(req["path"].get<std::string>()).lexically_normal();
      if (!p.is_absolute() || p.parent_path() != fs::path(telemetry_dir_)) {
        throw CommandError("record: " + req["path"].get<std::string>() +
                           " is outside the telemetry directory " + telemetry_dir_ +
                           " (telemetry.directory), the only place the daemon writes records (a "
                           "client's /tmp is not the service's); give a file name instead, the "
                           "reply names the file");
      }
      name = p.filename().string();
    } else if (req.contains("name")) {
      if (!req["name"].is_string()) throw CommandError("argument 'name' must be a string");
      name = req["name"].get<std::string>();
    }
    const bool plain = !name.empty() && name.size() <= 128 && name[0] != '.' &&
                       std::all_of(name.begin(), name.end(), [](char c) {
                         return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '.' ||
                                c == '_' || c == '-';
                       });
    if (!plain) {
      throw CommandError("record: file name '" + name +
                         "' must be 1..128 characters of A-Z a-z 0-9 . _ - (not starting with '.'); "
                         "it goes into " + telemetry_dir_);
    }
    if (!telemetry_error_.empty()) throw CommandError("record: " + telemetry_error_);
    const std::string path = (fs::path(telemetry_dir_) / name).string();
    try {
      writer_->start_recording(path);
    } catch (const std::exception& e) {
      throw CommandError(std::string("record: ") + e.what());
    }
    return {{"recording", true}, {"path", path}, {"directory", telemetry_dir_}};
  }
  if (a == "stop") return {{"recording", false}, {"path", writer_->stop_recording()}};
  throw CommandError("argument 'action' must be \"start\" or \"stop\"");
}

std::pair<double, double> Daemon::bound(Bound b, const json& req) const {
  switch (b) {
    case Bound::kStatic: break;
    // The live limits (SIGHUP swaps them at a cycle boundary): what the loop enforces now.
    case Bound::kJogVelocity: return {1e-3, loop_->active_limits().jog_max_velocity_mm_s * 60.0};
    case Bound::kAxisPosition: {
      const auto a = static_cast<std::size_t>(axis_index(req.at("axis"), cfg_.machine));
      const LiveLimits l = loop_->active_limits();
      return {l.min_mm[a], l.max_mm[a]};
    }
    case Bound::kOverridePercent: return {0.0, loop_->active_limits().feed_override_max * 100.0};
    case Bound::kRapidOverridePercent: return {0.0, loop_->active_limits().rapid_override_max * 100.0};
    case Bound::kSpindleOverridePercent: {
      const LiveLimits l = loop_->active_limits();
      return {l.spindle_override_min * 100.0, l.spindle_override_max * 100.0};
    }
    case Bound::kForceReference:
      // Keep below the force ceiling: a reference at or above it would hold the feed at once.
      return {0.0, cfg_.force.limits.force_ceiling_N};
  }
  return {-std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
}

// Dispatch from the command table (daemon/command_table.hpp): arguments and (for gated
// commands) the state are checked from the table before the handler runs.
json Daemon::handle(const json& req, const ClientInfo& client) {
  // Any request from the owner of a continuous jog renews its dead-man.
  if (client.id != 0 && client.id == jog_owner_.load()) {
    jog_renewed_ns_.store(std::chrono::steady_clock::now().time_since_epoch().count());
  }
  const std::string cmd = req.at("cmd").get<std::string>();
  const CommandSpec* spec = find_command(cmd);
  if (spec == nullptr) throw CommandError("unknown command '" + cmd + "'");
  validate_request(*spec, req, [this](Bound b, const json& r) { return bound(b, r); });
  check_state(*spec, loop_->status().state);
  auto simple = [&](CommandKind k) -> json {
    const auto st = loop_->status();
    const MachineState now = post_and_wait({k}, st.state, 1.0);
    if (now == st.state && k != CommandKind::kEnable) {
      throw CommandError(cmd + " refused by the loop in state " + std::string(to_string(now)));
    }
    return status_json();
  };
  auto state_name = [this]() { return std::string(to_string(loop_->status().state)); };
  using S = MachineState;
  switch (spec->id) {
    case CommandId::kStatus: return status_json();
    case CommandId::kLoad: return cmd_load(req);
    case CommandId::kUpload: return cmd_upload(req, client);
    case CommandId::kRun: {
      require_homed("run");  // before a load: a refused run leaves nothing loaded
      if (req.contains("start_line") && !req.contains("path") && !req.contains("program")) {
        throw CommandError("run: start_line needs the program (path or program): it is planned again from there");
      }
      if (req.contains("path") || req.contains("program")) cmd_load(req);
      const auto st = loop_->status();
      if (st.state != S::kReady) throw CommandError("run is not allowed in state " + state_name());
      if (st.attached_job == 0) throw CommandError("run: no program loaded (load one first)");
      const std::uint64_t job = st.attached_job;
      {
        std::lock_guard lk(jobs_mu_);
        jobs_[job].overruns_at_start = loop_->stats().overruns.load();
      }
      const MachineState now = post_and_wait({CommandKind::kRun}, st.state, 1.0);
      // A program that pauses at once (T1 M6 first, M0) is running: it waits for `resume`.
      const bool paused = now == S::kHold && loop_->status().interp_holding;
      if (now != S::kRunning && !paused && loop_->status().finished_job != job) {
        // What the loop's run rule found (ServoLoop::apply_command, kRun), as far as status shows.
        const auto after = loop_->status();
        std::string why;
        if (after.plc_requests.inhibit_start) {
          why = ": the machine logic inhibits start (NC.inhibit_start; contourctl plc status)";
        } else if (after.jogging) {
          why = ": a jog is active";
        } else if (after.homing) {
          why = ": homing is active";
        } else if (after.attached_job != job) {
          why = ": the program is no longer loaded";
        }
        throw CommandError("run refused by the loop (state " + std::string(to_string(now)) + ")" + why);
      }
      return {{"job", job}, {"state", to_string(now)}};
    }
    case CommandId::kResult: return result_json(req.at("job").get<std::uint64_t>());
    case CommandId::kHold: return simple(CommandKind::kHold);
    case CommandId::kResume: return simple(CommandKind::kResume);
    case CommandId::kStop: {
      const auto st = loop_->status();
      if (st.state != S::kRunning && st.state != S::kHold && !st.jogging && !st.homing &&
          st.attached_job == 0) {
        throw CommandError("stop: nothing to stop in state " + state_name());
      }
      loop_->post({CommandKind::kStop});
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
      while (std::chrono::steady_clock::now() < until) {
        const auto s = loop_->status();
        if (s.cycle > st.cycle + 2 && s.state != S::kRunning && s.state != S::kHold && !s.jogging &&
            !s.homing) {
          break;
        }
        // The stop goes on in the loop; another client's E-stop must not wait for its end.
        if (s.cycle > st.cycle + 2 && safety_request_waiting()) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
      loaded_job_ = 0;
      return status_json();
    }
    case CommandId::kEstop:
      post_and_wait({CommandKind::kEstop}, loop_->status().state, 0.5);
      spdlog::warn("E-STOP from socket client pid {} uid {}", client.pid, client.uid);
      loaded_job_ = 0;
      return status_json();
    case CommandId::kReset: {
      const auto st = loop_->status();
      if (st.state != S::kFault && st.state != S::kEstop) {
        throw CommandError("reset is only for FAULT or ESTOP (state " + state_name() + ")");
      }
      if (io_ && !io_->reset_estop()) {
        throw CommandError("reset refused: the E-stop input is still asserted (release it first)");
      }
      // The loop decides: at once, or when the causes clear within its reset window (250
      // cycles), or refused when the window closes. The answer is that verdict, not a wall-clock
      // guess: a reply "refused" for a reset that completes later would lie to the operator.
      const std::uint64_t verdicts0 = st.reset_verdicts;
      if (!loop_->post({CommandKind::kReset})) throw CommandError("command queue full; retry");
      const auto cap = std::chrono::steady_clock::now() + std::chrono::seconds(30);
      bool decided = false;
      while (std::chrono::steady_clock::now() < cap) {
        if (loop_->status().reset_verdicts != verdicts0) {
          decided = true;
          break;
        }
        if (safety_request_waiting()) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      if (!decided) {
        throw CommandError(std::string("reset pending: ") +
                           (safety_request_waiting() ? "answered early for a waiting stop/E-stop request"
                                                     : "the loop has not decided within 30 s") +
                           "; the machine resets by itself if its causes clear within the loop's "
                           "250-cycle window, watch the status");
      }
      const MachineState now = loop_->status().state;
      if (now == S::kFault || now == S::kEstop) {
        // The loop's reset rule names what is still missing (SafetySupervisor::reset_block).
        const ResetBlock b = loop_->status().reset_block;
        std::string why = b ? describe(b) : "the cause is still present";
        if (b && b.axis >= 0 && b.axis < static_cast<int>(cfg_.machine.axes.size())) {
          why += " (axis " + cfg_.machine.axes[static_cast<std::size_t>(b.axis)].name + ")";
        }
        throw CommandError("reset refused: " + why + "; fault cause " +
                           std::string(to_string(st.cause)));
      }
      const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
      while (loop_->status().state != S::kReady && std::chrono::steady_clock::now() < until &&
             !safety_request_waiting()) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      return status_json();
    }
    case CommandId::kEnable: return simple(CommandKind::kEnable);
    case CommandId::kDisable: return simple(CommandKind::kDisable);
    case CommandId::kJog: return cmd_jog(req, client);
    case CommandId::kSetPosition: return cmd_set_position(req);
    case CommandId::kHome: return cmd_home(req);
    case CommandId::kGains: return cmd_gains(req);
    case CommandId::kOverride: {
      if (!req.contains("percent") && !req.contains("rapid_percent") && !req.contains("spindle_percent")) {
        throw CommandError("override: give 'percent' (feed), 'rapid_percent' or 'spindle_percent'");
      }
      // In range (checked from the table against the live limits): the loop applies exactly
      // these at its next cycle; the others stay as they are.
      const LoopStatus st = loop_->status();
      double feed = st.feed_override * 100.0, rapid = st.rapid_override * 100.0,
             spindle = st.spindle_override * 100.0;
      auto set = [&](const char* key, int which, double& pct) {
        if (!req.contains(key)) return;
        pct = req.at(key).get<double>();
        loop_->post({CommandKind::kSetOverride, which, pct / 100.0, 0.0});
      };
      set("percent", kOverrideFeed, feed);
      set("rapid_percent", kOverrideRapid, rapid);
      set("spindle_percent", kOverrideSpindle, spindle);
      return {{"feed_override_percent", feed},
              {"rapid_override_percent", rapid},
              {"spindle_override_percent", spindle}};
    }
    case CommandId::kRecord: return cmd_record(req);
    case CommandId::kSubscribe:
    case CommandId::kUnsubscribe: {
      const std::string topic = req.at("topic").get<std::string>();
      if (spec->id == CommandId::kUnsubscribe) {
        server_->unsubscribe(client.id, topic);
        return {{"topic", topic}};
      }
      const double dec = req.value("decimation", 1.0);
      if (dec != std::floor(dec)) throw CommandError("decimation must be a whole number");
      if (topic != "telemetry" && dec != 1.0) throw CommandError("decimation is for telemetry only");
      server_->subscribe(client.id, topic, StreamOptions{static_cast<std::uint32_t>(dec)});
      return {{"topic", topic}, {"decimation", static_cast<int>(dec)}};
    }
    case CommandId::kForce: return cmd_force(req);
    case CommandId::kSimGpio: return cmd_sim_gpio(req);
    case CommandId::kIo: return cmd_io(req);
    case CommandId::kPlcStatus: return cmd_plc_status(req);
    case CommandId::kOffsets: return cmd_offsets(req);
    case CommandId::kTools: return cmd_tools(req);
    case CommandId::kTouchOff: return cmd_touch_off(req);
    case CommandId::kMdi: return cmd_mdi(req);
    case CommandId::kSwitches: {
      if (req.contains("block_delete")) planner_->set_block_delete(req.at("block_delete").get<bool>());
      bool optional_stop = loop_->status().optional_stop;
      if (req.contains("optional_stop")) {
        optional_stop = req.at("optional_stop").get<bool>();
        if (!loop_->post({CommandKind::kSetOptionalStop, 0, optional_stop ? 1.0 : 0.0, 0.0})) {
          throw CommandError("command queue full; retry");
        }
      }
      bool single_block = loop_->status().single_block;
      if (req.contains("single_block")) {
        single_block = req.at("single_block").get<bool>();
        if (!loop_->post({CommandKind::kSetSingleBlock, 0, single_block ? 1.0 : 0.0, 0.0})) {
          throw CommandError("command queue full; retry");
        }
      }
      return {{"block_delete", planner_->block_delete()},
              {"optional_stop", optional_stop},
              {"single_block", single_block}};
    }
    case CommandId::kIdentify: {
      json r = identify_on_loop(*loop_, cfg_, axis_index(req.at("axis"), cfg_.machine),
                                [this] { return safety_request_waiting(); });
      // Kept for `gains save` (the `gains` reply's "identified"): the model as measured.
      const std::time_t now = std::time(nullptr);
      std::tm tm{};
      ::gmtime_r(&now, &tm);
      char date[32];
      std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%SZ", &tm);
      std::lock_guard lk(identified_mu_);
      identified_[r.at("axis").get<std::string>()] = {{"gain_per_s", r.at("gain_per_s")},
                                                      {"tau_ms", r.at("tau_ms")},
                                                      {"delay_cycles", r.at("delay_cycles")},
                                                      {"date", date}};
      return r;
    }
    case CommandId::kShutdown:
      spdlog::info("shutdown requested by socket client pid {} uid {}", client.pid, client.uid);
      request_shutdown();
      return {{"shutting_down", true}};
  }
  throw CommandError("unknown command '" + cmd + "'");
}

}  // namespace contour::daemon
