// ServoLoop force channel and GPIO lines, with a fake force source (a first-order cutting process
// driven by the loop's own path speed and spindle command) and the simulated GPIO backend:
// a depth-of-cut step is regulated, a stale sample triggers the configured fallback (visible in
// the status, an RT event), E-stop from SimGpio reaches the loop in the cycle after the monitor
// latched it, M3/M8/M9 drive the spindle-enable and coolant outputs, no allocation per cycle.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

#include "daemon/io_channels.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using drivers::modbus::ForceState;
using test_rig::Rig;
using test_rig::sim_config;

struct FakeIo final : RtIo {
  [[nodiscard]] bool has_force() const noexcept override { return true; }
  drivers::modbus::ForceReading read_force() noexcept override { return reading; }
  [[nodiscard]] bool estop_tripped() const noexcept override { return estop.load(); }
  void set_spindle_rpm(double r) noexcept override { rpm = r; }
  void set_force(double f_N, ForceState st = ForceState::kOk) {
    reading.state = st;
    reading.sample.valid = st == ForceState::kOk;
    reading.sample.present = {true, false, false};
    reading.sample.filtered_N = {f_N, 0.0, 0.0};
    reading.sample.force_N = reading.sample.filtered_N;
    reading.age_ns = st == ForceState::kStale ? 100'000'000 : 1'000'000;
    ++reading.sample.seq;
  }
  drivers::modbus::ForceReading reading{};
  std::atomic<bool> estop{false};
  double rpm = 0.0;
};

// Cutting process of seed 001 (eq 3.8, physical spindle pole) around the design's operating
// point: F = depth * (x_f + x_s), x_f -> K_f * (path speed / k_v), x_s -> K_s * u2.
struct Process {
  explicit Process(const config::Config& cfg)
      : p(cfg.force.design.plant),
        lim(cfg.force.limits),
        af(std::exp(-cfg.machine.period_s / p.tau_f_s)),
        as(std::exp(-cfg.machine.period_s / p.tau_s_s)),
        t_s(cfg.machine.period_s) {}
  double step(const LoopStatus& st) {
    const double speed_ratio = (st.progress_mm - last_progress) / t_s / p.k_v_mm_s;
    last_progress = st.progress_mm;
    const double rpm = std::abs(st.spindle_rpm_cmd);
    const double u2 = rpm > 0.0 ? (rpm - lim.spindle_nominal_rpm) / lim.spindle_rpm_per_unit : 0.0;
    xf = af * xf + (1.0 - af) * p.k_f_N * speed_ratio;
    xs = as * xs + (1.0 - as) * p.k_s_N * u2;
    return depth * (xf + xs);
  }
  control::ForcePlantParams p;
  control::ForceLimits lim;
  double af, as, t_s;
  double xf = 0.0, xs = 0.0, depth = 1.0, last_progress = 0.0;
};

// 60 mm at the design's path speed (k_v = 4.5 mm/s = 270 mm/min): 13 s of cut.
const char* kCut = "G21 G90 G94\nM3 S3000\nG01 X60 F270\nM5\nM2\n";

config::Config force_config(bool enable) {
  auto cfg = sim_config();
  cfg.force.enable = enable;
  cfg.force.reference_N = 1.0;
  return cfg;
}

struct CutFigures {
  double force_before_step = 0.0, force_end = 0.0;
  double min_override = 1e9;
  double max_spindle_rpm = 0.0;
  MachineState state_end = MachineState::kDisabled;
};

CutFigures cut(bool force_control) {
  const auto cfg = force_config(force_control);
  FakeIo io;
  Rig r(cfg, &io);
  EXPECT_TRUE(r.enable());
  r.load(kCut, 1);
  r.loop.post({CommandKind::kRun});
  Process proc(cfg);
  CutFigures f;
  const int step_at = 6000, n = 12000;
  for (int k = 0; k < n; ++k) {
    if (k == step_at) proc.depth = 1.3;  // 30 % deeper cut
    io.set_force(proc.step(r.loop.status()));
    r.step();
    const auto st = r.loop.status();
    if (k == step_at - 1) f.force_before_step = st.force_N;
    if (k > step_at) {
      f.min_override = std::min(f.min_override, st.force_override);
      f.max_spindle_rpm = std::max(f.max_spindle_rpm, std::abs(st.spindle_rpm_cmd));
    }
    f.force_end = st.force_N;
  }
  f.state_end = r.loop.status().state;
  return f;
}

