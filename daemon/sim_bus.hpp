#pragma once
// In-process simulated machine: the same FeedDrive plant as contour-sim and contour-machine-sim,
// advancing exactly one step per begin_cycle() (lockstep), so a daemon run gives contour-sim's
// figures however late its cycles wake. The command written in cycle k is latched at SYNC k+1 and
// acts from there (CANopen synchronous RPDO semantics), on top of the drive's own configured
// transport delay (machine.axes[].sim.delay_cycles counts the total delay, as in contour-sim).
#include <array>
#include <atomic>
#include <memory>
#include <vector>

#include "config/config.hpp"
#include "control/feed_drive.hpp"
#include "daemon/axis_bus.hpp"

namespace contour::daemon {

class SimBus final : public AxisBus {
 public:
  // can_counts_per_mm empty: the ideal in-process bus (position quantised to the plant's BLU,
  // velocity commands as doubles). Non-empty (one per axis): model what a CANopen drive sees
  // and reports, as contour-machine-sim does over vcan, so that an offline run of a
  // `bus.type: socketcan` config gives the HIL figures exactly:
  //   - the velocity target is the RPDO's integer 0x60FF: round(v * counts_per_mm) counts/s
  //     (codec.hpp mm_s_to_counts_s), applied as counts / counts_per_mm;
  //   - the position is the TPDO's 0x6064: llround(x * counts_per_mm) counts / counts_per_mm
  //     (replaces the BLU quantisation, the drive's encoder unit being the count);
  //   - the velocity is what CanopenBus reports: 0x606C (llround(v * counts_per_mm) counts/s)
  //     when `can_velocity_mapped`, else the difference of the last two count positions over
  //     one period (codec.hpp counts_velocity_mm_s), 0 at the first reading.
  explicit SimBus(const std::vector<control::FeedDriveParams>& drives,
                  const std::vector<double>& can_counts_per_mm = {},
                  bool can_velocity_mapped = false);

  void start() override {}
  void stop() noexcept override {}
  void begin_cycle() noexcept override;
  void read(BusFeedback& fb) noexcept override;
  void write(const AxisCommands& cmd) noexcept override;
  bool set_position(int axis, double position_mm) override;
  [[nodiscard]] std::string describe() const override;

