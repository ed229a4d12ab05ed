#include "daemon/sim_bus.hpp"

#include <cmath>
#include <stdexcept>

#include "drivers/canopen/codec.hpp"

namespace contour::daemon {

SimBus::SimBus(const std::vector<control::FeedDriveParams>& drives,
               const std::vector<double>& can_counts_per_mm, bool can_velocity_mapped)
    : can_velocity_mapped_(can_velocity_mapped) {
  if (drives.empty() || drives.size() > kMaxAxes) {
    throw std::invalid_argument("SimBus: 1 to 3 axes");
  }
  if (!can_counts_per_mm.empty()) {
    if (can_counts_per_mm.size() != drives.size()) {
      throw std::invalid_argument("SimBus: one counts_per_mm per axis");
    }
    for (std::size_t i = 0; i < drives.size(); ++i) {
      if (!(can_counts_per_mm[i] > 0.0)) throw std::invalid_argument("SimBus: counts_per_mm > 0");
      can_cpm_[i] = can_counts_per_mm[i];
    }
  }
  axes_ = static_cast<int>(drives.size());
  for (std::size_t i = 0; i < drives.size(); ++i) {
    // The bus itself adds the one-cycle RPDO latch; the plant keeps any extra delay configured.
    control::FeedDriveParams p = drives[i];
    p.delay_cycles = p.delay_cycles > 0 ? p.delay_cycles - 1 : 0;
    drive_[i].configure(p);
  }
  for (auto& f : fault_) f = false;
  for (auto& d : disabled_) d = false;
  for (auto& m : di_force_mask_) m = 0;
  for (auto& v : di_force_values_) v = 0;
  for (std::size_t i = 0; i < kMaxAxes; ++i) true_pub_[i] = i < drives.size() ? drive_[i].position_mm() : 0.0;
}

void SimBus::add_input_switch(int axis, int bit, double threshold_mm, bool on_above) {
  if (axis < 0 || axis >= axes_) throw std::invalid_argument("SimBus: no axis " + std::to_string(axis));
  if (bit < 0 || bit > 31) throw std::invalid_argument("SimBus: 0x60FD bit 0..31");
  const auto a = static_cast<std::size_t>(axis);
  if (switch_count_[a] >= kMaxSwitches) throw std::invalid_argument("SimBus: too many switches");
  switches_[a][switch_count_[a]++] = Switch{bit, threshold_mm, on_above};
}

void SimBus::clear_input_switches() noexcept { switch_count_.fill(0); }

void SimBus::set_encoder_index(int axis, double pitch_mm, double phase_mm) {
  if (axis < 0 || axis >= axes_) throw std::invalid_argument("SimBus: no such axis");
  if (!(pitch_mm >= 0.0) || !std::isfinite(phase_mm)) throw std::invalid_argument("SimBus: index pitch >= 0");
  const auto a = static_cast<std::size_t>(axis);
  index_pitch_mm_[a] = pitch_mm;
  index_phase_mm_[a] = phase_mm;
}

void SimBus::configure_drive_homing(int axis, const DriveHomingParams& p) {
  if (axis < 0 || axis >= axes_) throw std::invalid_argument("SimBus: no such axis");
  if (!(p.search_mm_s >= 0.0) || !(p.latch_mm_s >= 0.0) || !(p.accel_mm_s2 > 0.0)) {
    throw std::invalid_argument("SimBus: drive homing speeds >= 0, acceleration > 0");
  }
  home_params_[static_cast<std::size_t>(axis)] = p;
}

void SimBus::set_drive_homing_supported(int axis, bool supported) {
  if (axis < 0 || axis >= axes_) throw std::invalid_argument("SimBus: no such axis");
  home_supported_[static_cast<std::size_t>(axis)] = supported;
}

std::uint32_t SimBus::inputs_at(std::size_t a, double x) const noexcept {
  std::uint32_t di = 0;
  for (std::size_t k = 0; k < switch_count_[a]; ++k) {
    const Switch& sw = switches_[a][k];
    if (sw.on_above ? x > sw.threshold_mm : x < sw.threshold_mm) di |= 1u << sw.bit;
  }
  const std::uint32_t m = di_force_mask_[a].load(std::memory_order_relaxed);
  return (di & ~m) | (di_force_values_[a].load(std::memory_order_relaxed) & m);
}

void SimBus::home_here(std::size_t a, double x_true) noexcept {
  encoder_zero_mm_[a] = x_true;
  home_rezeroed_[a] = true;
}

// One drive period of CiA 402 homing mode 6 (the drive's own profile, ramped at the acceleration
// of 0x609A). The methods (config::kDriveMethods): the switch and the side it sits on, and whether
// home is where the switch opens as the axis leaves it (17, 18, 19, 21) or where it closes on a
// slow approach after backing off (20, 22).
void SimBus::step_drive_homing(std::size_t a) noexcept {
  const DriveHomingParams& p = home_params_[a];
  const double x = drive_[a].position_mm();
  const double period = drive_[a].params().period_s;
  const std::uint32_t di = inputs_at(a, x);
  int bit = 2;
  double side = -1.0;  // where the switch is
  bool leave = true;
  switch (p.method) {
    case 17: bit = 0; side = -1.0; break;
    case 18: bit = 1; side = 1.0; break;
    case 19: side = 1.0; break;
    case 20: side = 1.0; leave = false; break;
    case 21: side = -1.0; break;
    case 22: side = -1.0; leave = false; break;
    case 33: side = -1.0; break;
    case 34: side = 1.0; break;
    default: break;
  }
  const bool sw = (di >> bit & 1u) != 0;
  HomeStage& st = home_stage_[a];
  double v_target = 0.0;
  switch (st) {
    case HomeStage::kSearch:
      if (sw) {
        st = HomeStage::kBrake;
        home_after_brake_[a] = HomeStage::kAway;
      } else {
        v_target = side * p.search_mm_s;
      }
      break;
    case HomeStage::kAway:
      if (!sw) {
        if (leave) home_here(a, x);
        st = HomeStage::kBrake;
        home_after_brake_[a] = leave ? HomeStage::kAttained : HomeStage::kApproach;
      } else {
        v_target = -side * p.latch_mm_s;
      }
      break;
    case HomeStage::kApproach:
      if (sw) {
        home_here(a, x);
        st = HomeStage::kBrake;
        home_after_brake_[a] = HomeStage::kAttained;
      } else {
        v_target = side * p.latch_mm_s;
      }
      break;
    case HomeStage::kIndex: {
      // The first index pulse crossed since the last period, exactly (the drive latches it).
      const double pitch = index_pitch_mm_[a];
      const double prev = home_prev_x_[a];
      if (pitch > 0.0 && x != prev) {
        const bool up = x > prev;
        const double lo = std::min(x, prev), hi = std::max(x, prev);
        const double k = up ? std::floor((lo - index_phase_mm_[a]) / pitch) + 1.0
                            : std::ceil((hi - index_phase_mm_[a]) / pitch) - 1.0;
        const double at = index_phase_mm_[a] + k * pitch;
        if (at > lo && at < hi) {
          home_here(a, at);
          st = HomeStage::kBrake;
          home_after_brake_[a] = HomeStage::kAttained;
          break;
        }
      }
      v_target = side * p.latch_mm_s;
      break;
    }
    case HomeStage::kBrake:
      if (home_v_[a] == 0.0 && std::abs(drive_[a].velocity_mm_s()) < 0.05) st = home_after_brake_[a];
      break;
    case HomeStage::kIdle:
    case HomeStage::kAttained:
    case HomeStage::kError:
      break;
  }
  // A limit switch ahead that is not the target: the search went the wrong way (no such switch
  // on that side). The drive stops and reports a homing error.
  const bool moving = st == HomeStage::kSearch || st == HomeStage::kAway || st == HomeStage::kApproach ||
                      st == HomeStage::kIndex;
  if (moving && ((v_target < 0.0 && (di & 1u) != 0 && bit != 0) || (v_target > 0.0 && (di & 2u) != 0 && bit != 1))) {
    st = HomeStage::kError;
    v_target = 0.0;
  }
  const double dv = p.accel_mm_s2 * period;
  home_v_[a] = v_target > home_v_[a] ? std::min(v_target, home_v_[a] + dv) : std::max(v_target, home_v_[a] - dv);
  if (st == HomeStage::kError) home_v_[a] = 0.0;  // stopped at once (the plant's lag remains)
  home_prev_x_[a] = x;
}

void SimBus::begin_cycle() noexcept {
  // SYNC: the drives act on the command latched at the previous SYNC for one period, then latch
  // the newest one.
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const bool on = mode_ == DriveMode::kEnabled && !fault_[a] && !disabled_[a];
    // Homing by the drive: a rising request starts mode 6, a falling one returns to velocity mode.
    if (!home_latched_[a]) {
      home_stage_[a] = HomeStage::kIdle;
    } else if (home_stage_[a] == HomeStage::kIdle && home_supported_[a]) {
      const int m = home_params_[a].method;
      home_v_[a] = 0.0;
      home_prev_x_[a] = drive_[a].position_mm();
      if (!on || m == 0) {
        home_stage_[a] = HomeStage::kError;
      } else if (m == 35 || m == 37) {
        home_here(a, drive_[a].position_mm());
        home_stage_[a] = HomeStage::kBrake;
        home_after_brake_[a] = HomeStage::kAttained;
      } else {
        home_stage_[a] = m == 33 || m == 34 ? HomeStage::kIndex : HomeStage::kSearch;
      }
    }
    const bool homing = home_stage_[a] != HomeStage::kIdle;
    if (homing && !on && home_stage_[a] != HomeStage::kAttained) home_stage_[a] = HomeStage::kError;
    if (homing && on) step_drive_homing(a);
    const double v = !on ? 0.0 : homing ? home_v_[a] : latched_v_[a];
    drive_[a].step_velocity(v);
    true_pub_[a].store(drive_[a].position_mm(), std::memory_order_relaxed);
    latched_v_[a] = received_v_[a];
    do_latched_[a] = do_received_[a];
    home_latched_[a] = home_received_[a];
  }
  if (spindle_tau_s_ > 0.0 && !spindle_stall_) {
    const double target = mode_ == DriveMode::kEnabled ? spindle_latched_rpm_ : 0.0;
    const double a = std::exp(-drive_[0].params().period_s / spindle_tau_s_);
    spindle_rpm_ = a * spindle_rpm_ + (1.0 - a) * target;
  }
  spindle_latched_rpm_ = spindle_received_rpm_;
  mode_ = received_mode_;
  ++cycle_;
}