TEST(ServoLoopForce, DepthOfCutStepIsRegulatedBackToTheReference) {
  const CutFigures off = cut(false);
  const CutFigures on = cut(true);
  std::printf(
      "force off: %.3f N before the step, %.3f N at the end; force on: %.3f N before, "
      "%.3f N at the end, min override %.3f, max spindle %.0f rpm\n",
      off.force_before_step, off.force_end, on.force_before_step, on.force_end, on.min_override,
      on.max_spindle_rpm);
  EXPECT_EQ(on.state_end, MachineState::kRunning);
  // Without force control the force follows the depth (1.3 N); with it, back to 1 N (2 %).
  EXPECT_NEAR(off.force_end, 1.3, 0.03);
  EXPECT_NEAR(on.force_before_step, 1.0, 0.02);
  EXPECT_NEAR(on.force_end, 1.0, 0.02);
  // ... by acting on the feed and/or the spindle.
  EXPECT_TRUE(on.min_override < 0.98 || on.max_spindle_rpm > 3050.0);
}

TEST(ServoLoopForce, StaleSampleHoldsTheFeedVisiblyAndForceOffResumes) {
  const auto cfg = force_config(true);
  ASSERT_EQ(cfg.force.limits.fallback, control::ForceFallback::kHold);
  FakeIo io;
  Rig r(cfg, &io);
  ASSERT_TRUE(r.enable());
  r.load(kCut, 1);
  r.loop.post({CommandKind::kRun});
  Process proc(cfg);
  for (int k = 0; k < 2000; ++k) {
    io.set_force(proc.step(r.loop.status()));
    r.step();
  }
  ASSERT_TRUE(r.loop.status().force_active);
  io.set_force(1.0, ForceState::kStale);
  r.step();
  auto st = r.loop.status();
  EXPECT_TRUE(st.force_fallback);
  EXPECT_FALSE(st.force_active);
  EXPECT_EQ(st.force_status, control::ForceStatus::kStaleHold);
  EXPECT_EQ(st.force_state, ForceState::kStale);
  EXPECT_EQ(st.force_override, 0.0);
  EXPECT_EQ(r.count(EventKind::kForceFallback), 1u);
  r.step(1000);  // the interpolator ramps the path speed down (FIR 100 ms)
  const double p1 = r.loop.status().progress_mm;
  r.step(500);
  st = r.loop.status();
  EXPECT_EQ(st.progress_mm, p1) << "feed held";
  EXPECT_EQ(st.state, MachineState::kRunning);
  EXPECT_EQ(r.count(EventKind::kForceFallback), 1u) << "logged once";
  // Valid samples again: noted, but force control stays off until asked.
  io.set_force(1.0);
  r.step();
  EXPECT_EQ(r.count(EventKind::kForceRecovered), 1u);
  EXPECT_TRUE(r.loop.status().force_fallback);
  // `force off`: continue at the programmed feed.
  r.loop.post({CommandKind::kForce, 0, std::nan(""), 0.0});
  r.step(1000);
  st = r.loop.status();
  EXPECT_FALSE(st.force_requested);
  EXPECT_DOUBLE_EQ(st.force_override, 1.0);
  EXPECT_GT(st.progress_mm, p1 + 3.0);
}

