#include "daemon/canopen_bus.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <stdexcept>

#include "drivers/can/socket_can.hpp"
#include "daemon/canopen_master_config.hpp"

namespace contour::daemon {

namespace co = drivers::canopen;

namespace {
std::int64_t mono_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}
co::DriveRequest to_request(DriveMode m) noexcept {
  switch (m) {
    case DriveMode::kEnabled:
      return co::DriveRequest::kEnabled;
    case DriveMode::kQuickStop:
      return co::DriveRequest::kQuickStop;
    case DriveMode::kDisabled:
      break;
  }
  return co::DriveRequest::kDisabled;
}
}  // namespace

CanopenBus::CanopenBus(const config::Config& cfg, Log log) : log_(std::move(log)) { init(cfg); }

CanopenBus::CanopenBus(const config::Config& cfg, drivers::CanBus& can, Log log)
    : log_(std::move(log)), can_(&can) {
  init(cfg);
}

CanopenBus::~CanopenBus() {
  if (started_) stop();
}

void CanopenBus::init(const config::Config& cfg) {
  const auto& axes = cfg.machine.axes;
  if (axes.empty() || axes.size() > static_cast<std::size_t>(kMaxAxes)) {
    throw std::runtime_error(cfg.source + ": machine.axes: the CANopen bus drives 1 to " +
                             std::to_string(kMaxAxes) + " axes");
  }
  for (std::size_t i = 0; i < axes.size(); ++i) {
    if (axes[i].node_id == 0) {
      throw std::runtime_error(cfg.source + ": machine.axes[" + std::to_string(i) + "] (" +
                               axes[i].name + ").node_id: required with bus.type socketcan");
    }
    if (!(axes[i].counts_per_mm > 0.0)) {
      throw std::runtime_error(cfg.source + ": machine.axes[" + std::to_string(i) + "] (" +
                               axes[i].name + ").counts_per_mm: must be > 0");
    }
    counts_per_mm_[i] = axes[i].counts_per_mm;
  }
  axes_ = static_cast<int>(axes.size());
  mcfg_ = master_config_from(cfg);  // axes first, in machine order, then the spindle
  for (std::size_t i = 0; i < mcfg_.nodes.size(); ++i) {
    if (mcfg_.nodes[i].kind == co::NodeKind::kIoModule) {
      if (io_count_ >= static_cast<int>(kMaxIoModules)) {
        throw std::runtime_error(cfg.source + ": plc.signals: more than " +
                                 std::to_string(kMaxIoModules) + " CiA 401 I/O modules");
      }
      io_index_[static_cast<std::size_t>(io_count_++)] = static_cast<int>(i);
      continue;
    }
    if (mcfg_.nodes[i].name == "spindle") spindle_index_ = static_cast<int>(i);
  }
  spindle_velocity_mapped_ =
      spindle_index_ >= 0 &&
      mcfg_.nodes[static_cast<std::size_t>(spindle_index_)].tpdo.find(0x606C) >= 0;
  for (int i = 0; i < axes_; ++i) {
    velocity_mapped_[static_cast<std::size_t>(i)] =
        mcfg_.nodes[static_cast<std::size_t>(i)].tpdo.find(0x606C) >= 0;
  }
  for (int i = 0; i < axes_; ++i) {
    csp_[static_cast<std::size_t>(i)] =
        mcfg_.nodes[static_cast<std::size_t>(i)].mode == co::DriveMode::kCsp;
    probe_[static_cast<std::size_t>(i)].mapped = mcfg_.nodes[static_cast<std::size_t>(i)].touch_probe;
  }
  period_s_ = cfg.machine.period_s;
  lockstep_ = cfg.bus_lockstep;
  if (lockstep_) {
    // Simulated drives answer every SYNC; a TPDO that is "late" only means this process or the
    // simulator was descheduled (VM steal time). Waiting keeps the run identical to contour-sim.
    mcfg_.tpdo_deadline_us = config::Config::kLockstepTpdoWaitMs * 1000;
  }
  ifname_ = cfg.bus.interface;
  period_ns_ = static_cast<std::int64_t>(cfg.loop.period_us) * 1000;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    const config::AxisConfig& ax = axes[a];
    max_step_counts_[a] = 2.0 * ax.max_velocity_mm_min / 60.0 * period_s_ * ax.counts_per_mm + 2.0;
    const config::HomeConfig& h = ax.home;
    if (h.method != config::HomeConfig::Method::kDrive) continue;
    HomeSeq& q = home_[a];
    q.configured = true;
    const double cpm = ax.counts_per_mm;
    auto u32 = [](double v) {
      return static_cast<std::uint32_t>(std::clamp(std::llround(std::abs(v)), 0LL, 0x7FFFFFFFLL));
    };
    const auto cyclic = static_cast<std::uint8_t>(mcfg_.nodes[a].mode);
    q.setup = {{{0x6098, 0, static_cast<std::uint8_t>(static_cast<std::int8_t>(h.drive_method)), 1},
                {0x6099, 1, u32(h.search_vel_mm_s * cpm), 4},
                {0x6099, 2, u32(h.latch_vel_mm_s * cpm), 4},
                {0x609A, 0, u32(h.drive_accel_mm_s2 * cpm), 4},
                {0x6060, 0, 6, 1},
                {0x6061, 0, 6, 0}}};
    q.back = {{{0x6060, 0, cyclic, 1}, {0x6061, 0, cyclic, 0}}};
  }
}