void SimBus::read(BusFeedback& fb) noexcept {
  fb.axes = axes_;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    AxisFeedback& f = fb.axis[a];
    if (can_cpm_[a] > 0.0) {
      // What CanopenBus makes of the drive's TPDO (see the constructor's comment).
      const double cpm = can_cpm_[a];
      const std::int64_t counts = std::llround((drive_[a].position_mm() - encoder_zero_mm_[a]) * cpm);
      if (home_rezeroed_[a]) {
        // The drive set its position at the home point: the difference velocity restarts there
        // (CanopenBus does the same at the jump).
        can_last_counts_[a] = counts;
      }
      f.position_mm = static_cast<double>(counts) / cpm;
      if (can_velocity_mapped_) {
        f.velocity_mm_s = static_cast<double>(std::llround(drive_[a].velocity_mm_s() * cpm)) / cpm;
      } else {
        f.velocity_mm_s = can_have_last_ ? drivers::canopen::counts_velocity_mm_s(
                                               counts - can_last_counts_[a], cpm,
                                               drive_[a].params().period_s * 1.0)
                                         : 0.0;
        can_last_counts_[a] = counts;
      }
    } else {
      f.position_mm = drive_[a].measured_mm() - encoder_zero_mm_[a];
      f.velocity_mm_s = drive_[a].velocity_mm_s();
    }
    home_rezeroed_[a] = false;
    f.fresh = true;
    if (drop_tpdos_[a].load(std::memory_order_relaxed) > 0) {
      drop_tpdos_[a].fetch_sub(1, std::memory_order_relaxed);
      f.fresh = false;  // position/velocity hold their last values in the loop's snapshot
    }
    // 0x60FD: sampled with the position (the same TPDO timing); a dropped TPDO leaves the last
    // value, not fresh.
    f.digital_inputs_present = true;
    f.digital_inputs_fresh = f.fresh;
    if (const int n = drop_input_tpdos_[a].load(std::memory_order_relaxed); n != 0) {
      if (n > 0) drop_input_tpdos_[a].fetch_sub(1, std::memory_order_relaxed);
      f.digital_inputs_fresh = false;
    }
    if (f.digital_inputs_fresh) di_last_[a] = inputs_at(a, drive_[a].position_mm());
    f.digital_inputs = di_last_[a];
    // Encoder index: a pulse between the previous true position and this one is latched at its
    // exact position (in the reported coordinates; counts with CANopen quantisation).
    f.index_present = index_pitch_mm_[a] > 0.0;
    const double x_true = drive_[a].position_mm();
    if (f.index_present && index_armed_[a] && !index_latched_[a] && x_true != index_prev_mm_[a]) {
      const double p = index_pitch_mm_[a];
      const double lo = std::min(x_true, index_prev_mm_[a]);
      const double hi = std::max(x_true, index_prev_mm_[a]);
      // The first pulse position above lo (moving up) or below hi (moving down).
      const bool up = x_true > index_prev_mm_[a];
      const double k = up ? std::floor((lo - index_phase_mm_[a]) / p) + 1.0
                          : std::ceil((hi - index_phase_mm_[a]) / p) - 1.0;
      const double at = index_phase_mm_[a] + k * p;
      if (at > lo && at < hi) {
        index_latched_[a] = true;
        const double rel = at - encoder_zero_mm_[a];
        index_at_mm_[a] = can_cpm_[a] > 0.0 ? static_cast<double>(std::llround(rel * can_cpm_[a])) / can_cpm_[a] : rel;
      }
    }
    index_prev_mm_[a] = x_true;
    f.index_latched = index_latched_[a];
    f.index_position_mm = index_at_mm_[a];
    f.fault = fault_[a];
    f.enabled = mode_ == DriveMode::kEnabled && !f.fault && !disabled_[a];
    f.statusword = f.fault ? 0x0008 : (f.enabled ? 0x0027 : 0x0040);
    f.drive_homing_present = true;
    f.drive_homing_detail = 0;
    switch (home_stage_[a]) {
      case HomeStage::kIdle:
        f.drive_homing = DriveHoming::kIdle;
        if (home_latched_[a] && !home_supported_[a]) {
          f.drive_homing = DriveHoming::kUnsupported;
          f.drive_homing_detail = 0x609800;
        }
        break;
      case HomeStage::kAttained:
        f.drive_homing = DriveHoming::kAttained;
        f.statusword |= 0x1400;  // target reached, homing attained
        break;
      case HomeStage::kError:
        f.drive_homing = DriveHoming::kError;
        f.statusword |= 0x2000;
        f.drive_homing_detail = f.statusword;
        break;
      default: f.drive_homing = DriveHoming::kRunning; break;
    }
  }
  if (can_cpm_[0] > 0.0) can_have_last_ = true;
  fb.spindle.present = spindle_tau_s_ > 0.0;
  fb.spindle.fresh = fb.spindle.present;
  fb.spindle.actual_rpm = spindle_rpm_;
  fb.spindle.enabled = fb.spindle.present && mode_ == DriveMode::kEnabled;
  fb.spindle.fault = fb.spindle.present && spindle_fault_;
}

