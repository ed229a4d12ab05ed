#pragma once
// The soft PLC engine (issue 20): the I/O image, its sources and sinks, and the scheduled
// Structured Text programs (compiled at config load, config/plc_config.hpp), scanned once per
// servo cycle in the loop's `logic` stage (daemon/servo_loop.hpp):
//
//   scan(in, out):
//     1. inputs, one consistent snapshot: forces queued by non-RT threads; the Modbus couplers'
//        and the GPIO thread's latest records (triple buffers; a coupler older than its stale_ms
//        latches a fault and its inputs take their defaults); CiA 402 0x60FD and CiA 401 inputs
//        from `in`; the simulated plant (sim bus) stepped one cycle; NC status; forced values
//     2. the programs due this cycle (cycle % period_cycles == offset_cycles), in plc.programs
//        order, each over the same image
//     3. outputs, once: forced values; couplers, GPIO, CiA 402 0x60FE, CiA 401 and the plant;
//        the NC requests and handshakes into `out`
//
// Safety is in the shape of this API: the only thing the PLC hands the NC is PlcRequests (hold,
// inhibit start, stop, E-stop, spindle inhibit, fault) and the M-code/tool-change "done"
// handshakes. There is no field to enable a drive, clear a fault or release an E-stop, and the
// NC-owned lines (drive_enable, spindle_enable, alive, the E-stop input) are read-only symbols
// the compiler refuses to assign. What the NC does with a request is the state machine's and
// the safety supervisor's business; a latched request is released only by the operator's reset,
// and only once the PLC no longer requests it (causes_gone()).
//
// Real-time contract: scan() and the handshake calls are noexcept, allocate nothing, take no
// lock, make no system call but clock_gettime (scan timing), log nothing. Budget: the shipped
// example scans in ~1-2 us (bench_plc; daemon/PLC.md has the figures). Everything else
// (construction, start/stop, force, snapshot) is non-RT: construction allocates every buffer and
// throws config::ConfigError (exit 78) for bindings that do not fit this machine.
#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "config/config.hpp"
#include "control/plc_compiler.hpp"
#include "control/plc_vm.hpp"
#include "daemon/axis_bus.hpp"
#include "daemon/machine_state.hpp"
#include "daemon/plc_gpio.hpp"
#include "daemon/plc_sim.hpp"
#include "daemon/spsc_ring.hpp"
#include "drivers/gpio/gpio.hpp"
#include "drivers/gpio/gpiod_backend.hpp"
#include "drivers/gpio/sim_gpio.hpp"
#include "drivers/modbus/io_coupler.hpp"

