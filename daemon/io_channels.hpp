#pragma once
// The daemon's machine I/O outside the axis bus (issue 8): the dynamometer (Modbus poll thread +
// ForceFilter, drivers/modbus) and the GPIO safety/enable lines (MachineIo + EstopMonitor,
// drivers/gpio), built from the `dynamometer:` and `gpio:` config sections and started/stopped
// by the daemon.
//
// RT side: ServoLoop sees only RtIo, a small interface of wait-free reads (the latest filtered
// force sample with its timestamp/validity, and the latched E-stop flag), so that unit tests can
// hand the loop a fake. No call in RtIo allocates, locks, logs or touches libmodbus/libgpiod.
//
// Non-RT side: a supervisor thread (start()) applies the loop's requested outputs to the GPIO
// lines every `period` (drive enable, spindle enable, coolant mist/flood: libgpiod calls are
// ioctls, never made from the RT thread) and toggles the optional daemon-alive line while the
// loop's cycle counter advances (a stuck loop stops the toggling; an external watchdog relay
// can drop the machine). With `gpio.backend: sim` the daemon owns a SimGpio that tests and users
// drive through the `sim_gpio` socket command.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "config/config.hpp"
#include "drivers/gpio/machine_io.hpp"
#include "drivers/gpio/sim_gpio.hpp"
#include "drivers/modbus/dynamometer_reader.hpp"
#include "drivers/modbus/vfd_spindle.hpp"
#include "drivers/spindle.hpp"

namespace contour::daemon {

// What the RT loop reads. Implementations: IoChannels (below), test fakes.
class RtIo {
 public:
  virtual ~RtIo() = default;
  // True when a force source exists (force control possible). Constant after construction.
  [[nodiscard]] virtual bool has_force() const noexcept = 0;
  // Latest force sample (state kOk/kNoData/kStale/kInvalid, filtered channels, age). Wait-free,
  // no allocation; budget < 1 us. Single consumer (the RT thread).
  virtual drivers::modbus::ForceReading read_force() noexcept = 0;
  // E-stop input latch (debounced by a non-RT thread). One atomic load.
  [[nodiscard]] virtual bool estop_tripped() const noexcept = 0;
  // Spindle speed for the force filter's tooth period (wait-free atomic store).
  virtual void set_spindle_rpm(double rpm) noexcept = 0;
  // A spindle outside the axis bus (spindle.type modbus_vfd): the loop's rate-limited signed
  // command (atomic store) and its status (atomic loads). Default: none.
  [[nodiscard]] virtual bool has_spindle() const noexcept { return false; }
  virtual void command_spindle(double /*rpm*/) noexcept {}
  [[nodiscard]] virtual drivers::SpindleStatus spindle_status() const noexcept { return {}; }
};

// Outputs requested by the loop (read from its published status by the supervisor thread).
struct IoOutputs {
  bool drive_enable = false;
  bool spindle_enable = false;
  bool mist = false;
  bool flood = false;
  std::uint64_t loop_cycle = 0;  // alive output toggles only while this advances
};

class IoChannels final : public RtIo {
 public:
  // Builds the reader and the GPIO lines from the config (throws std::invalid_argument /
  // drivers::gpio::GpioError naming the line or setting). Connects nothing yet.
  IoChannels(const config::Config& cfg, std::function<void(const std::string&)> log = {});
  ~IoChannels() override;
  IoChannels(const IoChannels&) = delete;
  IoChannels& operator=(const IoChannels&) = delete;

  // Starts the dynamometer poll thread, the E-stop monitor and the supervisor thread, which calls
  // `outputs` every `period` and applies the result to the lines.
  void start(std::function<IoOutputs()> outputs,
             std::chrono::milliseconds period = std::chrono::milliseconds(2));
  void stop();

  // RtIo.
  [[nodiscard]] bool has_force() const noexcept override { return reader_ != nullptr; }
  drivers::modbus::ForceReading read_force() noexcept override;
  [[nodiscard]] bool estop_tripped() const noexcept override;
  void set_spindle_rpm(double rpm) noexcept override;
  [[nodiscard]] bool has_spindle() const noexcept override { return vfd_ != nullptr; }
  void command_spindle(double rpm) noexcept override;
  [[nodiscard]] drivers::SpindleStatus spindle_status() const noexcept override;

  // Non-RT.
  [[nodiscard]] bool has_gpio() const noexcept { return io_ != nullptr; }
  [[nodiscard]] bool has_estop_input() const noexcept { return io_ != nullptr; }
  // Clears the E-stop latch; false (latch kept) while the input is still asserted.
  bool reset_estop();
  [[nodiscard]] bool estop_asserted() const;
  [[nodiscard]] std::optional<drivers::modbus::DynamometerStatus> dynamometer_status() const;
  [[nodiscard]] std::optional<drivers::gpio::MachineIoState> gpio_state() const;
  [[nodiscard]] std::uint64_t alive_toggles() const noexcept { return alive_toggles_.load(); }
  // The simulated backend (gpio.backend: sim), else null.
  [[nodiscard]] drivers::gpio::SimGpio* sim_gpio() const noexcept { return sim_.get(); }
  // Sim key of a role ("estop", "drive_enable", "spindle_enable", "coolant_mist",
  // "coolant_flood", "alive") or of a configured line name; empty if unknown.
  [[nodiscard]] std::string sim_key(const std::string& line) const;
  // Applies outputs now (the supervisor's body; also for tests without the thread).
  void apply_outputs(const IoOutputs& o);

 private:
  void supervise(std::function<IoOutputs()> outputs, std::chrono::milliseconds period);

  config::Config cfg_;
  std::function<void(const std::string&)> log_;
  std::unique_ptr<drivers::modbus::DynamometerReader> reader_;
  std::unique_ptr<drivers::modbus::VfdSpindle> vfd_;  // spindle.type modbus_vfd
  std::shared_ptr<drivers::gpio::SimGpio> sim_;
  std::unique_ptr<drivers::gpio::GpioBackend> gpiod_;
  std::unique_ptr<drivers::gpio::MachineIo> io_;
  mutable std::mutex io_mu_;  // MachineIo setters (supervisor) vs state()/reset (commands)
  std::thread thread_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  bool started_ = false;
  std::uint64_t last_cycle_ = 0;
  std::atomic<std::uint64_t> alive_toggles_{0};
};

}  // namespace contour::daemon
