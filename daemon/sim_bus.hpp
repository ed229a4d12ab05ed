#pragma once
// In-process simulated machine: the same FeedDrive plant as contour-sim and contour-machine-sim,
// advancing exactly one step per begin_cycle() (lockstep), so a daemon run gives contour-sim's
// figures however late its cycles wake. The command written in cycle k is latched at SYNC k+1 and
// acts from there (CANopen synchronous RPDO semantics), on top of the drive's own configured
// transport delay (machine.axes[].sim.delay_cycles counts the total delay, as in contour-sim).
#include <array>
#include <atomic>
#include <vector>

#include "control/feed_drive.hpp"
#include "daemon/axis_bus.hpp"

namespace contour::daemon {

class SimBus final : public AxisBus {
 public:
  explicit SimBus(const std::vector<control::FeedDriveParams>& drives);

  void start() override {}
  void stop() noexcept override {}
  void begin_cycle() noexcept override;
  void read(BusFeedback& fb) noexcept override;
  void write(const AxisCommands& cmd) noexcept override;
  bool set_position(int axis, double position_mm) override;
  [[nodiscard]] std::string describe() const override;

  // Fault injection for tests (thread-safe: read by the RT thread each cycle).
  void inject_drive_fault(int axis, bool on) noexcept { fault_[static_cast<std::size_t>(axis)] = on; }

 private:
  int axes_ = 0;
  std::array<control::FeedDrive, kMaxAxes> drive_{};
  std::array<double, kMaxAxes> latched_v_{};   // command the drives act on
  std::array<double, kMaxAxes> received_v_{};  // last command written (latched at next SYNC)
  DriveMode mode_ = DriveMode::kDisabled;
  DriveMode received_mode_ = DriveMode::kDisabled;
  std::array<std::atomic<bool>, kMaxAxes> fault_{};
  std::uint64_t cycle_ = 0;
};

}  // namespace contour::daemon
