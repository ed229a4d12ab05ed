#include "daemon/identify.hpp"

#include <chrono>
#include <cmath>
#include <string>
#include <thread>
#include <vector>

#include "control/system_identification.hpp"
#include "daemon/command_protocol.hpp"

namespace contour::daemon {

namespace {

double round_to(double v, double step) { return std::round(v / step) * step; }

}  // namespace

nlohmann::json identify_on_loop(ServoLoop& loop, const config::Config& cfg, int axis,
                                const std::function<bool()>& give_way) {
  const auto& axes = cfg.machine.axes;
  if (axis < 0 || axis >= static_cast<int>(axes.size())) {
    throw CommandError("identify: no axis " + std::to_string(axis));
  }
  const auto a = static_cast<std::size_t>(axis);
  const std::string name = axes[a].name;
  const LoopStatus st0 = loop.status();
  if (st0.state != MachineState::kReady) {
    throw CommandError("identify " + name + " needs the machine READY and at rest (state " +
                       std::string(to_string(st0.state)) + ")");
  }
  if (st0.attached_job != 0 || st0.jogging) {
    throw CommandError("identify " + name + ": unload the program / end the jog first");
  }
  // The excitation moves the axis at most excursion_mm from where it stands (both ways).
  const double excursion_mm =
      control::excitation_excursion_mm(loop.identify_excitation(), cfg.machine.period_s);
  const double margin_mm = 2.0 * excursion_mm;
  if (st0.act_mm[a] - margin_mm < st0.soft_min_mm[a] || st0.act_mm[a] + margin_mm > st0.soft_max_mm[a]) {
    throw CommandError("identify " + name + ": the axis is within " + std::to_string(margin_mm) +
                       " mm of a soft limit (the experiment moves it up to " +
                       std::to_string(excursion_mm) + " mm each way): move it away first");
  }

  const std::uint64_t seq0 = st0.identify_seq;
  if (!loop.post({CommandKind::kIdentify, axis})) throw CommandError("identify: loop command queue full");
  // Bounded in loop cycles, not wall time: a lockstep loop (bus.lockstep, a slow VM) runs its
  // cycles slower than real time. The experiment's cycles plus 3 s of cycles; a loop that stops
  // cycling for 10 s, or 120 s in all, ends the wait.
  const auto exp_cycles = static_cast<std::uint64_t>(loop.identify_excitation().size());
  const auto margin_cycles = static_cast<std::uint64_t>(std::ceil(3.0 / cfg.machine.period_s));
  const std::uint64_t c0 = st0.cycle;
  const auto t0 = std::chrono::steady_clock::now();
  auto last_progress = t0;
  std::uint64_t last_cycle = c0;
  LoopStatus st = loop.status();
  bool started = false;
  bool stalled = false;
  for (;;) {
    st = loop.status();
    if (st.identify_seq != seq0) break;
    started = started || st.identify_state == IdentifyState::kRunning;
    if (!started && st.state != MachineState::kReady) break;
    const auto now = std::chrono::steady_clock::now();
    if (st.cycle != last_cycle) {
      last_cycle = st.cycle;
      last_progress = now;
    }
    if (st.cycle > c0 + exp_cycles + margin_cycles) break;
    if (now - last_progress > std::chrono::seconds(10) || now - t0 > std::chrono::seconds(120)) {
      stalled = true;
      break;
    }
    if (give_way && give_way()) {
      throw CommandError("identify " + name + ": interrupted by another client's safety command");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  if (stalled && st.identify_seq == seq0) {
    throw CommandError("identify " + name + ": the loop stopped cycling (cycle " +
                       std::to_string(st.cycle) + ")");
  }
  if (st.identify_seq == seq0) {
    throw CommandError(started ? "identify " + name + ": no result within the expected time"
                               : "identify " + name + " refused by the loop (state " +
                                     std::string(to_string(st.state)) + ")");
  }
  if (st.identify_state != IdentifyState::kDone) {
    throw CommandError("identify " + name + " aborted (state " + std::string(to_string(st.state)) +
                       "): the machine left READY during the experiment");
  }

  control::IdentificationInput in;
  in.period_s = cfg.machine.period_s;
  in.command_gain_per_s = axes[a].drive.gain_per_s;
  int rec_axis = -1;
  if (!loop.identify_record(rec_axis, in.v_cmd_mm_s, in.position_mm) || rec_axis != axis) {
    throw CommandError("identify " + name + ": the record was replaced by another experiment");
  }
  const control::IdentificationResult id = control::identify_axis(in);
  if (!id.ok) throw CommandError("identify " + name + ": " + id.message);

  const auto& d = axes[a].drive;
  nlohmann::json out;
  out["axis"] = name;
  out["gain_per_s"] = round_to(id.gain_per_s, 1e-4);
  out["velocity_gain"] = round_to(id.velocity_gain, 1e-6);
  out["tau_ms"] = round_to(id.tau_s * 1e3, 1e-4);
  out["delay_cycles"] = id.delay_cycles;
  out["delay_confidence"] = round_to(id.delay_confidence, 1e-3);
  out["rms_residual_um"] = round_to(id.rms_residual_mm * 1e3, 1e-4);
  out["excursion_mm"] = round_to(id.excursion_mm, 1e-6);
  out["configured"] = {{"gain_per_s", d.gain_per_s},
                       {"tau_ms", d.tau_s * 1e3},
                       {"delay_cycles", d.delay_cycles}};
  const bool delay_ok = id.delay_cycles == d.delay_cycles;
  const double k_dev = d.gain_per_s > 0.0 ? id.gain_per_s / d.gain_per_s - 1.0 : 0.0;
  const double tau_dev = d.tau_s > 0.0 ? id.tau_s / d.tau_s - 1.0 : 0.0;
  out["delay_matches"] = delay_ok;
  out["gain_deviation_percent"] = round_to(k_dev * 100.0, 1e-3);
  out["tau_deviation_percent"] = round_to(tau_dev * 100.0, 1e-3);
  std::string verdict;
  if (!delay_ok) {
    verdict = "delay differs from machine.axes[" + std::to_string(axis) + "].drive.delay_cycles (" +
              std::to_string(d.delay_cycles) + " configured, " + std::to_string(id.delay_cycles) +
              " measured): the Smith predictor assumes the configured one (control/CHATTER.md)";
  } else if (std::abs(k_dev) > 0.05 || std::abs(tau_dev) > 0.10) {
    verdict = "gain or time constant differs from the configuration by more than 5 % / 10 %";
  } else {
    verdict = "matches the configuration";
  }
  out["verdict"] = verdict;
  out["record"] = {{"period_s", in.period_s},
                   {"v_cmd_mm_s", in.v_cmd_mm_s},
                   {"position_mm", in.position_mm}};
  out["ok"] = true;
  return out;
}

}  // namespace contour::daemon