namespace contour::daemon {

inline constexpr std::size_t kMaxCia401Nodes = kMaxIoModules;
inline constexpr int kCia401Subs = static_cast<int>(kIoModuleChannels);  // sub-indices 1..8

// One CiA 401 module's process data as the CANopen master maps it (its TPDOs -> inputs,
// outputs -> its RPDOs): drivers/canopen maps the sub-indices of 0x6000/0x6401 (inputs) and
// 0x6200/0x6411 (outputs) the PLC's signals use (daemon/canopen_master_config.hpp
// add_io_modules); ServoLoop copies BusFeedback::io in and AxisCommands::io out.
struct Cia401Inputs {
  std::uint8_t node_id = 0;
  bool valid = false;  // a TPDO arrived recently (else the PLC uses the signals' defaults)
  std::array<std::uint8_t, kCia401Subs> digital{};  // 0x6000:01..08
  std::array<std::int16_t, kCia401Subs> analog{};   // 0x6401:01..08
};
struct Cia401Outputs {
  std::uint8_t node_id = 0;
  std::array<std::uint8_t, kCia401Subs> digital{};  // 0x6200:01..08
  std::array<std::int16_t, kCia401Subs> analog{};   // 0x6411:01..08
};

// What the loop hands the PLC each cycle (its `read` stage and the NC's state).
struct PlcNcInput {
  std::uint64_t cycle = 0;  // the PLC's time base: cycle * servo period
  MachineState state = MachineState::kDisabled;
  bool program_running = false;
  bool spindle_on = false;
  bool spindle_at_speed = false;
  double spindle_rpm = 0.0;
  bool coolant_mist = false;   // the program's M7 / M8 / M9 state
  bool coolant_flood = false;
  int axes = 0;
  std::array<bool, kMaxAxes> homed{};
  std::array<double, kMaxAxes> pos_mm{};
  std::int32_t tool = 0;       // tool in the spindle
  // Fixed roles mirrored into the image (read-only for the PLC).
  bool estop_input = false;
  bool drive_enable = false;
  bool spindle_enable = false;
  bool alive = false;
  // CiA 402 digital inputs 0x60FD per axis (mapped by the master into the TPDO).
  std::array<std::uint32_t, kMaxAxes> drive_inputs{};
  std::array<bool, kMaxAxes> drive_inputs_valid{};
  std::span<const Cia401Inputs> cia401{};
};

// The PLC's requests to the NC. Requests only: nothing here can enable, reset or release.
struct PlcRequests {
  bool feed_hold = false;        // NC.feed_hold_req: hold; refuse resume while TRUE
  bool inhibit_start = false;    // NC.inhibit_start: refuse run / resume / MDI / jog
  bool stop = false;             // NC.stop_req rose this cycle: controlled stop
  bool estop = false;            // NC.estop_req (level): ESTOP, reset refused while TRUE
  bool spindle_inhibit = false;  // NC.spindle_inhibit: spindle speed 0
  bool fault = false;            // NC.fault_req (level): FAULT "PLC fault <code>"
  std::int32_t fault_code = 0;
  std::array<bool, kMaxAxes> axis_fault{};  // NC.axis_fault_<axis> (level): FAULT on the axis
};

// Faults the engine itself detects (latched until reset() finds the cause gone).
enum class PlcFaultKind : std::uint8_t {
  kNone,
  kIoStale,            // index: coupler; value: age s; limit: stale s
  kMcodeTimeout,       // code: M number; limit: timeout s
  kToolChangeTimeout,  // code: tool; limit: timeout s
  kRuntimeError,       // index: program; code: source line; value: RunStatus
};
[[nodiscard]] const char* to_string(PlcFaultKind k) noexcept;
struct PlcFault {
  PlcFaultKind kind = PlcFaultKind::kNone;
  int index = -1;
  std::int32_t code = 0;
  double value = 0.0;
  double limit = 0.0;
  explicit operator bool() const noexcept { return kind != PlcFaultKind::kNone; }
};

struct PlcCycleOutput {
  PlcRequests requests{};
  PlcFault fault{};  // a fault the engine latched THIS cycle (kNone otherwise)
  // CiA 402 digital outputs 0x60FE:01: the bits the PLC drives (mask) and their values.
  std::array<std::uint32_t, kMaxAxes> drive_outputs{};
  std::array<std::uint32_t, kMaxAxes> drive_output_mask{};
  std::array<Cia401Outputs, kMaxCia401Nodes> cia401{};
  std::size_t cia401_count = 0;
  // The coolant lines (gpio roles): the NC's M7/M8/M9 unless a program owns them.
  bool coolant_mist = false;
  bool coolant_flood = false;
};

// M-code / tool-change handshake, as the NC sees it.
enum class Handshake : std::uint8_t {
  kIdle,
  kPending,   // started; waiting for the PLC's previous "done" to fall before raising the request
  kWaiting,   // request up, waiting for done
  kDone,      // done seen: the NC may continue (then acknowledge)
  kTimedOut,  // no done within the timeout: a fault was latched (then acknowledge)
};
[[nodiscard]] const char* to_string(Handshake h) noexcept;

// Scan timing of a program (or of the whole scan).
struct PlcScanStats {
  std::uint64_t runs = 0;
  std::uint64_t overruns = 0;  // scans longer than plc.scan_budget_us
  std::uint32_t last_ns = 0, min_ns = 0, max_ns = 0;
  std::uint64_t instructions_last = 0, instructions_max = 0;
  static constexpr std::size_t kRecent = 256;
  std::array<std::uint32_t, kRecent> recent_ns{};  // ring of the last scans (median)
  std::uint8_t state = 0;  // programs: 0 running, 1 stopped by a runtime error
  std::int32_t error_line = 0;
  std::uint8_t error_status = 0;  // control::plc::RunStatus
};

// Non-RT view for `contourctl io` / `plc status` (daemon/plc_status.hpp renders it as JSON).
struct PlcSignalView {
  std::string name;
  control::plc::Type type = control::plc::Type::kBool;
  std::string direction;  // input | output | memory | nc_status | nc_request | nc_owned
  std::string source;     // "gpio DOOR", "modbus plant di 3", "sim door_closed", "NC", ...
  std::string description;
  control::plc::Cell value{};
  bool forced = false;
  bool forceable = false;
};
struct PlcProgramView {
  std::string name, file;
  int period_cycles = 1;
  std::uint64_t worst_case = 0;
  PlcScanStats stats{};
  double median_us = 0.0;
};
struct PlcDeviceView {
  std::string name, endpoint;
  std::string state;  // ok | stale | no_data
  double age_s = 0.0;
  drivers::modbus::CouplerStatus status{};
};
struct PlcSnapshot {
  std::uint64_t cycle = 0;
  bool forcing_allowed = false;
  std::vector<PlcSignalView> signals;
  std::vector<PlcProgramView> programs;
  PlcScanStats scan{};
  double scan_median_us = 0.0;
  std::vector<PlcDeviceView> devices;
  Handshake mcode = Handshake::kIdle;
  int mcode_number = 0;
  Handshake tool_change = Handshake::kIdle;
  std::int32_t tool_number = 0;
  std::vector<PlcFault> faults;  // latched now
};

class PlcEngine {
 public:
  // cfg.plc must be present and compiled. `gpio`: the backend for signals bound to gpio: (the
  // daemon's; null: a libgpiod backend of its own, or a SimGpio with gpio.backend: sim). Throws
  // config::ConfigError naming the signal (a CiA 402 axis this machine lacks, `sim:` without the
  // sim bus, too many CiA 401 nodes or sub-indices) or drivers::gpio::GpioError.
  PlcEngine(const config::Config& cfg, drivers::gpio::GpioBackend* gpio = nullptr,
            std::function<void(const std::string&)> log = {});
  ~PlcEngine();
  PlcEngine(const PlcEngine&) = delete;
  PlcEngine& operator=(const PlcEngine&) = delete;

