// Issue 18: offsets, tool table, touch-off and MDI on the command socket, and the status fields
// tool / work_offset / work_offset_mm / work_act_mm / work_ref_mm. The machine context itself is
// daemon/machine_data.hpp (persistence); programs use it through ProgramPlanner.
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <thread>

#include "config/program_config.hpp"
#include "daemon/commands.hpp"
#include "daemon/daemon.hpp"

namespace contour::daemon {

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

json vec_json(const Eigen::Vector3d& v, int axes) {
  json j = json::array();
  for (int i = 0; i < axes && i < 3; ++i) j.push_back(v[i]);
  return j;
}

json tool_json(const control::ToolData& t) {
  return {{"number", t.number}, {"pocket", t.pocket}, {"length_mm", t.length_mm()},
          {"diameter_mm", t.diameter_mm}, {"comment", t.comment}};
}

}  // namespace

void Daemon::open_machine_data() {
  const std::string var = resolve_config_path(opt_.config_path, cfg_.program.var_file);
  const std::string tbl = resolve_config_path(opt_.config_path, cfg_.program.tool_table);
  if (!var.empty()) {
    std::error_code ec;
    const fs::path dir = fs::path(var).parent_path();
    fs::create_directories(dir, ec);
    if (!fs::is_directory(dir, ec)) {
      throw StartupConfigError(opt_.config_path + ": program.var_file: the directory " +
                               dir.string() + " of " + var + " does not exist and cannot be created");
    }
  }
  if (!tbl.empty() && !fs::is_regular_file(tbl)) {
    throw StartupConfigError(opt_.config_path + ": program.tool_table: " + tbl + " does not exist");
  }
  try {
    machine_data_ = std::make_unique<MachineData>(cfg_.program, var, tbl);
  } catch (const MachineDataError& e) {
    throw StartupConfigError(e.what());
  }
  spdlog::info("machine data: var file {}, tool table {} ({} tools)", var.empty() ? "(none)" : var,
               tbl.empty() ? "(program.tools)" : tbl, machine_data_->snapshot().tools.size());
}

void Daemon::add_machine_status(json& j, const LoopStatus& st) const {
  if (!machine_data_) return;
  const control::MachineContext m = machine_data_->snapshot();
  const int axes = loop_->axes();
  const int sys = m.active_system();
  // LinuxCNC adds the G5x origin and the G92 offset (when applied); the tool length offset is
  // added on top for positions (XY rotation of G10 L2 R is not shown here).
  const Eigen::Vector3d off = m.work_offset_mm(sys) + (m.g92_applied() ? m.g92_offset_mm() : Eigen::Vector3d::Zero());
  const Eigen::Vector3d tlo = machine_data_->tool_offset_mm();
  const Eigen::Vector3d act(st.act_mm[0], st.act_mm[1], st.act_mm[2]);
  const Eigen::Vector3d ref(st.ref_mm[0], st.ref_mm[1], st.ref_mm[2]);
  j["tool"] = m.tool_in_spindle;
  j["work_offset"] = coord_system_name(sys);
  j["work_offset_mm"] = vec_json(off, axes);
  j["work_act_mm"] = vec_json(act - off - tlo, axes);
  j["work_ref_mm"] = vec_json(ref - off - tlo, axes);
  j["tool_offset_mm"] = vec_json(tlo, axes);
}

namespace {
// Changing offsets or tools under a loaded or running program would leave its plan on the old
// values (and the program's own changes would overwrite the new ones at its end).
void refuse_with_program(const LoopStatus& st, const char* what) {
  if (st.state == MachineState::kRunning || st.state == MachineState::kHold || st.attached_job != 0) {
    throw CommandError(std::string(what) + ": not while a program is loaded or runs (state " +
                       std::string(to_string(st.state)) + "; stop it first)");
  }
}

json offsets_json(const control::MachineContext& m, int axes) {
  json o{{"active", coord_system_name(m.active_system())}};
  for (int s = 1; s <= 9; ++s) o[coord_system_name(s)] = vec_json(m.work_offset_mm(s), axes);
  o["G92"] = vec_json(m.g92_offset_mm(), axes);
  o["G92_applied"] = m.g92_applied();
  o["G28"] = vec_json(m.g28_mm(), axes);
  o["G30"] = vec_json(m.g30_mm(), axes);
  return o;
}
}  // namespace