void SimBus::write(const AxisCommands& cmd) noexcept {
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    received_v_[a] = can_cpm_[a] > 0.0 ? static_cast<double>(drivers::canopen::mm_s_to_counts_s(
                                             cmd.velocity_mm_s[a], can_cpm_[a])) /
                                             can_cpm_[a]
                                       : cmd.velocity_mm_s[a];
    do_received_[a] = cmd.digital_outputs[a] & cmd.digital_output_mask[a];
    index_armed_[a] = cmd.index_arm[a];
    home_received_[a] = cmd.drive_home[a];
    if (!index_armed_[a]) index_latched_[a] = false;
  }
  received_mode_ = cmd.mode;
  spindle_received_rpm_ = std::isfinite(cmd.spindle_rpm) ? cmd.spindle_rpm : 0.0;
}

bool SimBus::set_position(int axis, double position_mm) {
  if (axis < 0 || axis >= axes_) return false;
  drive_[static_cast<std::size_t>(axis)].reset(position_mm + encoder_zero_mm_[static_cast<std::size_t>(axis)]);
  latched_v_[static_cast<std::size_t>(axis)] = 0.0;
  received_v_[static_cast<std::size_t>(axis)] = 0.0;
  return true;
}

void SimBus::power_up_at(int axis, double true_mm) {
  if (axis < 0 || axis >= axes_) throw std::invalid_argument("SimBus::power_up_at: no such axis");
  const auto a = static_cast<std::size_t>(axis);
  drive_[a].reset(true_mm);
  true_pub_[a].store(true_mm, std::memory_order_relaxed);
  encoder_zero_mm_[a] = true_mm;
  index_prev_mm_[a] = true_mm;
}

