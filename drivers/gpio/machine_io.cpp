#include "drivers/gpio/machine_io.hpp"

namespace contour::drivers::gpio {

namespace {
std::unique_ptr<GpioOutputLine> maybe_output(GpioBackend& b, const LineSpec& s) {
  if (!s.configured()) return nullptr;
  return b.request_output(s, false);
}
}  // namespace

MachineIo::MachineIo(GpioBackend& backend, const MachineIoSettings& s) {
  if (!s.estop.configured()) throw GpioError(s.estop.describe() + ": E-stop line is required");
  estop_ = std::make_unique<EstopMonitor>(backend.request_input(s.estop, true), s.estop_debounce);
  drive_ = maybe_output(backend, s.drive_enable);
  spindle_ = maybe_output(backend, s.spindle_enable);
  mist_ = maybe_output(backend, s.coolant_mist);
  flood_ = maybe_output(backend, s.coolant_flood);
  alive_ = maybe_output(backend, s.alive);
}

MachineIo::~MachineIo() {
  estop_->stop();
  // Safe state on the way out: enables off, coolant off.
  for (auto* l : {&drive_, &spindle_, &mist_, &flood_}) set(*l, false);
}

bool MachineIo::set(const std::unique_ptr<GpioOutputLine>& l, bool on) {
  if (!l) return false;
  l->set_active(on);
  return true;
}

bool MachineIo::set_drive_enable(bool on) { return set(drive_, on && !estop_->tripped()); }
bool MachineIo::set_spindle_enable(bool on) { return set(spindle_, on && !estop_->tripped()); }
bool MachineIo::set_coolant(bool mist, bool flood) {
  const bool a = set(mist_, mist);
  const bool b = set(flood_, flood);
  return a || b;
}
bool MachineIo::toggle_alive() { return alive_ ? set(alive_, !alive_->active()) : false; }

MachineIoState MachineIo::state() const {
  MachineIoState st;
  st.estop_asserted = estop_->asserted();
  st.estop_tripped = estop_->tripped();
  st.drive_enable = drive_ && drive_->active();
  st.spindle_enable = spindle_ && spindle_->active();
  st.coolant_mist = mist_ && mist_->active();
  st.coolant_flood = flood_ && flood_->active();
  st.alive = alive_ && alive_->active();
  return st;
}

}  // namespace contour::drivers::gpio