json Daemon::cmd_offsets(const json& req) {
  const int axes = loop_->axes();
  if (req.contains("set")) {
    refuse_with_program(loop_->status(), "offsets set");
    const std::string which = req["set"].get<std::string>();
    control::MachineContext m = machine_data_->snapshot();
    Eigen::Vector3d v = which == "G92" ? m.g92_offset_mm()
                        : which == "G28" ? m.g28_mm()
                        : which == "G30" ? m.g30_mm()
                                         : m.work_offset_mm(coord_system_index(which));
    bool any = false;
    static const char* kAxes[3] = {"X", "Y", "Z"};
    for (int i = 0; i < 3; ++i) {
      if (!req.contains(kAxes[i])) continue;
      if (i >= axes) throw CommandError(std::string("offsets: this machine has no axis ") + kAxes[i]);
      v[i] = req[kAxes[i]].get<double>();
      any = true;
    }
    if (!any) throw CommandError("offsets: set needs at least one of X, Y, Z");
    if (which == "G92") {
      for (int i = 0; i < 3; ++i) m.parameters[static_cast<std::size_t>(control::kParamG92 + i)] = v[i];
      m.parameters[control::kParamG92Applied] = 1.0;
    } else if (which == "G28") {
      m.set_g28_mm(v);
    } else if (which == "G30") {
      m.set_g30_mm(v);
    } else {
      m.set_work_offset_mm(coord_system_index(which), v);
    }
    try {
      machine_data_->commit(m);
    } catch (const MachineDataError& e) {
      throw CommandError(std::string("offsets: not changed: ") + e.what());
    }
    spdlog::info("offsets: {} set to [{}, {}, {}] mm", which, v[0], v[1], v[2]);
  } else {
    for (const char* k : {"X", "Y", "Z"}) {
      if (req.contains(k)) throw CommandError(std::string("offsets: '") + k + "' needs 'set'");
    }
  }
  return {{"offsets", offsets_json(machine_data_->snapshot(), axes)},
          {"var_file", machine_data_->var_path()}};
}

json Daemon::cmd_tools(const json& req) {
  const bool set = req.contains("set");
  const bool remove = req.contains("remove");
  if (set && remove) throw CommandError("tools: give either 'set' or 'remove'");
  if (!set) {
    for (const char* k : {"length_mm", "diameter_mm", "pocket", "comment"}) {
      if (req.contains(k)) throw CommandError(std::string("tools: '") + k + "' needs 'set'");
    }
  }
  auto integer = [&](const char* k) {
    const double d = req[k].get<double>();
    if (d != static_cast<double>(static_cast<long>(d))) {
      throw CommandError(std::string("argument '") + k + "' must be an integer");
    }
    return static_cast<int>(d);
  };
  if (set || remove) {
    refuse_with_program(loop_->status(), set ? "tools set" : "tools remove");
    control::MachineContext m = machine_data_->snapshot();
    const int n = integer(set ? "set" : "remove");
    auto it = std::find_if(m.tools.begin(), m.tools.end(), [n](const control::ToolData& t) { return t.number == n; });
    if (remove) {
      if (it == m.tools.end()) throw CommandError("tools: no tool " + std::to_string(n));
      if (m.tool_in_spindle == n) throw CommandError("tools: tool " + std::to_string(n) + " is in the spindle");
      m.tools.erase(it);
    } else {
      if (it == m.tools.end()) {
        control::ToolData t;
        t.number = n;
        t.pocket = n;
        m.tools.push_back(t);
        it = m.tools.end() - 1;
      }
      if (req.contains("length_mm")) it->offset[2] = req["length_mm"].get<double>();
      if (req.contains("diameter_mm")) it->diameter_mm = req["diameter_mm"].get<double>();
      if (req.contains("pocket")) it->pocket = integer("pocket");
      if (req.contains("comment")) {
        const std::string c = req["comment"].get<std::string>();
        if (c.find('\n') != std::string::npos) throw CommandError("tools: a comment is one line");
        it->comment = c;
      }
    }
    try {
      machine_data_->commit(m);
    } catch (const MachineDataError& e) {
      throw CommandError(std::string("tools: not changed: ") + e.what());
    }
    spdlog::info("tools: tool {} {}", n, remove ? "removed" : "set");
  }
  const control::MachineContext m = machine_data_->snapshot();
  json list = json::array();
  for (const auto& t : m.tools) list.push_back(tool_json(t));
  return {{"tools", list}, {"tool_table", machine_data_->tbl_path()}, {"tool", m.tool_in_spindle}};
}