  void start();  // coupler poll threads, GPIO thread
  void stop();   // outputs to their defaults, threads joined

  // ---- RT (the loop's thread) ----
  void scan(const PlcNcInput& in, PlcCycleOutput& out) noexcept;
  [[nodiscard]] bool handles_mcode(int m) const noexcept;
  [[nodiscard]] bool handles_tool_change() const noexcept { return tool_change_enabled_; }
  // Start a handshake (false: not a PLC M-code, or one is already running). p, q: NaN = absent.
  bool start_mcode(int m, double p, double q) noexcept;
  bool start_tool_change(std::int32_t tool) noexcept;
  [[nodiscard]] Handshake mcode_state() const noexcept { return mcode_.phase; }
  [[nodiscard]] Handshake tool_change_state() const noexcept { return tool_.phase; }
  // After kDone / kTimedOut (or to abandon a running one: program stopped): back to idle, the
  // request drops at the next scan.
  void release_mcode() noexcept;
  void release_tool_change() noexcept;
  // The reset rule's PLC part: no request is up (estop, fault, axis faults) and no latched
  // engine fault's cause remains (couplers fresh again).
  [[nodiscard]] bool causes_gone() const noexcept;
  // The operator's accepted reset: clears latched engine faults whose cause is gone, restarts
  // programs stopped by a runtime error from their initial values.
  void reset() noexcept;

  // The image value at `slot` now (find()); the RT thread's view: for the thread that scans
  // (tests driving scan() themselves), not for other threads (they use snapshot()).
  [[nodiscard]] control::plc::Cell peek(int slot) const noexcept {
    return mem_[static_cast<std::size_t>(slot)];
  }

  // ---- non-RT ----
  [[nodiscard]] bool forcing_allowed() const noexcept { return forcing_allowed_; }
  // Forces a user signal (plc.signals) to `value` ("TRUE", "0", "12.5", "T#2s"); empty string
  // on success, else the reason (unknown signal, not forceable, forcing not allowed, bad value).
  // Applied at the start of the next scan, shown as forced in the snapshot.
  std::string force(const std::string& name, const std::string& value);
  std::string unforce(const std::string& name);  // name "*" or "all": every signal
  [[nodiscard]] PlcSnapshot snapshot() const;
  [[nodiscard]] PlcSimPlant* sim_plant() noexcept { return sim_.get(); }
  [[nodiscard]] drivers::gpio::SimGpio* sim_gpio() noexcept { return own_sim_gpio_.get(); }
  [[nodiscard]] std::size_t image_size() const noexcept { return entries_.size(); }
  // Index of a name in the image (any case), or -1.
  [[nodiscard]] int find(const std::string& name) const;

 private:
  struct InputBinding;
  struct OutputBinding;
  struct Program {
    std::shared_ptr<const control::plc::CompiledProgram> compiled;
    std::vector<control::plc::Instr> code;
    std::int32_t base = 0;
    int period = 1, offset = 0;
    bool stopped = false;
    std::vector<std::int32_t> written;  // image slots it writes (reset to defaults on error)
  };
  struct HandshakeState {
    Handshake phase = Handshake::kIdle;
    std::uint64_t started_cycle = 0;
    std::uint64_t timeout_cycles = 0;
    int number = 0;  // M number / tool
    double p = 0.0, q = 0.0;
    bool req = false;
  };
  struct ForceCommand {
    std::int32_t slot = -1;  // -1: every signal
    bool on = false;
    control::plc::Cell value{};
  };
  struct Published;  // snapshot slot

