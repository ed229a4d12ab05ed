#pragma once
// `plc:` section: the soft PLC (issue 20) — the I/O image's signals and their sources/sinks, the
// Structured Text programs and their scan periods, forcing rules, M-code hooks. Absent section:
// no PLC (the fixed gpio: roles work as before).
//
// plc:
//   allow_forcing: false        # force/unforce only on the sim bus or with this set
//   instruction_budget: 20000   # worst-case instructions of one program scan (load refuses more)
//   scan_budget_us: 50          # a program scan longer than this is counted as an overrun
//   gpio_poll_ms: 2             # the PLC's GPIO lines are read/written by a thread this often
//   mcode_timeout_s: 30         # default wait for NC.mcode_done
//   mcodes:                     # user M-codes M100..M199 run by the PLC (others are refused)
//     - {m: 101, timeout_s: 10}
//   tool_change: {enabled: true, timeout_s: 60}   # M6 runs the PLC's tool-change sequence
//   modbus:                     # remote I/O couplers (polled by a thread each, like the
//     - name: coupler           # dynamometer; inputs older than stale_ms fault the machine)
//       transport: tcp          # tcp | rtu (device, baud, parity, data_bits, stop_bits)
//       host: 127.0.0.1
//       port: 1502
//       unit_id: 1
//       poll_hz: 100
//       timeout_ms: 20
//       stale_ms: 200
//   programs:                   # scanned in this order, each every period_cycles servo cycles
//     - {file: plc/door.st, period_cycles: 1, offset_cycles: 0}
//   signals:                    # the I/O image; exactly one binding key, none = memory
//     - {name: door_closed, type: BOOL, gpio: {name: DOOR, active_low: true}, direction: input}
//     - {name: air_ok, modbus: {device: coupler, discrete_input: 0}}
//     - {name: lube_pump, modbus: {device: coupler, coil: 3}, default: false}
//     - {name: x_home, cia402: {axis: X, input: home_switch}}
//     - {name: clamp, cia401: {node: 5, digital_output: 1, bit: 2}}
//     - {name: carousel_pocket, type: INT, sim: carousel_pocket}
//     - {name: parts_done, type: DINT}
// Types: BOOL INT DINT REAL LREAL (TIME for memory signals). `default` is the value at start, on
// a stale source (inputs) and while the PLC is stopped (outputs).
//
// The programs are compiled at load (control/plc_compiler.hpp): an error in a .st file is a
// configuration error like any other (file:line:column, all at once, exit 78). The image layout
// (PlcCompiled::entries) is built here so that the compiled code and the engine
// (daemon/plc_engine.hpp) agree on every slot.
#include <array>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "config/yaml_reader.hpp"
#include "control/plc_compiler.hpp"
#include "control/plc_sim_plant.hpp"
#include "control/plc_types.hpp"
#include "drivers/gpio/gpio.hpp"
#include "drivers/modbus/modbus_client.hpp"