TEST(ServoLoopForce, StaleWithProgrammedFeedFallbackContinuesAndOptionFaults) {
  {
    auto cfg = force_config(true);
    cfg.force.limits.fallback = control::ForceFallback::kProgrammedFeed;
    FakeIo io;
    Rig r(cfg, &io);
    ASSERT_TRUE(r.enable());
    r.load(kCut, 1);
    r.loop.post({CommandKind::kRun});
    io.set_force(1.0);
    r.step(1000);
    io.set_force(1.0, ForceState::kInvalid);
    r.step(2000);
    const auto st = r.loop.status();
    EXPECT_TRUE(st.force_fallback);
    EXPECT_EQ(st.force_status, control::ForceStatus::kStaleProgrammed);
    EXPECT_DOUBLE_EQ(st.force_override, 1.0);
    EXPECT_EQ(st.state, MachineState::kRunning);
  }
  {
    LoopOptions opt;
    opt.force_stale_faults = true;
    FakeIo io;
    Rig r(force_config(true), &io, opt);
    ASSERT_TRUE(r.enable());
    r.load(kCut, 1);
    r.loop.post({CommandKind::kRun});
    io.set_force(1.0);
    r.step(500);
    io.set_force(1.0, ForceState::kStale);
    r.step(2);
    const auto st = r.loop.status();
    EXPECT_EQ(st.state, MachineState::kFault);
    EXPECT_EQ(st.cause, FaultCause::kForceStale);
  }
}

TEST(ServoLoopForce, ForceCommandWithoutAForceSourceIsRefused) {
  Rig r(sim_config());  // no RtIo
  ASSERT_TRUE(r.enable());
  EXPECT_FALSE(r.loop.force_configured());
  r.loop.post({CommandKind::kForce, 1, 1.0, 0.0});
  r.step();
  EXPECT_EQ(r.count(EventKind::kCommandRefused), 1u);
  EXPECT_FALSE(r.loop.status().force_requested);
}

TEST(ServoLoopForce, NoAllocationOver10kCyclesWithForceControlOn) {
  const auto cfg = force_config(true);
  FakeIo io;
  Rig r(cfg, &io);
  ASSERT_TRUE(r.enable());
  r.load(kCut, 1);
  r.loop.post({CommandKind::kRun});
  Process proc(cfg);
  r.step(3);
  RtEvent e;
  TelemetrySample s;
  std::size_t allocs = 0;
  {
    test::AllocGuard g;
    for (int i = 0; i < 10000; ++i) {
      io.set_force(proc.step(r.loop.status()), i == 8000 ? ForceState::kStale : ForceState::kOk);
      r.loop.cycle();
      while (r.loop.events().pop(e)) {
      }
      while (r.loop.telemetry().pop(s)) {
      }
    }
    allocs = g.counts().total();
  }
  EXPECT_EQ(allocs, 0u);
  EXPECT_TRUE(r.loop.status().force_fallback);  // the stale path ran inside the guard too
}

TEST(ServoLoopForce, EstopFromTheRtIoLatchIsEstopInTheSameCycle) {
  FakeIo io;
  Rig r(sim_config(), &io);
  ASSERT_TRUE(r.enable());
  io.estop = true;
  r.step(1);
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop);
  EXPECT_EQ(r.loop.status().cause, FaultCause::kEstopInput);
  EXPECT_TRUE(r.loop.status().estop_input);
  EXPECT_FALSE(r.loop.status().out_drive_enable);
  r.loop.post({CommandKind::kReset});
  r.step(3);
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop) << "latch still set";
  io.estop = false;
  r.loop.post({CommandKind::kReset});
  r.step(10);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
}

config::Config gpio_config() {
  auto cfg = sim_config();
  cfg.gpio.enabled = true;
  cfg.gpio.backend = "sim";
  auto line = [](const char* name, const char* role, bool active_low) {
    drivers::gpio::LineSpec l;
    l.name = name;
    l.role = role;
    l.active_low = active_low;
    return l;
  };
  cfg.gpio.lines.estop = line("ESTOP", "estop", true);
  cfg.gpio.lines.drive_enable = line("DRIVE_EN", "drive_enable", false);
  cfg.gpio.lines.spindle_enable = line("SPINDLE_EN", "spindle_enable", false);
  cfg.gpio.lines.coolant_mist = line("MIST", "coolant_mist", false);
  cfg.gpio.lines.coolant_flood = line("FLOOD", "coolant_flood", false);
  cfg.gpio.lines.alive = line("ALIVE", "alive", false);
  cfg.gpio.lines.estop_debounce = std::chrono::microseconds(1000);
  return cfg;
}

