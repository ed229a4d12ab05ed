#include "daemon/sim_bus.hpp"

#include <stdexcept>

namespace contour::daemon {

SimBus::SimBus(const std::vector<control::FeedDriveParams>& drives) {
  if (drives.empty() || drives.size() > kMaxAxes) {
    throw std::invalid_argument("SimBus: 1 to 3 axes");
  }
  axes_ = static_cast<int>(drives.size());
  for (std::size_t i = 0; i < drives.size(); ++i) {
    // The bus itself adds the one-cycle RPDO latch; the plant keeps any extra delay configured.
    control::FeedDriveParams p = drives[i];
    p.delay_cycles = p.delay_cycles > 0 ? p.delay_cycles - 1 : 0;
    drive_[i].configure(p);
  }
  for (auto& f : fault_) f = false;
}

void SimBus::begin_cycle() noexcept {
  // SYNC: the drives act on the command latched at the previous SYNC for one period, then latch
  // the newest one.
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const double v = (mode_ == DriveMode::kEnabled && !fault_[a]) ? latched_v_[a] : 0.0;
    drive_[a].step_velocity(v);
    latched_v_[a] = received_v_[a];
  }
  mode_ = received_mode_;
  ++cycle_;
}

void SimBus::read(BusFeedback& fb) noexcept {
  fb.axes = axes_;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    AxisFeedback& f = fb.axis[a];
    f.position_mm = drive_[a].measured_mm();
    f.velocity_mm_s = drive_[a].velocity_mm_s();
    f.fresh = true;
    f.fault = fault_[a];
    f.enabled = mode_ == DriveMode::kEnabled && !f.fault;
    f.statusword = f.fault ? 0x0008 : (f.enabled ? 0x0027 : 0x0040);
  }
}

void SimBus::write(const AxisCommands& cmd) noexcept {
  for (int i = 0; i < axes_; ++i) {
    received_v_[static_cast<std::size_t>(i)] = cmd.velocity_mm_s[static_cast<std::size_t>(i)];
  }
  received_mode_ = cmd.mode;
}

bool SimBus::set_position(int axis, double position_mm) {
  if (axis < 0 || axis >= axes_) return false;
  drive_[static_cast<std::size_t>(axis)].reset(position_mm);
  latched_v_[static_cast<std::size_t>(axis)] = 0.0;
  received_v_[static_cast<std::size_t>(axis)] = 0.0;
  return true;
}

std::string SimBus::describe() const {
  return "simulated machine, " + std::to_string(axes_) + " axes (in-process, lockstep)";
}

}  // namespace contour::daemon
