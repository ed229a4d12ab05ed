#include "daemon/offline_run.hpp"

#include <stdexcept>

#include "daemon/sim_bus.hpp"

namespace contour::daemon {

OfflineResult run_offline(const config::Config& cfg, const ProgramText& src,
                          std::uint64_t max_cycles, const std::string& csv_path) {
  // With bus.type socketcan the offline run models the CANopen drive's integer units (velocity
  // target in counts/s, position in counts), so it reproduces a HIL run against
  // contour-machine-sim exactly (see SimBus, make_sim_bus).
  const auto sim_bus = make_sim_bus(cfg);
  SimBus& bus = *sim_bus;
  ServoLoop loop(cfg, bus);
  TelemetryWriter writer(loop.telemetry(), loop.period_s());
  ProgramPlanner planner(cfg);
  if (!csv_path.empty()) writer.start_recording(csv_path);
  RtEvent ev;
  auto step = [&] {
    loop.cycle();
    while (loop.events().pop(ev)) {}
    if (loop.telemetry().size() > loop.telemetry().capacity() / 2) writer.drain();
  };
  loop.post({CommandKind::kEnable});
  for (int i = 0; i < 100 && loop.status().state != MachineState::kReady; ++i) step();
  if (loop.status().state != MachineState::kReady) throw std::runtime_error("drives did not enable");
  const auto st0 = loop.status();
  const Eigen::Vector3d start(st0.ref_mm[0], st0.ref_mm[1], st0.ref_mm[2]);
  planner.validate(src, start);
  const std::uint64_t id = 1;
  writer.begin_job(id);
  auto job = planner.start(src, start, id, [&](std::uint64_t j, const control::PlannedSegment& s) {
    writer.add_segment(j, s);
  });
  ProgramPlanner::wait_prefill(*job, 60.0);
  loop.post({CommandKind::kAttachJob, 0, 0.0, 0.0, job.get()});
  loop.post({CommandKind::kRun});
  OfflineResult r;
  std::uint64_t n = 0;
  for (; n < max_cycles; ++n) {
    step();
    const auto st = loop.status();
    if (st.finished_job == id) break;
    if (st.state == MachineState::kFault || st.state == MachineState::kEstop) break;
  }
  writer.drain();
  writer.stop_recording();
  planner.abort_and_join();
  const auto st = loop.status();
  r.state = std::string(to_string(st.state));
  r.cause = std::string(to_string(st.cause));
  r.fault_axis = st.fault_axis;
  r.fault_value = st.fault_value;
  r.fault_limit = st.fault_limit;
  r.finished_ok = st.finished_job == id && st.finished_ok;
  r.cycles = n;
  r.stats = writer.stats(id);
  r.duration_s = r.stats.duration_s(loop.period_s());
  r.velocity_clamps = st.velocity_clamps;
  r.underruns = st.underruns;
  return r;
}

}  // namespace contour::daemon