  // Fault injection for tests (thread-safe: read by the RT thread each cycle).
  void inject_drive_fault(int axis, bool on) noexcept { fault_[static_cast<std::size_t>(axis)] = on; }
  // The drive leaves operation enabled without a fault (its enable input / STO opened).
  void inject_drive_disabled(int axis, bool on) noexcept {
    disabled_[static_cast<std::size_t>(axis)] = on;
  }
  // The next `count` cycles without the axis' 0x60FD digital inputs only (a drive whose TPDO2
  // stops while its position still comes); -1: from now on, until cleared with 0.
  void inject_inputs_tpdo_drop(int axis, int count) noexcept {
    drop_input_tpdos_[static_cast<std::size_t>(axis)] = count;
  }
  // The next `count` TPDOs of an axis do not arrive (stale feedback; a streak faults the loop).
  void inject_tpdo_drop(int axis, int count) noexcept {
    drop_tpdos_[static_cast<std::size_t>(axis)] = count;
  }
  // Spindle model: first-order speed lag tau_s (0 = no spindle). Setup-time only.
  void configure_spindle(double tau_s) noexcept { spindle_tau_s_ = tau_s; }
  // The spindle is jammed / its drive does not follow (stays at its speed).
  void inject_spindle_stall(bool on) noexcept { spindle_stall_ = on; }
  void inject_spindle_fault(bool on) noexcept { spindle_fault_ = on; }
  // CiA 402 digital inputs 0x60FD (AxisFeedback::digital_inputs, present on every axis of this
  // bus): switches on the plant's true position, as a cam on the axis actuates a real switch.
  // Bit `bit` (0..31) is on while the position is above `threshold_mm` (on_above) or below it.
  // Setup-time only (before the loop runs); at most kMaxSwitches per axis (std::invalid_argument).
  static constexpr std::size_t kMaxSwitches = 4;
  void add_input_switch(int axis, int bit, double threshold_mm, bool on_above);
  // Power-up (setup-time only): the axis stands at the true position `true_mm` and its
  // incremental encoder reads 0 there (machine.axes[].sim.power_up_mm): reported positions are
  // true - true_mm from then on; the switches stay on the true position.
  void power_up_at(int axis, double true_mm);
  // The plant's true position (tests: where the machine really is, whatever homing found).
  [[nodiscard]] double true_position_mm(int axis) const noexcept {
    return drive_[static_cast<std::size_t>(axis)].position_mm();
  }
  // The same, published at each SYNC for other threads (status.sim_true_mm; relaxed atomics).
  [[nodiscard]] double published_true_position_mm(int axis) const noexcept {
    return true_pub_[static_cast<std::size_t>(axis)].load(std::memory_order_relaxed);
  }
  void clear_input_switches() noexcept;
  // Encoder index (setup-time only): one pulse per `pitch_mm` of true travel, at true positions
  // phase_mm + k * pitch_mm (a rotary encoder on the motor of a ball screw); pitch 0 = none.
  // Latched exactly (to the count with CANopen quantisation) while AxisCommands::index_arm.
  void set_encoder_index(int axis, double pitch_mm, double phase_mm);
  // Thread-safe override of input bits (tests, fault injection): bits in `mask` read as `values`.
  void inject_digital_inputs(int axis, std::uint32_t mask, std::uint32_t values) noexcept {
    di_force_mask_[static_cast<std::size_t>(axis)] = mask;
    di_force_values_[static_cast<std::size_t>(axis)] = values;
  }
  // 0x60FE:01 as the drive holds it: the last write()'s outputs & mask, latched at the next SYNC
  // (RPDO semantics). RT thread / the thread stepping the bus.
  [[nodiscard]] std::uint32_t digital_outputs(int axis) const noexcept {
    return do_latched_[static_cast<std::size_t>(axis)];
  }
  // The mode of the last write() (what the RPDOs of this cycle asked for).
  [[nodiscard]] DriveMode written_mode() const noexcept { return received_mode_; }

  // Homing by the drive (CiA 402 homing mode 6, AxisCommands::drive_home): the simulated drive
  // homes itself with `method` (0x6098; config::kDriveMethods), searching at search_mm_s
  // (0x6099:01), latching at latch_mm_s (0x6099:02), with accel_mm_s2 (0x609A) on its profile,
  // on the switches of add_input_switch (bit 0 negative limit, 1 positive limit, 2 home) and the
  // encoder index of set_encoder_index. Like a drive it samples the switch each cycle on the true
  // position; at the home point its encoder is set to read 0 there; it brakes, and reports
  // attained once it stands. Running into the limit switch of its direction of travel that is not
  // its target is a homing error (statusword bit 13). Setup-time only; every axis of a SimBus
  // can home by drive (method 0 = none configured: a request fails as a homing error).
  struct DriveHomingParams {
    int method = 0;
    double search_mm_s = 0.0;  // magnitudes
    double latch_mm_s = 0.0;
    double accel_mm_s2 = 500.0;
  };
  void configure_drive_homing(int axis, const DriveHomingParams& p);
  // A drive without homing support (tests): a request answers kUnsupported, object 0x6098:00.
  void set_drive_homing_supported(int axis, bool supported);