std::string SimBus::describe() const {
  return "simulated machine, " + std::to_string(axes_) + " axes (in-process, lockstep" +
         (can_cpm_[0] > 0.0 ? ", CANopen count quantisation)" : ")");
}

std::vector<control::FeedDriveParams> sim_bus_drives(const config::Config& cfg) {
  std::vector<control::FeedDriveParams> drives;
  for (const auto& a : cfg.machine.axes) {
    control::FeedDriveParams p = a.drive;
    p.period_s = cfg.machine.period_s;
    drives.push_back(p);
  }
  return drives;
}

std::unique_ptr<SimBus> make_sim_bus(const config::Config& cfg) {
  std::vector<double> cpm;
  bool velocity_mapped = false;
  if (cfg.bus.type == "socketcan") {
    for (const auto& a : cfg.machine.axes) cpm.push_back(a.counts_per_mm);
    // The axes' TPDO mapping (bus.drives / bus.nodes): 0x606C mapped on the first axis decides
    // for all (a mixed mapping is not modelled).
    const auto nodes = config::resolve_bus_nodes(cfg.bus, cfg.machine);
    if (!nodes.empty()) {
      for (const auto& e : nodes.front().tpdo)
        velocity_mapped = velocity_mapped || e.index == 0x606C;
    }
  }
  auto bus = std::make_unique<SimBus>(sim_bus_drives(cfg), cpm, velocity_mapped);
  // The spindle: the built-in machine's (spindle.type sim), or, for an offline run of a CANopen
  // config, the simulated spindle drive's lag when its speed (0x606C) is fed back.
  bool can_spindle_feedback = false;
  if (cfg.bus.type == "socketcan" && cfg.bus.spindle) {
    for (const auto& e : cfg.bus.spindle->tpdo) can_spindle_feedback = can_spindle_feedback || e.index == 0x606C;
  }
  if (cfg.spindle.type == "sim" || can_spindle_feedback) bus->configure_spindle(cfg.spindle.sim_tau_s);
  configure_sim_machine(*bus, cfg);
  return bus;
}