namespace contour::config {

enum class PlcDirection : std::uint8_t { kInput, kOutput, kMemory };
enum class PlcBindingKind : std::uint8_t { kMemory, kGpio, kModbus, kCia402, kCia401, kSim };
enum class ModbusTable : std::uint8_t { kCoil, kDiscreteInput, kHoldingRegister, kInputRegister };
// CiA 401 generic I/O objects: 0x6000 digital inputs (8 bits per sub-index), 0x6200 digital
// outputs, 0x6401 analog inputs (16 bit), 0x6411 analog outputs (16 bit).
enum class Cia401Object : std::uint8_t { kDigitalInput, kDigitalOutput, kAnalogInput, kAnalogOutput };
[[nodiscard]] std::uint16_t cia401_index(Cia401Object o) noexcept;

// CiA 402 digital inputs 0x60FD: bit 0 negative limit, 1 positive limit, 2 home switch,
// 3 interlock, 16..31 manufacturer-specific. Digital outputs 0x60FE:01: bits 16..31 (bit 0 is the
// drive's own brake; the PLC never drives it).
inline constexpr int kCia402NegativeLimit = 0, kCia402PositiveLimit = 1, kCia402HomeSwitch = 2,
                     kCia402Interlock = 3;

struct PlcBinding {
  PlcBindingKind kind = PlcBindingKind::kMemory;
  drivers::gpio::LineSpec line{};  // gpio
  int device = -1;                 // modbus: index into PlcConfig::modbus
  ModbusTable table = ModbusTable::kCoil;
  int address = 0;                 // modbus register/coil address; cia401 sub-index
  int bit = -1;                    // modbus register bit, cia402 / cia401 bit; -1 = whole value
  double scale = 1.0;              // registers/analog -> REAL: raw * scale
  bool is_signed = true;           // registers/analog: two's complement
  int axis = -1;                   // cia402: index into machine.axes
  std::string axis_name;
  int node_id = 0;                 // cia401
  Cia401Object object = Cia401Object::kDigitalInput;
  control::plc::PlantPoint point = control::plc::PlantPoint::kDoorClosed;  // sim
  bool invert = false;             // modbus bits: TRUE when the bit is 0
};

struct PlcSignalConfig {
  std::string name;
  control::plc::Type type = control::plc::Type::kBool;
  PlcDirection direction = PlcDirection::kMemory;
  PlcBinding binding{};
  control::plc::Cell initial{};  // `default`
  std::string description;
  std::string where;  // "file:line:column" of the entry (for errors found later)
};

struct PlcModbusDevice {
  std::string name;
  drivers::modbus::TransportSettings transport{};
  double poll_hz = 100.0;
  std::chrono::microseconds stale_after{200000};
  std::string where;
};

struct PlcProgramConfig {
  std::string file;    // as given in YAML
  std::string path;    // resolved (relative to the config file's directory)
  std::string source;  // the file's text, read at load
  int period_cycles = 1;
  int offset_cycles = 0;
};

struct PlcMcode {
  int m = 100;
  double timeout_s = 30.0;
};

// ---- The NC's side of the image (NC.* names) ---------------------------------------------------
enum class NcField : std::uint8_t {
  // status: read-only for the PLC
  kState, kReady, kProgramRunning, kFeedHold, kFault, kEstop, kSpindleOn, kSpindleAtSpeed,
  kSpindleRpm, kCoolantMist, kCoolantFlood, kHomed, kTool, kToolChangeReq, kToolNumber, kMcodeReq,
  kMcode, kMcodeP, kMcodeQ,
  // requests: written by the PLC (requests only: hold, inhibit, stop, E-stop, fault; never an
  // enable, a reset or a release)
  kFeedHoldReq, kInhibitStart, kStopReq, kEstopReq, kSpindleInhibit, kFaultReq, kFaultCode,
  kToolChangeDone, kMcodeDone,
  // per axis (NC.pos_x, NC.homed_x: status; NC.axis_fault_x: request)
  kPos, kHomedAxis, kAxisFault,
};
inline constexpr int kNcFields = static_cast<int>(NcField::kAxisFault) + 1;
struct NcFieldInfo {
  NcField field;
  const char* name;  // after "NC." (per axis: before "_<axis>")
  control::plc::Type type;
  bool request;      // PLC-written
  const char* what;  // one line for `contourctl io` and PLC.md
};
[[nodiscard]] const NcFieldInfo& nc_field(NcField f) noexcept;

// The fixed gpio: roles as entries of the image (same names as the gpio: keys). The NC owns
// estop (input), drive_enable, spindle_enable and alive: the PLC reads them, never writes them.
// coolant_mist / coolant_flood follow the NC's M7/M8/M9 unless a program writes them.
enum class FixedRole : std::uint8_t { kEstop, kDriveEnable, kSpindleEnable, kCoolantMist, kCoolantFlood, kAlive };
inline constexpr int kFixedRoles = 6;
[[nodiscard]] const char* fixed_role_name(FixedRole r) noexcept;

enum class PlcEntryKind : std::uint8_t { kSignal, kNc, kFixed };
struct PlcImageEntry {
  std::string name;
  control::plc::Type type = control::plc::Type::kBool;
  control::plc::Access access = control::plc::Access::kRead;
  PlcEntryKind kind = PlcEntryKind::kSignal;
  int index = 0;  // kSignal: PlcConfig::signals; kNc: NcField; kFixed: FixedRole
  int axis = -1;  // kNc per-axis fields
};

// The image layout (slot i = entries[i]) and the compiled programs (parallel to
// PlcConfig::programs). Immutable, shared by every copy of the Config.
struct PlcCompiled {
  std::vector<std::string> axis_names;
  std::vector<PlcImageEntry> entries;
  control::plc::SymbolTable symbols;
  std::vector<std::shared_ptr<const control::plc::CompiledProgram>> programs;
};

struct PlcConfig {
  bool present = false;  // the section was given
  bool allow_forcing = false;
  std::uint64_t instruction_budget = 20000;
  double scan_budget_us = 50.0;
  int gpio_poll_ms = 2;
  double mcode_timeout_s = 30.0;
  std::vector<PlcMcode> mcodes;
  bool tool_change = false;
  double tool_change_timeout_s = 60.0;
  std::vector<PlcModbusDevice> modbus;
  std::vector<PlcSignalConfig> signals;
  std::vector<PlcProgramConfig> programs;
  std::shared_ptr<const PlcCompiled> compiled;  // null when the section is absent or invalid
};

// Parses, reads the .st files (relative to the config file's directory) and compiles them
// against the image built for `axis_names` (machine.axes[].name, X Y Z order). The one-argument
// form assumes the axes X, Y, Z (config.cpp should pass machine.axes' names: see daemon/PLC.md).
PlcConfig parse_plc(Section& s, const std::vector<std::string>& axis_names);
PlcConfig parse_plc(Section& s);

// Builds the image layout and compiles every program, appending errors to `errors` (.st errors
// as "file:line:column: message"). Used by parse_plc; exposed for tests and tools.
std::shared_ptr<const PlcCompiled> compile_plc(const PlcConfig& c,
                                               const std::vector<std::string>& axis_names,
                                               std::vector<std::string>& errors);

}  // namespace contour::config
