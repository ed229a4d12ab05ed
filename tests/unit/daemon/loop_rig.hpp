#pragma once
// Test rig shared by the ServoLoop unit tests: the loop on the in-process SimBus, stepped by the
// test (lockstep: one plant step per cycle), with a telemetry writer and the planner.
#include <memory>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "daemon/planner.hpp"
#include "daemon/servo_loop.hpp"
#include "daemon/sim_bus.hpp"
#include "daemon/telemetry.hpp"

namespace contour::daemon::test_rig {

inline config::Config sim_config() {
  return config::load_config_file(std::string(CONTOUR_SOURCE_DIR) + "/config/sim.yaml");
}

inline std::vector<control::FeedDriveParams> drives(const config::Config& cfg) {
  std::vector<control::FeedDriveParams> d;
  for (const auto& a : cfg.machine.axes) {
    auto p = a.drive;
    p.period_s = cfg.machine.period_s;
    d.push_back(p);
  }
  return d;
}

struct Rig {
  explicit Rig(const config::Config& c, RtIo* io = nullptr, LoopOptions opt = {})
      : cfg(c),
        bus(drives(cfg)),
        loop(cfg, bus, 4096, io, opt),
        writer(loop.telemetry(), loop.period_s()),
        planner(cfg) {}
  void step(int n = 1) {
    RtEvent e;
    for (int i = 0; i < n; ++i) {
      loop.cycle();
      while (loop.events().pop(e)) events.push_back(e);
      if (loop.telemetry().size() > loop.telemetry().capacity() / 2) writer.drain();
    }
  }
  bool enable() {
    loop.post({CommandKind::kEnable});
    step(5);
    return loop.status().state == MachineState::kReady;
  }
  std::shared_ptr<ProgramJob> load(const std::string& text, std::uint64_t id) {
    ProgramText src{"<test>", "", text};
    const auto st = loop.status();
    const Eigen::Vector3d start(st.ref_mm[0], st.ref_mm[1], st.ref_mm[2]);
    planner.validate(src, start);
    writer.begin_job(id);
    auto job = planner.start(
        src, start, id,
        [this](std::uint64_t j, const control::PlannedSegment& s) { writer.add_segment(j, s); });
    ProgramPlanner::wait_prefill(*job, 30.0);
    loop.post({CommandKind::kAttachJob, 0, 0.0, 0.0, job.get()});
    return job;
  }
  [[nodiscard]] std::size_t count(EventKind k) const {
    std::size_t n = 0;
    for (const auto& e : events) n += e.kind == k ? 1u : 0u;
    return n;
  }
  config::Config cfg;
  SimBus bus;
  ServoLoop loop;
  TelemetryWriter writer;
  ProgramPlanner planner;
  std::vector<RtEvent> events;
};

}  // namespace contour::daemon::test_rig
