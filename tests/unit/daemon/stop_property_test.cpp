// Issue 16, "A stop never adds energy": a seeded storm of faults at random instants on random
// programs, through the whole ServoLoop on the simulated machine (config/sim.yaml, cross-coupled
// controller). For every run:
//   - from the first FAULT cycle on, no axis' |velocity command| increases from one cycle to the
//     next (the ramp starts from a velocity the axis really has and decelerates monotonically);
//   - the first command of the stop is not above what the axis really did at the fault: its
//     measured velocity or its reference velocity, whichever is larger (the old ramp started from
//     the last command, which carries the coupling derivative's chatter);
//   - the drives are switched off only at standstill: when the loop first writes "disabled" after
//     the fault, every axis of the plant moves slower than safety.standstill_velocity_mm_s.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <sstream>
#include <string>

#include "tests/unit/daemon/loop_rig.hpp"

namespace contour::daemon {
namespace {

using test_rig::Rig;
using test_rig::sim_config;

std::string random_program(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> xy(-40.0, 40.0), z(-10.0, 10.0), f(1500.0, 4000.0);
  std::uniform_int_distribution<int> kind(0, 3);
  std::ostringstream p;
  p << "G21 G90 G17 G64 P0.02\nG01 X0 Y0 Z0 F" << f(rng) << "\n";
  double x = 0.0, y = 0.0;
  for (int i = 0; i < 8; ++i) {
    if (kind(rng) == 0) {
      // A quarter-ish arc around a centre 5..15 mm away (IJK form, end on the circle).
      const double r = 5.0 + 10.0 * std::uniform_real_distribution<double>(0, 1)(rng);
      const double a1 = M_PI + 1.2;  // G3 from the start at angle pi around the centre
      const double cx = x + r, cy = y;
      const double ex = cx + r * std::cos(a1), ey = cy + r * std::sin(a1);
      p << "G03 X" << ex << " Y" << ey << " I" << r << " J0\n";
      x = ex;
      y = ey;
    } else {
      x = xy(rng);
      y = xy(rng);
      p << "G01 X" << x << " Y" << y << " Z" << z(rng) << " F" << f(rng) << "\n";
    }
  }
  p << "M2\n";
  return p.str();
}

enum class Storm { kDriveFault, kDriveDisabled, kTpdoStreak, kContourLimit };

TEST(StopProperty, NoAxisEverSpeedsUpAfterAFaultAndDrivesGoOffOnlyAtStandstill) {
  const config::Config base = sim_config();
  int faults_seen = 0;
  for (std::uint64_t seed = 1; seed <= 24; ++seed) {
    std::mt19937_64 rng(seed);
    config::Config cfg = base;
    const auto storm = static_cast<Storm>(seed % 4);
    if (storm == Storm::kContourLimit) cfg.safety.contour_error_limit_mm = 0.004;  // trips mid-path
    Rig r(cfg);
    ASSERT_TRUE(r.enable());
    const std::string prog = random_program(rng);
    r.load(prog, seed);
    r.loop.post({CommandKind::kRun});
    r.step(2);
    const int fault_at = std::uniform_int_distribution<int>(200, 1500)(rng);
    const int axis = std::uniform_int_distribution<int>(0, 2)(rng);
    LoopStatus prev = r.loop.status();
    Eigen::Vector3d ref_prev(prev.ref_mm[0], prev.ref_mm[1], prev.ref_mm[2]);
    Eigen::Vector3d v_ref_at_fault = Eigen::Vector3d::Zero();
    BusFeedback fb{}, fb_at_fault{};
    bool faulted = false, first = true, disabled_checked = false;
    std::array<double, 3> last_cmd{};
    for (int k = 0; k < 8000; ++k) {
      if (k == fault_at) {
        switch (storm) {
          case Storm::kDriveFault: r.bus.inject_drive_fault(axis, true); break;
          case Storm::kDriveDisabled: r.bus.inject_drive_disabled(axis, true); break;
          case Storm::kTpdoStreak: r.bus.inject_tpdo_drop(axis, 10); break;
          case Storm::kContourLimit: break;
        }
      }
      r.step();
      r.bus.read(fb);  // the ideal sim bus: reading has no side effect; the plant's real velocity
      const LoopStatus st = r.loop.status();
      const Eigen::Vector3d ref(st.ref_mm[0], st.ref_mm[1], st.ref_mm[2]);
      if (!faulted && st.state == MachineState::kFault) {
        faulted = true;
        ++faults_seen;
        v_ref_at_fault = (ref - ref_prev) / r.loop.period_s();
        fb_at_fault = fb;  // what the loop read in the fault's cycle
        last_cmd = st.cmd_mm_s;  // the command written in the fault's own cycle
        ref_prev = ref;
        prev = st;
        continue;
      }
      if (faulted) {
        for (std::size_t a = 0; a < 3; ++a) {
          EXPECT_LE(std::abs(st.cmd_mm_s[a]), std::abs(last_cmd[a]) + 1e-9)
              << "seed " << seed << " axis " << a << " cycle " << k << " (" << to_string(prev.cause)
              << ")\n" << prog;
          if (first) {
            // What the axis did in the fault's cycle: its measured velocity, its reference velocity.
            const double real = std::max(std::abs(fb_at_fault.axis[a].velocity_mm_s),
                                         std::abs(v_ref_at_fault[static_cast<Eigen::Index>(a)]));
            // A stale axis (missed TPDOs) is judged by the loop from its drive-model estimate: the
            // plant's true speed is within a few per cent of it.
            const double tol = fb_at_fault.axis[a].fresh ? 0.5 : 0.5 + 0.05 * real;
            EXPECT_LE(std::abs(st.cmd_mm_s[a]), real + tol)
                << "seed " << seed << " axis " << a << ": the stop started from "
                << st.cmd_mm_s[a] << " mm/s, the axis did " << real << " mm/s";
          }
        }
        first = false;
        last_cmd = st.cmd_mm_s;
        if (!disabled_checked && r.bus.written_mode() == DriveMode::kDisabled) {
          disabled_checked = true;
          for (std::size_t a = 0; a < 3; ++a) {
            if (storm == Storm::kTpdoStreak && a == static_cast<std::size_t>(axis)) continue;
            EXPECT_LT(std::abs(fb.axis[a].velocity_mm_s), cfg.safety.standstill_velocity_mm_s)
                << "seed " << seed << ": drives disabled while axis " << a << " still moves";
          }
        }
        if (st.stop_phase == StopSource::Phase::kOff || st.stop_phase == StopSource::Phase::kQuickStop) {
          if (disabled_checked) break;
        }
      } else if (st.state == MachineState::kReady && st.finished_job == seed) {
        break;  // the program ended before the storm hit
      }
      ref_prev = ref;
      prev = st;
    }
    if (faulted) {
      EXPECT_TRUE(disabled_checked) << "seed " << seed << ": drives never disabled";
    }
  }
  EXPECT_GE(faults_seen, 16) << "the storm must actually hit most runs";
}

}  // namespace
}  // namespace contour::daemon