void CanopenBus::start() {
  if (started_) return;
  if (can_ == nullptr) {
    try {
      owned_can_ = std::make_unique<drivers::SocketCan>(ifname_, co::master_rx_filters(mcfg_));
    } catch (const drivers::SocketCanError& e) {
      throw std::runtime_error(std::string("bus.interface ") + e.what());
    }
    can_ = owned_can_.get();
  }
  master_ = std::make_unique<co::Master>(*can_, mcfg_, log_);
  if (log_) {
    const auto& l = master_->bus_load();
    log_("CANopen: " + describe() + "; bus load " +
         std::to_string(std::lround(l.worst_case * 100.0)) + " % worst case (" +
         std::to_string(std::lround(l.nominal * 100.0)) + " % nominal)");
  }
  master_->start_up();  // throws StartupError (a std::runtime_error) naming node and object
  master_->set_request_all(co::DriveRequest::kDisabled);
  cycle_ = 0;
  last_mode_ = DriveMode::kDisabled;
  for (auto& p : probe_) p = ProbeSeq{p.mapped};
  started_ = true;
  if (event_thread_wanted_ && log_) {
    stop_events_ = false;
    event_thread_ = std::thread([this] {
      while (!stop_events_.load(std::memory_order_acquire)) {
        drain_events(log_);
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    });
  }
}

void CanopenBus::run_cycles_for_stop() noexcept {
  // Up to 1 s of cycles at the loop period: enough for a quick-stop ramp (0x6085) and the
  // disable controlwords; ends as soon as no drive is powered.
  int silent = 0;
  for (int k = 0; k < 1000; ++k) {
    begin_cycle();
    BusFeedback fb;
    read(fb);
    bool any_fresh = false;
    for (std::size_t i = 0; i < master_->size(); ++i)
      any_fresh = any_fresh || master_->node(i).tpdo_fresh;
    // Nobody answers (drives gone, or pre-operational after a communication error): each cycle
    // would cost the whole TPDO wait; the controlwords below are sent a few times, then give up.
    silent = any_fresh ? 0 : silent + 1;
    bool powered = false;
    for (std::size_t i = 0; i < master_->size(); ++i) {
      const auto s = master_->node(i).state;
      powered = powered || s == co::Cia402State::kOperationEnabled ||
                s == co::Cia402State::kQuickStopActive || s == co::Cia402State::kSwitchedOn ||
                s == co::Cia402State::kFaultReactionActive;
    }
    bool enabled = false;
    for (std::size_t i = 0; i < master_->size(); ++i)
      enabled = enabled || master_->node(i).state == co::Cia402State::kOperationEnabled;
    // Quick stop while a drive still runs, then disable voltage.
    master_->set_request_all(enabled ? co::DriveRequest::kQuickStop : co::DriveRequest::kDisabled);
    for (std::size_t i = 0; i < master_->size(); ++i) {
      master_->set_target(i, 0);
      master_->set_digital_outputs(i, 0);  // the PLC's drive outputs off with the drives
      master_->set_touch_probe_function(i, 0);
    }
    for (int m = 0; m < io_count_; ++m)  // and the CiA 401 modules' outputs
      master_->set_io_outputs(static_cast<std::size_t>(io_index_[static_cast<std::size_t>(m)]), {},
                              {});
    master_->send_rpdos();
    if ((!powered && k > 2) || silent > 3) break;
    if (!lockstep_) {
      timespec ts{0, static_cast<long>(period_ns_)};
      nanosleep(&ts, nullptr);
    }
  }
}

void CanopenBus::stop() noexcept {
  if (!started_) return;
  started_ = false;
  run_cycles_for_stop();
  // NMT pre-operational: the nodes stop their PDOs but stay configured and answer SDOs.
  for (std::size_t i = 0; i < master_->size(); ++i) {
    can_->send(co::nmt_frame(co::NmtCommand::kPreOperational, master_->setup(i).node_id));
  }
  stop_events_.store(true, std::memory_order_release);
  if (event_thread_.joinable()) event_thread_.join();
  if (log_) {
    try {
      drain_events(log_);
      log_("CANopen: drives disabled, nodes pre-operational");
    } catch (...) {  // logging must not throw out of stop()
    }
  }
}

void CanopenBus::begin_cycle() noexcept {
  const std::int64_t now = lockstep_ ? static_cast<std::int64_t>(cycle_) * period_ns_ : mono_ns();
  ++cycle_;
  sync_ns_ = now;
  begin_fault_ = master_->begin_cycle(now) == co::CycleStatus::kFault;
}

void CanopenBus::read(BusFeedback& fb) noexcept {
  master_->collect();
  fb.axes = axes_;
  fb.heartbeat_lost = false;
  fb.heartbeat_lost_node = 0;
  for (std::size_t i = 0; i < master_->size(); ++i) {
    const co::NodeRuntime& r = master_->node(i);
    if ((r.faults & static_cast<std::uint8_t>(co::NodeFault::kHeartbeatLost)) != 0 &&
        !fb.heartbeat_lost) {
      fb.heartbeat_lost = true;
      fb.heartbeat_lost_node = master_->setup(i).node_id;
    }
    if (static_cast<int>(i) >= axes_) continue;
    AxisFeedback& f = fb.axis[i];
    const double cpm = counts_per_mm_[i];
    f.fresh = r.tpdo_fresh;
    if (r.tpdo_fresh) {
      f.position_mm = co::counts_to_mm(r.position_counts, cpm);
      if (velocity_mapped_[i]) {
        f.velocity_mm_s = static_cast<double>(r.velocity_counts_s) / cpm;
      } else {
        // Lockstep: readings n cycles apart are n periods apart in drive time (the same
        // expression as SimBus, bit for bit). Real drives sample at SYNC on the wall clock, and
        // a late or skipped cycle stretches the gap: use the SYNC times then.
        const double dt_s = lockstep_
                                ? period_s_ * static_cast<double>(cycle_ - last_fresh_cycle_[i])
                                : static_cast<double>(sync_ns_ - last_fresh_ns_[i]) * 1e-9;
        const std::int64_t step = r.position_counts - last_counts_[i];
        if (home_[i].step != HomeStep::kIdle && have_last_[i] &&
            std::abs(static_cast<double>(step)) > max_step_counts_[i]) {
          // The drive set its position at the home point: a reset, not motion (keep the last
          // velocity; the next reading differences from the new position).
        } else {
          f.velocity_mm_s = have_last_[i] && dt_s > 0.0 ? co::counts_velocity_mm_s(step, cpm, dt_s) : 0.0;
        }
        last_counts_[i] = r.position_counts;
        last_fresh_cycle_[i] = cycle_;
        last_fresh_ns_[i] = sync_ns_;
        have_last_[i] = true;
      }
    }
    ProbeSeq& p = probe_[i];
    if (p.mapped && r.touch_probe_fresh) {
      const std::uint16_t st = r.touch_probe_status;
      constexpr std::uint16_t kLatch = co::kTouchProbe1Enabled | co::kTouchProbe1PositiveStored;
      if (p.step == ProbeStep::kOff) {
        p.off_seen = (st & co::kTouchProbe1Enabled) == 0;
      } else if (p.step == ProbeStep::kArmed && (st & kLatch) == kLatch) {
        // The unwrapped position plus the 32-bit difference of the two raw registers: the same
        // unwrapping as position_mm (valid within 2^31 counts of this cycle's 0x6064).
        const auto diff = static_cast<std::int32_t>(
            static_cast<std::uint32_t>(r.touch_probe_position_raw) - static_cast<std::uint32_t>(r.position_raw));
        p.latched_counts = r.position_counts + diff;
        p.step = ProbeStep::kLatched;
      }
    }
    f.index_present = p.mapped;
    f.index_latched = p.step == ProbeStep::kLatched;
    f.index_position_mm = f.index_latched ? co::counts_to_mm(p.latched_counts, cpm) : 0.0;
    f.digital_inputs_present = master_->setup(i).digital_inputs;
    f.digital_inputs_fresh = f.digital_inputs_present && r.digital_inputs_fresh;
    f.digital_inputs = r.digital_inputs;
    f.statusword = r.statusword;
    f.node_id = master_->setup(i).node_id;
    f.emcy_code = r.emcy_code;
    f.nmt_lost = r.nmt_lost;
    f.enabled = r.state == co::Cia402State::kOperationEnabled;
    const HomeSeq& q = home_[i];
    f.drive_homing_present = q.configured;
    f.drive_homing_detail = q.detail;
    switch (q.step) {
      case HomeStep::kIdle: f.drive_homing = DriveHoming::kIdle; break;
      case HomeStep::kAttained: f.drive_homing = DriveHoming::kAttained; break;
      case HomeStep::kError: f.drive_homing = DriveHoming::kError; break;
      case HomeStep::kUnsupported: f.drive_homing = DriveHoming::kUnsupported; break;
      default: f.drive_homing = DriveHoming::kRunning; break;
    }
    // The drive's own fault state (a reboot behind our back is nmt_lost: the supervisor names it
    // as an NMT change, and a reset needs the node operational again).
    f.fault = r.state == co::Cia402State::kFault ||
              r.state == co::Cia402State::kFaultReactionActive ||
              (r.faults & static_cast<std::uint8_t>(co::NodeFault::kDriveFault)) != 0;
  }
  fb.io_modules = io_count_;
  for (int k = 0; k < io_count_; ++k) {
    const auto i = static_cast<std::size_t>(io_index_[static_cast<std::size_t>(k)]);
    const co::NodeRuntime& r = master_->node(i);
    IoModuleFeedback& m = fb.io[static_cast<std::size_t>(k)];
    m.node_id = master_->setup(i).node_id;
    m.fresh = r.tpdo_fresh;
    m.missed_streak = r.missed_streak;
    m.emcy_code = r.emcy_code;
    m.nmt_lost = r.nmt_lost;
    m.digital = r.io_digital_in;
    m.analog = r.io_analog_in;
  }
  if (spindle_index_ >= 0) {
    const co::NodeRuntime& r = master_->node(static_cast<std::size_t>(spindle_index_));
    SpindleFeedback& s = fb.spindle;
    s.present = spindle_velocity_mapped_;
    s.fresh = r.tpdo_fresh;
    // 0x606C in the simulated spindle drive's unit, rpm (the same unit as the 0x60FF target).
    if (r.tpdo_fresh && spindle_velocity_mapped_) s.actual_rpm = static_cast<double>(r.velocity_counts_s);
    s.enabled = r.state == co::Cia402State::kOperationEnabled;
    s.fault = r.state == co::Cia402State::kFault || r.state == co::Cia402State::kFaultReactionActive;
  }
  const auto bs = can_->bus_state();
  // A SYNC that could not be sent at all (not a counted ENOBUFS drop), bus-off or error-passive.
  fb.bus_error =
      begin_fault_ || bs == drivers::BusState::kBusOff || bs == drivers::BusState::kErrorPassive;
  fb.emcy_count = static_cast<std::uint32_t>(master_->counters().emcy_frames);
  co::MasterEvent e;
  while (master_->pop_event(e)) events_.push(e);  // full ring: counted drop, never blocks
}

void CanopenBus::write(const AxisCommands& cmd) noexcept {
  const co::DriveRequest req = to_request(cmd.mode);
  if (cmd.mode == DriveMode::kEnabled && last_mode_ != DriveMode::kEnabled) {
    master_->reset_faults();  // fault-reset edge for drives in Fault; clears master latches
  }
  last_mode_ = cmd.mode;
  for (int i = 0; i < axes_; ++i) {
    const auto a = static_cast<std::size_t>(i);
    master_->set_request(a, req);
    if (home_[a].configured) step_drive_homing(a, cmd.drive_home[a]);
    if (csp_[a]) {
      const co::NodeRuntime& r = master_->node(a);
      if (r.state != co::Cia402State::kOperationEnabled || req != co::DriveRequest::kEnabled ||
          home_[a].step != HomeStep::kIdle) {
        csp_target_counts_[a] = static_cast<double>(r.position_counts);
      } else if (std::isfinite(cmd.velocity_mm_s[a])) {
        csp_target_counts_[a] += cmd.velocity_mm_s[a] * counts_per_mm_[a] * period_s_;
      }
      // The drive's 32-bit register wraps: send the low 32 bits of the rounded target.
      const auto t = static_cast<std::int64_t>(std::llround(csp_target_counts_[a]));
      master_->set_target(a, static_cast<std::int32_t>(static_cast<std::uint32_t>(t & 0xFFFFFFFF)));
    } else {
      master_->set_target(a, co::mm_s_to_counts_s(cmd.velocity_mm_s[a], counts_per_mm_[a]));
    }
    master_->set_digital_outputs(a, cmd.digital_outputs[a] & cmd.digital_output_mask[a]);
    if (ProbeSeq& p = probe_[a]; p.mapped) {
      if (!cmd.index_arm[a]) {
        if (p.step != ProbeStep::kOff) p.off_seen = false;  // wait for the drive to show the 0
        p.step = ProbeStep::kOff;
      } else if (p.step == ProbeStep::kOff && p.off_seen) {
        p.step = ProbeStep::kArmed;  // 0 -> 0x0015 at the drive: the edge that arms it
      }
      master_->set_touch_probe_function(a, p.step == ProbeStep::kOff ? 0 : co::kTouchProbe1ArmIndex);
    }
  }
  if (spindle_index_ >= 0) {
    const auto s = static_cast<std::size_t>(spindle_index_);
    const double rpm = std::isfinite(cmd.spindle_rpm) ? cmd.spindle_rpm : 0.0;
    master_->set_request(s, cmd.mode == DriveMode::kQuickStop ? co::DriveRequest::kQuickStop
                            : cmd.mode == DriveMode::kEnabled ? co::DriveRequest::kEnabled
                                                              : co::DriveRequest::kDisabled);
    master_->set_target(s, co::mm_s_to_counts_s(rpm, 1.0));  // rounds and saturates
  }
  for (const IoModuleCommands& o : cmd.io) {
    if (o.node_id <= 0 || o.node_id > 127) continue;
    const int i = master_->index_of(static_cast<std::uint8_t>(o.node_id));
    if (i < 0 || master_->setup(static_cast<std::size_t>(i)).kind != co::NodeKind::kIoModule)
      continue;
    master_->set_io_outputs(static_cast<std::size_t>(i), o.digital, o.analog);
  }
  master_->send_rpdos();
}

// One cycle of the axis' homing by its drive (RT: no allocation, no blocking; one SDO frame at
// most). The set-up and the way back to the cyclic mode are SDO transfers of the master's
// non-blocking client; the start and the result go through the PDOs.
void CanopenBus::step_drive_homing(std::size_t a, bool request) noexcept {
  HomeSeq& q = home_[a];
  const co::AsyncSdo& sdo = master_->sdo_async(a);
  const co::NodeRuntime& r = master_->node(a);
  // The object of the current SDO step: sends it once, then judges the answer. Returns true when
  // it is done (and matches, for a read-back); false while in flight. A refusal or a time-out
  // ends the sequence.
  auto sdo_step = [&](const HomeObject& o, bool& failed, bool& refused) {
    failed = refused = false;
    if (!q.sent) {
      if (sdo.state == co::AsyncSdo::State::kBusy) return false;  // (an earlier transfer)
      q.sent = o.bytes == 0 ? master_->sdo_async_upload(a, o.index, o.sub)
                            : master_->sdo_async_download(a, o.index, o.sub, o.value, o.bytes);
      return false;
    }
    switch (sdo.state) {
      case co::AsyncSdo::State::kBusy:
      case co::AsyncSdo::State::kIdle: return false;
      case co::AsyncSdo::State::kDone:
        master_->sdo_async_clear(a);
        q.sent = false;
        if (o.bytes == 0 && static_cast<std::int8_t>(sdo.value & 0xFFu) != static_cast<std::int8_t>(o.value)) {
          refused = true;  // the mode was not taken
          q.detail = static_cast<std::uint32_t>(o.index) << 8 | o.sub;
        }
        return !refused;
      case co::AsyncSdo::State::kAborted:
        refused = true;
        q.detail = static_cast<std::uint32_t>(o.index) << 8 | o.sub;
        break;
      case co::AsyncSdo::State::kTimedOut:
        failed = true;
        q.detail = static_cast<std::uint32_t>(o.index) << 8 | o.sub;
        break;
    }
    master_->sdo_async_clear(a);
    q.sent = false;
    return false;
  };
  auto leave_mode6 = [&](HomeStep then) {
    master_->set_controlword_extra(a, 0);
    if (q.mode6) {
      q.step = HomeStep::kModeBack;
      q.result = then;
      q.k = 0;
    } else {
      q.step = then;
    }
  };
  bool failed = false, refused = false;
  if (!request && q.step != HomeStep::kIdle && q.step != HomeStep::kModeBack) {
    // The request dropped: back to the cyclic mode (if it was left), then idle.
    if (q.sent && sdo.state == co::AsyncSdo::State::kBusy) return;  // let the transfer end
    if (q.sent) {
      master_->sdo_async_clear(a);
      q.sent = false;
    }
    leave_mode6(HomeStep::kIdle);
    if (q.step == HomeStep::kIdle) q.detail = 0;
    return;
  }
  switch (q.step) {
    case HomeStep::kIdle:
      if (!request) return;
      {
        HomeSeq fresh;  // a new run: everything but the configuration starts afresh
        fresh.configured = q.configured;
        fresh.setup = q.setup;
        fresh.back = q.back;
        q = fresh;
      }
      q.step = HomeStep::kSetup;
      [[fallthrough]];
    case HomeStep::kSetup:
      if (sdo_step(q.setup[q.k], failed, refused)) {
        if (q.setup[q.k].index == 0x6060) {
          q.mode6 = true;
          master_->set_rpdo_mode(a, 6);
        }
        if (++q.k == q.setup.size()) {
          // Mode 6 confirmed: the rising edge of bit 4 starts the homing. The statusword is
          // judged from the third TPDO on: the RPDO sent now acts at the next SYNC and a drive
          // sampling at SYNC reports it one SYNC later.
          master_->set_controlword_extra(a, 0x0010);
          q.step = HomeStep::kStartEdge;
          q.wait = 3;
        }
      } else if (refused) {
        leave_mode6(HomeStep::kUnsupported);
      } else if (failed) {
        leave_mode6(HomeStep::kError);
      }
      break;
    case HomeStep::kStartEdge:
      if (--q.wait <= 0) q.step = HomeStep::kRunning;
      break;
    case HomeStep::kRunning:
      if (!r.tpdo_fresh) break;
      if ((r.statusword & 0x2000u) != 0 || r.state != co::Cia402State::kOperationEnabled) {
        q.detail = r.statusword;
        leave_mode6(HomeStep::kError);
      } else if ((r.statusword & 0x1400u) == 0x1400u) {
        leave_mode6(HomeStep::kAttained);
      }
      break;
    case HomeStep::kModeBack:
      if (sdo_step(q.back[q.k], failed, refused)) {
        if (q.back[q.k].index == 0x6060) master_->set_rpdo_mode(a, 0);
        if (++q.k == q.back.size()) {
          q.mode6 = false;
          q.step = request ? q.result : HomeStep::kIdle;
        }
      } else if (refused || failed) {
        // The drive stays in homing mode: it will not follow the velocity target. Error.
        master_->set_rpdo_mode(a, 0);
        q.mode6 = false;
        q.step = request ? HomeStep::kError : HomeStep::kIdle;
      }
      break;
    case HomeStep::kAttained:
    case HomeStep::kError:
    case HomeStep::kUnsupported:
      break;
  }
}

bool CanopenBus::set_position(int /*axis*/, double /*position_mm*/) { return false; }

std::string CanopenBus::describe() const {
  std::string s = "CANopen over SocketCAN " + ifname_ + ", axes on nodes";
  for (std::size_t i = 0; i < mcfg_.nodes.size(); ++i) {
    const auto& n = mcfg_.nodes[i];
    if (static_cast<int>(i) == spindle_index_ || n.kind == co::NodeKind::kIoModule) continue;
    s += " " + std::to_string(n.node_id) + "(" + n.name;
    // Only a profile other than the default is worth a word here (the start-up log has all).
    if (n.quirks.profile != "generic") s += ", drive profile " + n.quirks.profile;
    s += ")";
  }
  if (spindle_index_ >= 0) {
    s += ", spindle node " +
         std::to_string(mcfg_.nodes[static_cast<std::size_t>(spindle_index_)].node_id);
  }
  if (io_count_ > 0) {
    s += ", CiA 401 I/O modules on nodes";
    for (int k = 0; k < io_count_; ++k)
      s += " " + std::to_string(
                     mcfg_.nodes[static_cast<std::size_t>(io_index_[static_cast<std::size_t>(k)])]
                         .node_id);
  }
  if (lockstep_) s += ", lockstep (simulated drives)";
  return s;
}

std::size_t CanopenBus::drain_events(const Log& sink) {
  std::lock_guard<std::mutex> g(drain_mutex_);
  std::size_t n = 0;
  co::MasterEvent e;
  while (events_.pop(e)) {
    ++n;
    if (sink && master_) sink("CANopen: " + master_->describe(e));
  }
  if (const auto d = events_.dropped(); d != 0 && n != 0 && sink) {
    sink("CANopen: " + std::to_string(d) + " bus events dropped so far (event ring full)");
  }
  return n;
}

}  // namespace contour::daemon