 private:
  int axes_ = 0;
  std::array<double, kMaxAxes> index_pitch_mm_{};
  std::array<double, kMaxAxes> index_phase_mm_{};
  std::array<bool, kMaxAxes> index_armed_{};
  std::array<bool, kMaxAxes> index_latched_{};
  std::array<double, kMaxAxes> index_at_mm_{};   // reported position at the pulse
  std::array<double, kMaxAxes> index_prev_mm_{};  // true position at the previous read
  std::array<control::FeedDrive, kMaxAxes> drive_{};
  std::array<double, kMaxAxes> latched_v_{};   // command the drives act on
  std::array<double, kMaxAxes> received_v_{};  // last command written (latched at next SYNC)
  DriveMode mode_ = DriveMode::kDisabled;
  DriveMode received_mode_ = DriveMode::kDisabled;
  std::array<std::atomic<bool>, kMaxAxes> fault_{};
  std::array<std::atomic<bool>, kMaxAxes> disabled_{};
  std::array<std::atomic<int>, kMaxAxes> drop_tpdos_{};
  std::array<std::atomic<int>, kMaxAxes> drop_input_tpdos_{};
  double spindle_tau_s_ = 0.0;
  double spindle_rpm_ = 0.0;
  double spindle_latched_rpm_ = 0.0;
  double spindle_received_rpm_ = 0.0;
  std::atomic<bool> spindle_stall_{false};
  std::atomic<bool> spindle_fault_{false};
  std::uint64_t cycle_ = 0;
  std::array<double, kMaxAxes> can_cpm_{};  // 0 = ideal bus
  std::array<double, kMaxAxes> encoder_zero_mm_{};  // true position where the encoder reads 0
  bool can_velocity_mapped_ = false;
  std::array<std::int64_t, kMaxAxes> can_last_counts_{};
  bool can_have_last_ = false;
  struct Switch {
    int bit = 0;
    double threshold_mm = 0.0;
    bool on_above = true;
  };
  std::array<std::array<Switch, kMaxSwitches>, kMaxAxes> switches_{};
  std::array<std::size_t, kMaxAxes> switch_count_{};
  std::array<std::uint32_t, kMaxAxes> di_last_{};
  std::array<std::atomic<std::uint32_t>, kMaxAxes> di_force_mask_{};
  std::array<std::atomic<std::uint32_t>, kMaxAxes> di_force_values_{};
  std::array<std::uint32_t, kMaxAxes> do_received_{};
  std::array<std::uint32_t, kMaxAxes> do_latched_{};

  // Homing by the drive (mode 6), stepped at SYNC (begin_cycle).
  enum class HomeStage : std::uint8_t {
    kIdle, kSearch, kAway, kApproach, kIndex, kBrake, kAttained, kError,
  };
  [[nodiscard]] std::uint32_t inputs_at(std::size_t a, double x_true) const noexcept;
  void step_drive_homing(std::size_t a) noexcept;
  void home_here(std::size_t a, double x_true) noexcept;  // the home point: encoder reads 0
  std::array<DriveHomingParams, kMaxAxes> home_params_{};
  std::array<bool, kMaxAxes> home_supported_{true, true, true};
  std::array<bool, kMaxAxes> home_received_{};  // AxisCommands::drive_home of the last write()
  std::array<bool, kMaxAxes> home_latched_{};   // as the drive acts on it (from the next SYNC)
  std::array<HomeStage, kMaxAxes> home_stage_{};
  std::array<HomeStage, kMaxAxes> home_after_brake_{};
  std::array<double, kMaxAxes> home_v_{};        // the drive's profile velocity, mm/s
  std::array<double, kMaxAxes> home_prev_x_{};   // true position at the previous step (index)
  std::array<bool, kMaxAxes> home_rezeroed_{};   // the encoder jumped: CAN velocity restarts
  std::array<std::atomic<double>, kMaxAxes> true_pub_{};
};

// The simulated drives' default switches (make_sim_bus and the daemon's sim bus): per axis,
// negative_limit (bit 0) below machine.axes[].min_mm - kSimLimitMargin_mm, positive_limit
// (bit 1) above max_mm + kSimLimitMargin_mm (where the sim: plant's overtravel switches sit), and
// home_switch (bit 2) below min_mm + kSimHomeBand_mm (homing towards the negative end).
inline constexpr double kSimLimitMargin_mm = 2.0;
inline constexpr double kSimHomeBand_mm = 0.5;
void add_default_input_switches(SimBus& bus, const config::Config& cfg);
// The built-in simulated machine as configured: the default switches, and each axis standing at
// machine.axes[].sim.power_up_mm with its encoder reading 0 there (homing has to find zero).
void configure_sim_machine(SimBus& bus, const config::Config& cfg);

// The drives of machine.axes with the loop period (delay_cycles as configured).
std::vector<control::FeedDriveParams> sim_bus_drives(const config::Config& cfg);
// SimBus for `cfg`: with bus.type socketcan it models the CANopen quantisation (see SimBus).
std::unique_ptr<SimBus> make_sim_bus(const config::Config& cfg);

}  // namespace contour::daemon