void add_default_input_switches(SimBus& bus, const config::Config& cfg) {
  for (std::size_t a = 0; a < cfg.machine.axes.size() && a < static_cast<std::size_t>(kMaxAxes); ++a) {
    const auto& ax = cfg.machine.axes[a];
    const int i = static_cast<int>(a);
    bus.add_input_switch(i, 0, ax.min_mm - kSimLimitMargin_mm, false);
    bus.add_input_switch(i, 1, ax.max_mm + kSimLimitMargin_mm, true);
    bus.add_input_switch(i, 2, ax.min_mm + kSimHomeBand_mm, false);
  }
}

}  // namespace contour::daemon

namespace contour::daemon {

void configure_sim_machine(SimBus& bus, const config::Config& cfg) {
  add_default_input_switches(bus, cfg);
  for (std::size_t a = 0; a < cfg.machine.axes.size() && a < static_cast<std::size_t>(kMaxAxes); ++a) {
    if (cfg.machine.axes[a].sim_power_up_mm != 0.0) {
      bus.power_up_at(static_cast<int>(a), cfg.machine.axes[a].sim_power_up_mm);
    }
    bus.set_encoder_index(static_cast<int>(a), cfg.machine.axes[a].sim_index_pitch_mm,
                          cfg.machine.axes[a].sim_index_phase_mm);
    const config::HomeConfig& h = cfg.machine.axes[a].home;
    if (h.method == config::HomeConfig::Method::kDrive) {
      bus.configure_drive_homing(static_cast<int>(a), {h.drive_method, h.search_vel_mm_s,
                                                       h.latch_vel_mm_s, h.drive_accel_mm_s2});
    }
  }
}

}  // namespace contour::daemon
