#include "config/plc_config.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace contour::config {

namespace plc = control::plc;

std::uint16_t cia401_index(Cia401Object o) noexcept {
  switch (o) {
    case Cia401Object::kDigitalInput:
      return 0x6000;
    case Cia401Object::kDigitalOutput:
      return 0x6200;
    case Cia401Object::kAnalogInput:
      return 0x6401;
    case Cia401Object::kAnalogOutput:
      return 0x6411;
  }
  return 0;
}

namespace {
using plc::Type;
constexpr std::array<NcFieldInfo, kNcFields> kNc{{
    {NcField::kState, "state", Type::kInt, false,
     "machine state: 0 DISABLED, 1 ENABLING, 2 READY, 3 RUNNING, 4 HOLD, 5 FAULT, 6 ESTOP"},
    {NcField::kReady, "ready", Type::kBool, false, "drives enabled (READY, RUNNING or HOLD)"},
    {NcField::kProgramRunning, "program_running", Type::kBool, false, "a program is RUNNING"},
    {NcField::kFeedHold, "feed_hold", Type::kBool, false, "the machine is in HOLD"},
    {NcField::kFault, "fault", Type::kBool, false, "the machine is in FAULT"},
    {NcField::kEstop, "estop", Type::kBool, false, "the machine is in ESTOP"},
    {NcField::kSpindleOn, "spindle_on", Type::kBool, false, "the spindle is commanded to turn"},
    {NcField::kSpindleAtSpeed, "spindle_at_speed", Type::kBool, false, "spindle at its target speed"},
    {NcField::kSpindleRpm, "spindle_rpm", Type::kLreal, false, "measured spindle speed, rpm"},
    {NcField::kCoolantMist, "coolant_mist", Type::kBool, false, "the program's M7 (M9 clears)"},
    {NcField::kCoolantFlood, "coolant_flood", Type::kBool, false, "the program's M8 (M9 clears)"},
    {NcField::kHomed, "homed", Type::kBool, false, "every axis is homed"},
    {NcField::kTool, "tool", Type::kDint, false, "tool in the spindle (0: none)"},
    {NcField::kToolChangeReq, "tool_change_req", Type::kBool, false,
     "M6 waits for the PLC's tool change (until NC.tool_change_done)"},
    {NcField::kToolNumber, "tool_number", Type::kDint, false, "the tool M6 asks for"},
    {NcField::kMcodeReq, "mcode_req", Type::kBool, false,
     "a user M-code waits for the PLC (until NC.mcode_done)"},
    {NcField::kMcode, "mcode", Type::kInt, false, "the M number of the waiting M-code (100..199)"},
    {NcField::kMcodeP, "mcode_p", Type::kLreal, false, "its P word (0 when absent)"},
    {NcField::kMcodeQ, "mcode_q", Type::kLreal, false, "its Q word (0 when absent)"},
    {NcField::kFeedHoldReq, "feed_hold_req", Type::kBool, true,
     "request: hold the program while TRUE (resume is refused while TRUE)"},
    {NcField::kInhibitStart, "inhibit_start", Type::kBool, true,
     "request: refuse run, resume, MDI and jog while TRUE"},
    {NcField::kStopReq, "stop_req", Type::kBool, true,
     "request: controlled stop of the program (on the rising edge)"},
    {NcField::kEstopReq, "estop_req", Type::kBool, true,
     "request: E-stop (latched by the NC; reset only once this is FALSE)"},
    {NcField::kSpindleInhibit, "spindle_inhibit", Type::kBool, true,
     "request: spindle speed 0 while TRUE"},
    {NcField::kFaultReq, "fault_req", Type::kBool, true,
     "request: FAULT with NC.fault_code (reset only once this is FALSE)"},
    {NcField::kFaultCode, "fault_code", Type::kDint, true, "the code shown with NC.fault_req"},
    {NcField::kToolChangeDone, "tool_change_done", Type::kBool, true,
     "handshake: the tool change is complete (drop it when NC.tool_change_req falls)"},
    {NcField::kMcodeDone, "mcode_done", Type::kBool, true,
     "handshake: the M-code is complete (drop it when NC.mcode_req falls)"},
    {NcField::kPos, "pos", Type::kLreal, false, "axis position, machine coordinates, mm"},
    {NcField::kHomedAxis, "homed", Type::kBool, false, "the axis is homed"},
    {NcField::kAxisFault, "axis_fault", Type::kBool, true,
     "request: FAULT on this axis, e.g. an overtravel switch (reset only once FALSE)"},
}};

constexpr std::array<const char*, kFixedRoles> kRoles{"estop",         "drive_enable",
                                                      "spindle_enable", "coolant_mist",
                                                      "coolant_flood",  "alive"};

bool valid_identifier(const std::string& n) {
  if (n.empty() || !(std::isalpha(static_cast<unsigned char>(n[0])) || n[0] == '_')) return false;
  return std::all_of(n.begin(), n.end(),
                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; });
}