template <typename Pred>
bool poll(Pred p) {
  // Waits for a non-RT thread (the E-stop monitor); bounded, no timing assertion.
  for (int i = 0; i < 5000; ++i) {
    if (p()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

TEST(IoChannels, SimGpioEstopReachesTheLoopWithinOneCycleOfTheMonitorLatch) {
  const auto cfg = gpio_config();
  IoChannels io(cfg);
  ASSERT_NE(io.sim_gpio(), nullptr);
  io.start({});
  Rig r(cfg, &io);
  ASSERT_TRUE(r.enable());
  EXPECT_FALSE(io.estop_tripped()) << "sim E-stop starts released";
  io.sim_gpio()->set_input_level(io.sim_key("estop"), false);  // active low: pressed
  ASSERT_TRUE(poll([&] { return io.estop_tripped(); }));
  r.step(1);
  EXPECT_EQ(r.loop.status().state, MachineState::kEstop);
  EXPECT_EQ(r.loop.status().cause, FaultCause::kEstopInput);
  EXPECT_FALSE(io.reset_estop()) << "still pressed";
  io.sim_gpio()->set_input_level("ESTOP", true);
  ASSERT_TRUE(poll([&] { return !io.estop_asserted(); }));
  EXPECT_TRUE(io.reset_estop());
  r.loop.post({CommandKind::kReset});
  r.step(10);
  EXPECT_EQ(r.loop.status().state, MachineState::kReady);
  io.stop();
}

TEST(IoChannels, OutputsFollowDrivesSpindleAndCoolantFromTheProgram) {
  const auto cfg = gpio_config();
  IoChannels io(cfg);
  io.start({});
  Rig r(cfg, &io);
  auto apply = [&] {
    const auto st = r.loop.status();
    io.apply_outputs(
        {st.out_drive_enable, st.out_spindle_enable, st.out_mist, st.out_flood, st.cycle});
  };
  auto* sim = io.sim_gpio();
  apply();
  EXPECT_FALSE(sim->output_active("DRIVE_EN"));
  ASSERT_TRUE(r.enable());
  apply();
  EXPECT_TRUE(sim->output_active("DRIVE_EN"));
  r.load("G21 G90\nM3 S1200\nM8\nG01 X5 F600\nM9\nM7\nG01 X10\nM5 M9\nM2\n", 1);
  r.loop.post({CommandKind::kRun});
  bool flood = false, mist = false, spindle = false, both = false;
  for (int k = 0; k < 5000 && r.loop.status().finished_job != 1; ++k) {
    r.step();
    apply();
    flood = flood || sim->output_active("FLOOD");
    mist = mist || sim->output_active("MIST");
    both = both || (sim->output_active("FLOOD") && sim->output_active("MIST"));
    if (sim->output_active("SPINDLE_EN")) {
      spindle = true;
      // sim.yaml's spindle: the command ramps (rate_rpm_s) to the programmed S.
      EXPECT_DOUBLE_EQ(r.loop.status().spindle_target_rpm, 1200.0);
      EXPECT_GT(r.loop.status().spindle_rpm_cmd, 0.0);
      EXPECT_LE(r.loop.status().spindle_rpm_cmd, 1200.0);
    }
  }
  EXPECT_TRUE(r.loop.status().finished_ok);
  EXPECT_TRUE(flood);
  EXPECT_TRUE(mist);
  EXPECT_FALSE(both) << "M9 between M8 and M7";
  EXPECT_TRUE(spindle);
  EXPECT_EQ(r.loop.status().spindle_waits, 1u);  // G01 X5 waited for the spindle
  r.step(2);  // the cycle after the program ended (M2: spindle and coolant off)
  apply();
  EXPECT_FALSE(sim->output_active("SPINDLE_EN"));
  EXPECT_FALSE(sim->output_active("FLOOD"));
  EXPECT_FALSE(sim->output_active("MIST"));
  EXPECT_GT(io.alive_toggles(), 100u);
  // E-stop: drive enable off.
  r.loop.post({CommandKind::kEstop});
  r.step();
  apply();
  EXPECT_FALSE(sim->output_active("DRIVE_EN"));
  io.stop();
}

}  // namespace
}  // namespace contour::daemon