json Daemon::cmd_touch_off(const json& req) {
  const auto st = loop_->status();
  refuse_with_program(st, "touch-off");
  if (st.jogging) throw CommandError("touch-off: not while jogging");
  const int axis = axis_index(req.at("axis"), cfg_.machine);
  if (axis > 2) throw CommandError("touch-off: only X, Y, Z carry work offsets");
  const double value = req.at("value").get<double>();
  control::MachineContext m = machine_data_->snapshot();
  const int sys = req.contains("offset") ? coord_system_index(req["offset"].get<std::string>())
                                         : m.active_system();
  // G10 L20: the origin that makes the commanded position read `value` with the G92 offset and
  // the tool length offset as they are: program = machine - origin - g92 - tool.
  const Eigen::Vector3d g92 = m.g92_applied() ? m.g92_offset_mm() : Eigen::Vector3d::Zero();
  const Eigen::Vector3d tlo = machine_data_->tool_offset_mm();
  Eigen::Vector3d origin = m.work_offset_mm(sys);
  origin[axis] = st.ref_mm[static_cast<std::size_t>(axis)] - g92[axis] - tlo[axis] - value;
  m.set_work_offset_mm(sys, origin);
  try {
    machine_data_->commit(m);
  } catch (const MachineDataError& e) {
    throw CommandError(std::string("touch-off: not changed: ") + e.what());
  }
  spdlog::info("touch-off: {} {} reads {} mm ({} origin {} mm)", coord_system_name(sys),
               cfg_.machine.axes[static_cast<std::size_t>(axis)].name, value,
               cfg_.machine.axes[static_cast<std::size_t>(axis)].name, origin[axis]);
  return {{"offset", coord_system_name(sys)},
          {"axis", cfg_.machine.axes[static_cast<std::size_t>(axis)].name},
          {"value", value},
          {"offsets", offsets_json(machine_data_->snapshot(), loop_->axes())}};
}

json Daemon::cmd_mdi(const json& req) {
  const auto st = loop_->status();
  if (st.state != MachineState::kReady) {
    throw CommandError("mdi is not allowed in state " + std::string(to_string(st.state)) + " (needs READY)");
  }
  if (st.attached_job != 0) throw CommandError("mdi: not while a program is loaded (stop it first)");
  if (st.jogging) throw CommandError("mdi: not while jogging");
  if (st.homing) throw CommandError("mdi: not while homing");
  require_homed("mdi");
  const std::string text = req.at("text").get<std::string>();
  if (text.size() > 4096) throw CommandError("mdi: more than 4096 bytes (use load/run for programs)");
  // One interpreter for all MDI blocks (modal state carries over, as in LinuxCNC); rebuilt from
  // the machine context when a program or command changed it since.
  if (!mdi_parser_ || mdi_generation_ != machine_data_->generation()) {
    const config::Config c = planner_->config_snapshot();
    control::ProgramSetup setup = config::to_program_setup(c.program, c.interpolator);
    setup.machine = machine_data_->snapshot();
    mdi_parser_ = std::make_unique<control::GcodeParser>(setup, "<mdi>");
    mdi_generation_ = machine_data_->generation();
  }
  const Eigen::Vector3d start(st.ref_mm[0], st.ref_mm[1], st.ref_mm[2]);
  mdi_parser_->set_position_mm(start);
  ProgramText src;
  src.name = "<mdi>";
  src.mdi = true;
  std::size_t from = 0;
  try {
    while (from <= text.size()) {
      const std::size_t nl = text.find('\n', from);
      const std::string line = text.substr(from, nl == std::string::npos ? std::string::npos : nl - from);
      if (!line.empty()) mdi_parser_->mdi(line, src.blocks);
      if (nl == std::string::npos) break;
      from = nl + 1;
    }
  } catch (const control::GcodeError& e) {
    mdi_parser_.reset();  // its state after a refused line is not trusted: rebuilt next time
    throw CommandError(std::string("mdi: ") + e.what());
  }
  (void)mdi_parser_->take_messages();
  machine_data_->set_tool_offset_mm(mdi_parser_->modal_state().tool_offset_mm);
  if (mdi_parser_->machine_changed()) {
    try {
      machine_data_->commit(mdi_parser_->machine(), mdi_parser_->modal_state().tool_offset_mm);
    } catch (const MachineDataError& e) {
      throw CommandError(std::string("mdi: ") + e.what());
    }
    mdi_generation_ = machine_data_->generation();
  }
  std::size_t moves = 0;
  for (const auto& b : src.blocks) moves += b.kind == control::BlockKind::kEnd ? 0 : 1;
  if (moves == 0) return {{"blocks", 0}, {"state", to_string(st.state)}};
  // The blocks end where the interpreter stands; kEnd makes the planner drain and finish.
  while (!src.blocks.empty() && src.blocks.back().kind == control::BlockKind::kEnd) src.blocks.pop_back();
  control::Block end;
  end.kind = control::BlockKind::kEnd;
  end.line = 1;
  end.seg.start = end.seg.end = mdi_parser_->position_mm();
  src.blocks.push_back(end);
  const json loaded = load_source(src);
  const std::uint64_t job = loaded.at("job").get<std::uint64_t>();
  {
    std::lock_guard lk(jobs_mu_);
    jobs_[job].overruns_at_start = loop_->stats().overruns.load();
  }
  const MachineState now = post_and_wait({CommandKind::kRun}, MachineState::kReady, 1.0);
  const bool paused = now == MachineState::kHold && loop_->status().interp_holding;
  if (now != MachineState::kRunning && !paused && loop_->status().finished_job != job) {
    throw CommandError("mdi: run refused by the loop (state " + std::string(to_string(now)) + ")");
  }
  return {{"job", job}, {"state", to_string(now)}, {"blocks", moves}};
}

}  // namespace contour::daemon