bool reserved_word(const std::string& upper_name) {
  static const std::set<std::string> kWords{
      "PROGRAM", "END_PROGRAM", "VAR", "VAR_EXTERNAL", "CONSTANT", "END_VAR", "IF", "THEN", "ELSIF",
      "ELSE", "END_IF", "CASE", "OF", "END_CASE", "FOR", "TO", "BY", "DO", "END_FOR", "WHILE",
      "REPEAT", "EXIT", "RETURN", "AND", "OR", "XOR", "NOT", "MOD", "TRUE", "FALSE", "ARRAY",
      "BOOL", "INT", "DINT", "REAL", "LREAL", "TIME", "T", "NC", "TON", "TOF", "TP", "R_TRIG",
      "F_TRIG", "SR", "RS", "CTU", "CTD", "CTUD", "RETAIN", "FUNCTION", "FUNCTION_BLOCK"};
  return kWords.count(upper_name) != 0;
}

std::string mark_of(Section& s) {
  const YAML::Mark m = s.node().Mark();
  return s.diag().file() + ":" + std::to_string(m.line + 1) + ":" + std::to_string(m.column + 1);
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

plc::Cell parse_default(Section& s, Type t) {
  if (!s.has("default")) {
    s.accept("default");
    return plc::is_real(t) ? plc::real_cell(0.0) : plc::int_cell(0);
  }
  if (t == Type::kBool) return plc::int_cell(s.boolean("default", false) ? 1 : 0);
  if (plc::is_real(t)) return plc::normalise(t, plc::real_cell(s.number("default", 0.0)));
  if (t == Type::kTime)  // milliseconds
    return plc::int_cell(s.integer("default", 0, 0, 1000L * 86400 * 365) * 1000000);
  const long lo = t == Type::kInt ? -32768 : -2147483648L;
  const long hi = t == Type::kInt ? 32767 : 2147483647L;
  return plc::int_cell(s.integer("default", 0, lo, hi));
}

drivers::gpio::LineSpec parse_line(Section& g, const std::string& role) {
  drivers::gpio::LineSpec spec;
  spec.role = role;
  spec.chip = g.string("chip", "gpiochip0");
  spec.offset = g.has("offset") ? static_cast<int>(g.integer("offset", -1, 0, 4095)) : -1;
  if (!g.has("offset")) g.accept("offset");
  spec.name = g.string("name", "");
  if (spec.offset < 0 && spec.name.empty()) g.error("offset", "give either offset or name");
  if (spec.offset >= 0 && !spec.name.empty()) g.error("name", "give either offset or name, not both");
  if (!g.has("chip") && !spec.name.empty()) spec.chip.clear();
  spec.active_low = g.boolean("active_low", false);
  return spec;
}

void parse_modbus_binding(Section& m, PlcSignalConfig& sig, const PlcConfig& cfg) {
  PlcBinding& b = sig.binding;
  const std::string dev = m.required_string("device");
  for (std::size_t i = 0; i < cfg.modbus.size(); ++i)
    if (cfg.modbus[i].name == dev) b.device = static_cast<int>(i);
  if (b.device < 0 && !dev.empty())
    m.error("device", "no plc.modbus device named '" + dev + "'");
  const std::pair<const char*, ModbusTable> tables[] = {
      {"coil", ModbusTable::kCoil},
      {"discrete_input", ModbusTable::kDiscreteInput},
      {"holding_register", ModbusTable::kHoldingRegister},
      {"input_register", ModbusTable::kInputRegister}};
  int found = 0;
  for (const auto& [key, table] : tables) {
    if (!m.has(key)) {
      m.accept(key);
      continue;
    }
    ++found;
    b.table = table;
    b.address = static_cast<int>(m.integer(key, 0, 0, 65535));
  }
  if (found != 1) {
    m.error(found == 0 ? "device" : "coil",
            "give exactly one of coil, discrete_input, holding_register, input_register");
    return;
  }
  const bool bit_table = b.table == ModbusTable::kCoil || b.table == ModbusTable::kDiscreteInput;
  b.bit = m.has("bit") ? static_cast<int>(m.integer("bit", 0, 0, 15)) : -1;
  if (!m.has("bit")) m.accept("bit");
  b.scale = m.number("scale", 1.0);
  b.is_signed = m.boolean("signed", true);
  b.invert = m.boolean("invert", false);
  if (bit_table && b.bit >= 0) m.error("bit", "only for registers (a coil or discrete input is one bit)");
  if (bit_table && sig.type != Type::kBool)
    m.error("device", std::string("a coil or discrete input is BOOL, not ") + plc::type_name(sig.type));
  if (!bit_table && sig.type == Type::kBool && b.bit < 0)
    m.error("bit", "a BOOL in a register needs bit: 0..15");
  if (!bit_table && sig.type != Type::kBool && b.bit >= 0)
    m.error("bit", "bit: is for BOOL signals");
  if (b.invert && sig.type != Type::kBool) m.error("invert", "only for BOOL signals");
  if (m.has("scale") && !plc::is_real(sig.type)) m.error("scale", "only for REAL and LREAL signals");
  if (b.scale == 0.0 || !std::isfinite(b.scale)) m.error("scale", "must be finite and not 0");
  if (sig.type == Type::kTime) m.error("device", "TIME signals are memory only");
  if (sig.type == Type::kDint && b.address == 65535)
    m.error("device", "a DINT takes two registers: the address must be below 65535");
  // Direction implied by the table (holding registers can be either).
  PlcDirection implied = PlcDirection::kMemory;
  if (b.table == ModbusTable::kCoil) implied = PlcDirection::kOutput;
  if (b.table == ModbusTable::kDiscreteInput || b.table == ModbusTable::kInputRegister)
    implied = PlcDirection::kInput;
  if (implied != PlcDirection::kMemory) {
    if (sig.direction != PlcDirection::kMemory && sig.direction != implied)
      m.error("device", std::string("a ") +
                            (b.table == ModbusTable::kCoil ? "coil is an output"
                             : b.table == ModbusTable::kDiscreteInput ? "discrete input is an input"
                                                                      : "input register is an input") +
                            " (direction)");
    sig.direction = implied;
  } else if (sig.direction == PlcDirection::kMemory) {
    m.error("holding_register", "a holding register is an input or an output: give direction");
  }
}

void parse_cia402_binding(Section& c, PlcSignalConfig& sig, const std::vector<std::string>& axes) {
  PlcBinding& b = sig.binding;
  b.axis_name = c.required_string("axis");
  for (std::size_t i = 0; i < axes.size(); ++i)
    if (lower(axes[i]) == lower(b.axis_name)) b.axis = static_cast<int>(i);
  if (b.axis < 0 && !b.axis_name.empty()) {
    std::string list;
    for (const auto& a : axes) list += (list.empty() ? "" : ", ") + a;
    c.error("axis", "no axis '" + b.axis_name + "' (machine.axes: " + list + ")");
  }
  if (sig.type != Type::kBool) c.error("axis", "CiA 402 digital inputs/outputs are BOOL");
  const bool in = c.has("input"), out = c.has("output");
  if (in == out) {
    c.error("axis", "give input: (0x60FD: negative_limit, positive_limit, home_switch, "
                    "interlock or 16..31) or output: (0x60FE bits 16..31)");
    c.accept("input");
    c.accept("output");
    return;
  }
  if (in) {
    const std::string v = c.string("input", "");
    c.accept("output");
    if (v == "negative_limit") b.bit = kCia402NegativeLimit;
    else if (v == "positive_limit") b.bit = kCia402PositiveLimit;
    else if (v == "home_switch") b.bit = kCia402HomeSwitch;
    else if (v == "interlock") b.bit = kCia402Interlock;
    else if (!v.empty() && std::all_of(v.begin(), v.end(), [](char ch) { return std::isdigit(static_cast<unsigned char>(ch)); }) &&
             std::stoi(v) >= 16 && std::stoi(v) <= 31)
      b.bit = std::stoi(v);
    else
      c.error("input", "'" + v + "': negative_limit, positive_limit, home_switch, interlock or "
                                 "a manufacturer bit 16..31 of 0x60FD");
    if (sig.direction == PlcDirection::kOutput) c.error("input", "an input (direction)");
    sig.direction = PlcDirection::kInput;
  } else {
    c.accept("input");
    b.bit = static_cast<int>(c.integer("output", 16, 0, 31));
    if (b.bit < 16)
      c.error("output", "0x60FE bits 0..15 are the drive's (bit 0: brake): use 16..31");
    if (sig.direction == PlcDirection::kInput) c.error("output", "an output (direction)");
    sig.direction = PlcDirection::kOutput;
  }
}

void parse_cia401_binding(Section& c, PlcSignalConfig& sig) {
  PlcBinding& b = sig.binding;
  b.node_id = static_cast<int>(c.required_integer("node", 1, 127));
  const std::pair<const char*, Cia401Object> objs[] = {
      {"digital_input", Cia401Object::kDigitalInput},
      {"digital_output", Cia401Object::kDigitalOutput},
      {"analog_input", Cia401Object::kAnalogInput},
      {"analog_output", Cia401Object::kAnalogOutput}};
  int found = 0;
  for (const auto& [key, obj] : objs) {
    if (!c.has(key)) {
      c.accept(key);
      continue;
    }
    ++found;
    b.object = obj;
    b.address = static_cast<int>(c.integer(key, 1, 1, 254));  // sub-index
  }
  if (found != 1) {
    c.error("node", "give exactly one of digital_input, digital_output, analog_input, "
                    "analog_output (the sub-index)");
    return;
  }
  const bool digital = b.object == Cia401Object::kDigitalInput || b.object == Cia401Object::kDigitalOutput;
  if (digital) {
    b.bit = static_cast<int>(c.required_integer("bit", 0, 7));
    if (sig.type != Type::kBool) c.error("node", "a digital CiA 401 point is BOOL");
  } else {
    c.accept("bit");
    if (sig.type != Type::kInt && !plc::is_real(sig.type))
      c.error("node", "an analog CiA 401 point is INT, REAL or LREAL");
  }
  b.scale = c.number("scale", 1.0);
  if (c.has("scale") && !plc::is_real(sig.type)) c.error("scale", "only for REAL and LREAL signals");
  const PlcDirection d = b.object == Cia401Object::kDigitalInput || b.object == Cia401Object::kAnalogInput
                             ? PlcDirection::kInput
                             : PlcDirection::kOutput;
  if (sig.direction != PlcDirection::kMemory && sig.direction != d)
    c.error("node", std::string("0x") + (d == PlcDirection::kInput ? "6000/0x6401 are inputs"
                                                                   : "6200/0x6411 are outputs") +
                        " (direction)");
  sig.direction = d;
}

PlcSignalConfig parse_signal(Section& s, const PlcConfig& cfg, const std::vector<std::string>& axes,
                             std::map<std::string, std::string>& names) {
  PlcSignalConfig sig;
  sig.where = mark_of(s);
  sig.name = s.required_string("name");
  const std::string up = plc::upper(sig.name);
  if (!sig.name.empty()) {
    if (!valid_identifier(sig.name))
      s.error("name", "'" + sig.name + "' is not an identifier (letters, digits, _; not starting "
                                       "with a digit)");
    else if (reserved_word(up))
      s.error("name", "'" + sig.name + "' is a reserved word of Structured Text");
    else if (std::find_if(kRoles.begin(), kRoles.end(), [&](const char* r) { return plc::upper(r) == up; }) != kRoles.end())
      s.error("name", "'" + sig.name + "' is a fixed role of the image (the gpio: section's line)");
    else if (names.count(up) != 0)
      s.error("name", "'" + sig.name + "' is declared twice (first at " + names[up] + ")");
    else
      names[up] = sig.where;
  }
  const std::string t = s.choice("type", "BOOL", {"BOOL", "INT", "DINT", "REAL", "LREAL", "TIME"});
  if (t == "INT") sig.type = Type::kInt;
  else if (t == "DINT") sig.type = Type::kDint;
  else if (t == "REAL") sig.type = Type::kReal;
  else if (t == "LREAL") sig.type = Type::kLreal;
  else if (t == "TIME") sig.type = Type::kTime;
  else sig.type = Type::kBool;
  if (s.has("direction")) {
    const std::string d = s.choice("direction", "input", {"input", "output", "memory"});
    sig.direction = d == "input" ? PlcDirection::kInput
                    : d == "output" ? PlcDirection::kOutput
                                    : PlcDirection::kMemory;
  } else {
    s.accept("direction");
  }
  const bool explicit_dir = s.has("direction");
  sig.description = s.string("description", "");
  sig.initial = parse_default(s, sig.type);

  const char* kinds[] = {"gpio", "modbus", "cia402", "cia401", "sim"};
  int found = 0;
  for (const char* k : kinds) found += s.has(k) ? 1 : 0;
  if (found > 1) s.error("name", "give at most one of gpio, modbus, cia402, cia401, sim");
  PlcBinding& b = sig.binding;
  if (s.has("gpio")) {
    b.kind = PlcBindingKind::kGpio;
    Section g = s.child("gpio");
    b.line = parse_line(g, sig.name);
    if (sig.type != Type::kBool) s.error("type", "a GPIO line is BOOL");
    if (!explicit_dir || sig.direction == PlcDirection::kMemory)
      s.error("gpio", "a GPIO line is an input or an output: give direction");
  } else {
    s.accept("gpio");
  }
  if (s.has("modbus")) {
    b.kind = PlcBindingKind::kModbus;
    Section m = s.child("modbus");
    parse_modbus_binding(m, sig, cfg);
  } else {
    s.accept("modbus");
  }
  if (s.has("cia402")) {
    b.kind = PlcBindingKind::kCia402;
    Section c = s.child("cia402");
    parse_cia402_binding(c, sig, axes);
  } else {
    s.accept("cia402");
  }
  if (s.has("cia401")) {
    b.kind = PlcBindingKind::kCia401;
    Section c = s.child("cia401");
    parse_cia401_binding(c, sig);
  } else {
    s.accept("cia401");
  }
  if (s.has("sim")) {
    b.kind = PlcBindingKind::kSim;
    const std::string p = s.string("sim", "");
    if (!plc::find_plant_point(p, b.point)) {
      std::string list;
      for (int i = 0; i < plc::kPlantPoints; ++i)
        list += std::string(list.empty() ? "" : ", ") + plc::plant_point(static_cast<plc::PlantPoint>(i)).name;
      s.error("sim", "no simulated point '" + p + "' (" + list + ")");
    } else {
      const auto& info = plc::plant_point(b.point);
      if (info.type != sig.type)
        s.error("type", std::string("sim point '") + p + "' is " + plc::type_name(info.type));
      const PlcDirection d = info.plc_input ? PlcDirection::kInput : PlcDirection::kOutput;
      if (explicit_dir && sig.direction != d)
        s.error("direction", std::string("sim point '") + p + "' is an " +
                                 (info.plc_input ? "input" : "output"));
      sig.direction = d;
    }
  } else {
    s.accept("sim");
  }
  if (b.kind == PlcBindingKind::kMemory) {
    if (explicit_dir && sig.direction != PlcDirection::kMemory)
      s.error("direction", "an input or output needs a binding (gpio, modbus, cia402, cia401 or sim)");
    sig.direction = PlcDirection::kMemory;
  } else if (sig.type == Type::kTime) {
    s.error("type", "TIME signals are memory only");
  }
  return sig;
}

// GPIO lines used twice, coils / registers / CiA points / sim points driven by two outputs.
void check_unique_points(const PlcConfig& c, std::vector<Section>& sections) {
  std::map<std::string, std::size_t> owner;
  for (std::size_t i = 0; i < c.signals.size() && i < sections.size(); ++i) {
    const PlcSignalConfig& s = c.signals[i];
    const PlcBinding& b = s.binding;
    std::vector<std::string> units;
    switch (b.kind) {
      case PlcBindingKind::kGpio:
        units.push_back("GPIO line " + (b.line.name.empty() ? b.line.chip + ":" + std::to_string(b.line.offset)
                                                            : "'" + b.line.name + "'"));
        break;
      case PlcBindingKind::kModbus: {
        if (s.direction != PlcDirection::kOutput || b.device < 0) break;
        const std::string dev = c.modbus[static_cast<std::size_t>(b.device)].name;
        if (b.table == ModbusTable::kCoil) {
          units.push_back("coil " + std::to_string(b.address) + " of '" + dev + "'");
          break;
        }
        const int regs = s.type == Type::kDint ? 2 : 1;
        for (int r = 0; r < regs; ++r) {
          for (int bit = 0; bit < 16; ++bit) {
            if (b.bit >= 0 && bit != b.bit) continue;
            units.push_back("holding register " + std::to_string(b.address + r) + " bit " +
                            std::to_string(bit) + " of '" + dev + "'");
          }
        }
        break;
      }
      case PlcBindingKind::kCia402:
        if (s.direction == PlcDirection::kOutput)
          units.push_back("0x60FE bit " + std::to_string(b.bit) + " of axis " + b.axis_name);
        break;
      case PlcBindingKind::kCia401:
        if (s.direction == PlcDirection::kOutput)
          units.push_back("node " + std::to_string(b.node_id) + " 0x" +
                          (b.object == Cia401Object::kDigitalOutput ? "6200" : "6411") + ":" +
                          std::to_string(b.address) +
                          (b.bit >= 0 ? " bit " + std::to_string(b.bit) : std::string()));
        break;
      case PlcBindingKind::kSim:
        if (s.direction == PlcDirection::kOutput)
          units.push_back(std::string("sim point ") + plc::plant_point(b.point).name);
        break;
      default:
        break;
    }
    for (const auto& u : units) {
      const auto [it, fresh] = owner.emplace(u, i);
      if (!fresh) {
        sections[i].error("name", "'" + s.name + "': " + u + " is already " +
                                      (b.kind == PlcBindingKind::kGpio ? "used" : "driven") +
                                      " by signal '" + c.signals[it->second].name + "' (" +
                                      c.signals[it->second].where + ")");
        break;
      }
    }
  }
}

}  // namespace