  void read_inputs(const PlcNcInput& in, std::int64_t wall_ns, PlcCycleOutput& out) noexcept;
  void run_programs(std::uint64_t cycle) noexcept;
  void write_outputs(const PlcNcInput& in, PlcCycleOutput& out) noexcept;
  void apply_forces() noexcept;
  void handshakes(std::uint64_t cycle, PlcCycleOutput& out) noexcept;
  void latch(const PlcFault& f, PlcCycleOutput& out) noexcept;
  void publish() noexcept;
  static void record(PlcScanStats& s, std::uint32_t ns, std::uint64_t instr, double budget_ns) noexcept;
  control::plc::Cell& at(std::int32_t slot) noexcept { return mem_[static_cast<std::size_t>(slot)]; }
  [[nodiscard]] bool slot_bool(std::int32_t slot) const noexcept {
    return slot >= 0 && mem_[static_cast<std::size_t>(slot)].i != 0;
  }

  config::Config cfg_;
  std::shared_ptr<const config::PlcCompiled> compiled_;
  std::function<void(const std::string&)> log_;
  const std::vector<config::PlcImageEntry>& entries_;
  std::int64_t period_ns_ = 1000000;
  double scan_budget_ns_ = 50000.0;
  bool forcing_allowed_ = false;
  bool tool_change_enabled_ = false;
  double tool_change_timeout_s_ = 60.0;
  std::array<double, 200> mcode_timeout_s_{};  // 0: not a PLC M-code (index = M number)

  // Memory: image then each program's locals; the initial values for a restart.
  std::vector<control::plc::Cell> mem_, init_;
  std::vector<control::plc::Cell> stack_;
  std::vector<Program> programs_;
  std::vector<InputBinding> inputs_;
  std::vector<OutputBinding> outputs_;
  std::vector<std::int32_t> user_slots_;    // every plc.signals entry (forceable)
  std::vector<std::uint8_t> forced_;        // per slot
  std::vector<control::plc::Cell> forced_value_;
  std::size_t forced_count_ = 0;

  // Slots of the NC fields / fixed roles (-1 when absent).
  std::array<std::int32_t, config::kNcFields> nc_{};
  std::array<std::array<std::int32_t, kMaxAxes>, 3> nc_axis_{};  // pos, homed, axis_fault
  std::array<std::int32_t, config::kFixedRoles> fixed_{};
  bool coolant_mist_owned_ = false, coolant_flood_owned_ = false;
  bool stop_req_prev_ = false;

  // Field I/O.
  struct Coupler {
    std::unique_ptr<drivers::modbus::IoCoupler> dev;
    drivers::modbus::CouplerInputs in{};
    drivers::modbus::CouplerOutputs out{};
    drivers::modbus::CouplerReading reading{};
    std::int64_t stale_ns = 0;
    std::int64_t started_ns = 0;
    bool ok = false;          // inputs usable this cycle
    bool fault_latched = false;
  };
  std::vector<Coupler> couplers_;
  std::unique_ptr<drivers::gpio::GpiodBackend> own_gpiod_;
  std::shared_ptr<drivers::gpio::SimGpio> own_sim_gpio_;
  std::unique_ptr<PlcGpio> gpio_;
  GpioBits gpio_in_{}, gpio_out_{};
  std::unique_ptr<PlcSimPlant> sim_;
  std::array<std::uint8_t, kMaxCia401Nodes> cia401_nodes_{};
  std::size_t cia401_count_ = 0;
  std::array<const Cia401Inputs*, kMaxCia401Nodes> cia401_in_{};

  // Handshakes and latched faults (RT-owned).
  HandshakeState mcode_, tool_;
  std::vector<PlcFault> latched_;  // capacity reserved; RT pushes within it
  std::size_t latched_count_ = 0;
  PlcFault pending_runtime_error_{};

  // Stats (RT-owned, published).
  std::vector<PlcScanStats> stats_;
  PlcScanStats scan_stats_{};
  std::uint64_t cycle_ = 0;
  bool started_ = false;

  // Non-RT -> RT: forces (producers serialised by a mutex).
  SpscRing<ForceCommand> force_ring_{64};
  std::mutex force_mu_;
  // RT -> non-RT: snapshot triple buffer over pre-sized slots.
  std::unique_ptr<Published[]> pub_;
  mutable std::atomic<std::uint8_t> pub_middle_{1};
  std::uint8_t pub_back_ = 2;
  mutable std::uint8_t pub_front_ = 0;
  mutable std::mutex snapshot_mu_;  // non-RT readers of the front slot
};

}  // namespace contour::daemon