const NcFieldInfo& nc_field(NcField f) noexcept { return kNc[static_cast<std::size_t>(f)]; }
const char* fixed_role_name(FixedRole r) noexcept { return kRoles[static_cast<std::size_t>(r)]; }

std::shared_ptr<const PlcCompiled> compile_plc(const PlcConfig& c,
                                               const std::vector<std::string>& axis_names,
                                               std::vector<std::string>& errors) {
  auto out = std::make_shared<PlcCompiled>();
  out->axis_names = axis_names;
  auto add = [&](PlcImageEntry e) {
    const auto slot = static_cast<std::int32_t>(out->entries.size());
    std::string what;
    if (e.access == plc::Access::kRead) {
      if (e.kind == PlcEntryKind::kSignal) {
        what = "an input";
      } else if (e.kind == PlcEntryKind::kNc) {
        what = "NC status (read-only)";
      } else if (e.index == static_cast<int>(FixedRole::kEstop)) {
        what = "the E-stop input (read-only)";
      } else {
        what = "owned by the NC: the PLC can request a stop (NC.stop_req, NC.estop_req) or "
               "inhibit (NC.inhibit_start, NC.spindle_inhibit), never enable a drive";
      }
    }
    try {
      out->symbols.add({e.name, e.type, e.access, slot, what});
    } catch (const std::invalid_argument&) {
      return;  // a duplicate name: reported by the YAML checks
    }
    out->entries.push_back(std::move(e));
  };
  for (std::size_t i = 0; i < c.signals.size(); ++i) {
    const PlcSignalConfig& s = c.signals[i];
    if (s.name.empty()) continue;
    add({s.name, s.type, s.direction == PlcDirection::kInput ? plc::Access::kRead : plc::Access::kReadWrite,
         PlcEntryKind::kSignal, static_cast<int>(i), -1});
  }
  for (int r = 0; r < kFixedRoles; ++r) {
    const auto role = static_cast<FixedRole>(r);
    const bool writable = role == FixedRole::kCoolantMist || role == FixedRole::kCoolantFlood;
    add({kRoles[static_cast<std::size_t>(r)], Type::kBool,
         writable ? plc::Access::kReadWrite : plc::Access::kRead, PlcEntryKind::kFixed, r, -1});
  }
  for (int f = 0; f < kNcFields; ++f) {
    const NcFieldInfo& info = kNc[static_cast<std::size_t>(f)];
    const auto access = info.request ? plc::Access::kReadWrite : plc::Access::kRead;
    const bool per_axis = info.field == NcField::kPos || info.field == NcField::kHomedAxis ||
                          info.field == NcField::kAxisFault;
    if (!per_axis) {
      add({std::string("NC.") + info.name, info.type, access, PlcEntryKind::kNc, f, -1});
      continue;
    }
    for (std::size_t a = 0; a < axis_names.size(); ++a)
      add({std::string("NC.") + info.name + "_" + lower(axis_names[a]), info.type, access,
           PlcEntryKind::kNc, f, static_cast<int>(a)});
  }
  // Compile every program, then the one-writer rule across programs.
  std::map<std::int32_t, std::pair<std::size_t, plc::Pos>> writer;
  for (std::size_t p = 0; p < c.programs.size(); ++p) {
    const PlcProgramConfig& pc = c.programs[p];
    plc::CompileResult r =
        plc::compile_program(pc.source, out->symbols, {pc.path, c.instruction_budget});
    for (const auto& e : r.errors) errors.push_back(e.format());
    out->programs.push_back(r.program);
    if (!r.program) continue;
    for (const auto& w : r.program->writes) {
      const PlcImageEntry& e = out->entries[static_cast<std::size_t>(w.slot)];
      const bool exclusive = !(e.kind == PlcEntryKind::kSignal &&
                               c.signals[static_cast<std::size_t>(e.index)].direction ==
                                   PlcDirection::kMemory);
      if (!exclusive) continue;
      const auto [it, fresh] = writer.emplace(w.slot, std::make_pair(p, w.pos));
      if (fresh) continue;
      const auto& first = c.programs[it->second.first];
      errors.push_back(pc.path + ":" + std::to_string(w.pos.line) + ":" +
                       std::to_string(w.pos.column) + ": '" + e.name +
                       "' is also written by program '" +
                       (out->programs[it->second.first] ? out->programs[it->second.first]->name
                                                        : first.file) +
                       "' (" + first.path + ":" + std::to_string(it->second.second.line) + ":" +
                       std::to_string(it->second.second.column) +
                       "): an output or NC request has one writing program");
    }
  }
  return out;
}

PlcConfig parse_plc(Section& s) { return parse_plc(s, {"X", "Y", "Z"}); }

PlcConfig parse_plc(Section& s, const std::vector<std::string>& axis_names) {
  PlcConfig c;
  c.present = s.present();
  if (!c.present) return c;
  c.allow_forcing = s.boolean("allow_forcing", false);
  c.instruction_budget =
      static_cast<std::uint64_t>(s.integer("instruction_budget", 20000, 100, 10000000));
  c.scan_budget_us = s.number("scan_budget_us", 50.0, 1.0, 100000.0);
  c.gpio_poll_ms = static_cast<int>(s.integer("gpio_poll_ms", 2, 1, 100));
  c.mcode_timeout_s = s.number("mcode_timeout_s", 30.0, 0.01, 3600.0);
  {
    std::set<int> seen;
    for (Section& m : s.list("mcodes")) {
      PlcMcode mc;
      mc.m = static_cast<int>(m.required_integer("m", 100, 199));
      mc.timeout_s = m.number("timeout_s", c.mcode_timeout_s, 0.01, 3600.0);
      if (!seen.insert(mc.m).second) m.error("m", "M" + std::to_string(mc.m) + " is listed twice");
      c.mcodes.push_back(mc);
    }
  }
  if (s.has("tool_change")) {
    Section t = s.child("tool_change");
    c.tool_change = t.boolean("enabled", true);
    c.tool_change_timeout_s = t.number("timeout_s", 60.0, 0.1, 3600.0);
  } else {
    s.accept("tool_change");
  }
  {
    std::set<std::string> names;
    for (Section& m : s.list("modbus")) {
      PlcModbusDevice d;
      d.where = mark_of(m);
      d.name = m.required_string("name");
      if (!d.name.empty() && !names.insert(d.name).second)
        m.error("name", "device '" + d.name + "' is declared twice");
      auto& t = d.transport;
      const std::string transport = m.choice("transport", "tcp", {"tcp", "rtu"});
      t.transport = transport == "tcp" ? drivers::modbus::Transport::kTcp : drivers::modbus::Transport::kRtu;
      t.host = m.string("host", "127.0.0.1");
      t.port = static_cast<int>(m.integer("port", 502, 1, 65535));
      t.device = m.string("device", "/dev/ttyUSB0");
      t.baud = static_cast<int>(m.integer("baud", 115200, 1200, 4000000));
      const std::string parity = m.choice("parity", "none", {"none", "even", "odd"});
      t.parity = parity == "none" ? 'N' : parity == "even" ? 'E' : 'O';
      t.data_bits = static_cast<int>(m.integer("data_bits", 8, 7, 8));
      t.stop_bits = static_cast<int>(m.integer("stop_bits", 1, 1, 2));
      t.unit_id = static_cast<int>(m.integer("unit_id", 1, 0, 247));
      if (transport == "rtu" && t.unit_id == 0) m.error("unit_id", "RTU unit id must be 1..247");
      if (transport == "tcp" && m.has("device")) m.error("device", "only for transport: rtu");
      if (transport == "rtu" && m.has("host")) m.error("host", "only for transport: tcp");
      t.response_timeout = std::chrono::microseconds(
          static_cast<long>(1000.0 * m.number("timeout_ms", 20.0, 1.0, 5000.0)));
      d.poll_hz = m.number("poll_hz", 100.0, 0.1, 2000.0);
      d.stale_after = std::chrono::microseconds(
          static_cast<long>(1000.0 * m.number("stale_ms", 200.0, 1.0, 60000.0)));
      if (d.stale_after.count() < static_cast<long>(1e6 / d.poll_hz))
        m.error("stale_ms", "shorter than one poll period (1 / poll_hz)");
      c.modbus.push_back(std::move(d));
    }
  }
  std::vector<Section> sig_sections = s.list("signals");
  {
    std::map<std::string, std::string> names;
    for (Section& sig : sig_sections) c.signals.push_back(parse_signal(sig, c, axis_names, names));
  }
  check_unique_points(c, sig_sections);
  std::vector<Section> prog_sections = s.list("programs");
  const std::filesystem::path base =
      s.diag().file().empty() || s.diag().file()[0] == '<'
          ? std::filesystem::path()
          : std::filesystem::path(s.diag().file()).parent_path();
  bool readable = true;
  for (Section& p : prog_sections) {
    PlcProgramConfig pc;
    pc.file = p.required_string("file");
    pc.period_cycles = static_cast<int>(p.integer("period_cycles", 1, 1, 100000));
    pc.offset_cycles = static_cast<int>(p.integer("offset_cycles", 0, 0, 100000));
    if (pc.offset_cycles >= pc.period_cycles)
      p.error("offset_cycles", "must be below period_cycles");
    if (pc.file.empty()) readable = false;
    if (!pc.file.empty()) {
      const std::filesystem::path fp(pc.file);
      pc.path = (fp.is_absolute() || base.empty() ? fp : base / fp).lexically_normal().string();
      std::ifstream in(pc.path);
      if (!in) {
        readable = false;
        p.error("file", "cannot read '" + pc.path + "'");
      } else {
        std::ostringstream text;
        text << in.rdbuf();
        pc.source = text.str();
      }
    }
    c.programs.push_back(std::move(pc));
  }
  // Compile (all programs, all errors), each error attached to its program's `file:` key.
  std::vector<std::string> errors;
  std::shared_ptr<const PlcCompiled> compiled;
  if (readable) compiled = compile_plc(c, axis_names, errors);
  for (const auto& e : errors) {
    std::size_t which = 0;
    for (std::size_t i = 0; i < c.programs.size(); ++i)
      if (e.rfind(c.programs[i].path + ":", 0) == 0) which = i;
    if (which < prog_sections.size()) prog_sections[which].error("file", e);
  }
  if (errors.empty()) c.compiled = compiled;
  return c;
}

}  // namespace contour::config
