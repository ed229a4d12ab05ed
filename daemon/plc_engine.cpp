#include "daemon/plc_engine.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

namespace contour::daemon {

namespace cp = control::plc;
namespace cfgns = config;
namespace dm = drivers::modbus;
using cp::Cell;
using cp::Type;

const char* to_string(PlcFaultKind k) noexcept {
  switch (k) {
    case PlcFaultKind::kNone:
      return "none";
    case PlcFaultKind::kIoStale:
      return "PLC I/O stale";
    case PlcFaultKind::kMcodeTimeout:
      return "M-code timeout";
    case PlcFaultKind::kToolChangeTimeout:
      return "tool change timeout";
    case PlcFaultKind::kRuntimeError:
      return "PLC runtime error";
  }
  return "?";
}

const char* to_string(Handshake h) noexcept {
  switch (h) {
    case Handshake::kIdle:
      return "idle";
    case Handshake::kPending:
      return "pending";
    case Handshake::kWaiting:
      return "waiting";
    case Handshake::kDone:
      return "done";
    case Handshake::kTimedOut:
      return "timed_out";
  }
  return "?";
}

struct PlcEngine::InputBinding {
  enum Kind : std::uint8_t { kDiscrete, kInputReg, kHoldingReg, kGpio, kCia402, kCia401Di, kCia401Ai, kSim };
  Kind kind = kDiscrete;
  std::int32_t slot = 0;
  Type type = Type::kBool;
  int src = 0;    // coupler / axis / CiA 401 node position
  int index = 0;  // offset in the record / GPIO input / sub-index - 1 / plant point
  int bit = -1;
  bool invert = false;
  bool is_signed = true;
  double scale = 1.0;
  Cell def{};
};

struct PlcEngine::OutputBinding {
  enum Kind : std::uint8_t { kCoil, kHoldingReg, kGpio, kCia402, kCia401Do, kCia401Ao, kSim };
  Kind kind = kCoil;
  std::int32_t slot = 0;
  Type type = Type::kBool;
  int src = 0;
  int index = 0;
  int bit = -1;
  bool invert = false;
  bool is_signed = true;
  double scale = 1.0;
};

struct PlcEngine::Published {
  std::uint64_t cycle = 0;
  std::vector<Cell> values;
  std::vector<std::uint8_t> forced;
  std::vector<PlcScanStats> programs;
  PlcScanStats scan{};
  std::vector<std::uint8_t> device_state;  // CouplerState
  std::vector<std::int64_t> device_age_ns;
  Handshake mcode = Handshake::kIdle, tool = Handshake::kIdle;
  int mcode_number = 0;
  std::int32_t tool_number = 0;
  std::vector<PlcFault> faults;
  std::size_t nfaults = 0;
};

namespace {

constexpr std::uint64_t kPublishEvery = 20;  // cycles (20 ms at 1 kHz): `io --watch` rate and more
constexpr std::uint8_t kDirty = 0x4, kIndex = 0x3;
constexpr std::size_t kMaxLatched = 32;

std::int64_t wall_now_ns() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

const std::shared_ptr<const cfgns::PlcCompiled>& checked(const cfgns::Config& c) {
  if (!c.plc.present || !c.plc.compiled)
    throw std::invalid_argument("PlcEngine: the plc: section is absent or did not compile");
  return c.plc.compiled;
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Decodes a register value (or two for DINT) into a cell of `type`.
Cell decode_register(Type type, std::uint16_t r0, std::uint16_t r1, int bit, bool invert,
                     bool is_signed, double scale) noexcept {
  switch (type) {
    case Type::kBool:
      return cp::int_cell((((r0 >> bit) & 1u) != 0) != invert ? 1 : 0);
    case Type::kInt:
      return cp::int_cell(is_signed ? static_cast<std::int16_t>(r0) : cp::wrap16(r0));
    case Type::kDint: {
      const std::uint32_t v = (static_cast<std::uint32_t>(r0) << 16) | r1;
      return cp::int_cell(is_signed ? static_cast<std::int64_t>(static_cast<std::int32_t>(v))
                                    : cp::wrap32(static_cast<std::int64_t>(v)));
    }
    case Type::kReal:
    case Type::kLreal: {
      const double raw = is_signed ? static_cast<double>(static_cast<std::int16_t>(r0))
                                   : static_cast<double>(r0);
      return cp::normalise(type, cp::real_cell(raw * scale));
    }
    default:
      return cp::int_cell(0);
  }
}

// A REAL on a 16-bit register or analog channel: raw = round(v / scale), saturated.
std::int64_t encode_scaled(double v, double scale, bool is_signed) noexcept {
  double raw = std::nearbyint(v / scale);
  if (std::isnan(raw)) raw = 0.0;
  const double lo = is_signed ? -32768.0 : 0.0, hi = is_signed ? 32767.0 : 65535.0;
  return static_cast<std::int64_t>(std::clamp(raw, lo, hi));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
PlcEngine::PlcEngine(const config::Config& cfg, drivers::gpio::GpioBackend* gpio,
                     std::function<void(const std::string&)> log)
    : cfg_(cfg), compiled_(checked(cfg)), log_(std::move(log)), entries_(compiled_->entries) {
  const cfgns::PlcConfig& pc = cfg_.plc;
  std::vector<std::string> errors;
  auto err = [&](const cfgns::PlcSignalConfig& s, const std::string& m) {
    errors.push_back(s.where + ": plc.signals '" + s.name + "': " + m);
  };
  period_ns_ = static_cast<std::int64_t>(std::llround(cfg_.machine.period_s * 1e9));
  scan_budget_ns_ = pc.scan_budget_us * 1000.0;
  forcing_allowed_ = pc.allow_forcing || cfg_.bus.type == "sim";
  tool_change_enabled_ = pc.tool_change;
  tool_change_timeout_s_ = pc.tool_change_timeout_s;
  for (const auto& m : pc.mcodes) mcode_timeout_s_[static_cast<std::size_t>(m.m)] = m.timeout_s;

  // Memory: the image, then each program's locals.
  const auto n = static_cast<std::int32_t>(entries_.size());
  mem_.assign(static_cast<std::size_t>(n), cp::int_cell(0));
  nc_.fill(-1);
  for (auto& a : nc_axis_) a.fill(-1);
  fixed_.fill(-1);
  for (std::int32_t slot = 0; slot < n; ++slot) {
    const cfgns::PlcImageEntry& e = entries_[static_cast<std::size_t>(slot)];
    if (e.kind == cfgns::PlcEntryKind::kSignal) {
      at(slot) = pc.signals[static_cast<std::size_t>(e.index)].initial;
      user_slots_.push_back(slot);
    } else if (e.kind == cfgns::PlcEntryKind::kFixed) {
      fixed_[static_cast<std::size_t>(e.index)] = slot;
    } else {
      const auto f = static_cast<cfgns::NcField>(e.index);
      if (e.axis < 0) {
        nc_[static_cast<std::size_t>(e.index)] = slot;
      } else if (e.axis < kMaxAxes) {
        const std::size_t which = f == cfgns::NcField::kPos ? 0 : f == cfgns::NcField::kHomedAxis ? 1 : 2;
        nc_axis_[which][static_cast<std::size_t>(e.axis)] = slot;
      }
      if (is_real(e.type)) at(slot) = cp::real_cell(0.0);
    }
  }
  std::int32_t base = n;
  std::size_t max_stack = 1;
  for (std::size_t p = 0; p < pc.programs.size(); ++p) {
    Program prog;
    prog.compiled = compiled_->programs.at(p);
    prog.base = base;
    prog.period = pc.programs[p].period_cycles;
    prog.offset = pc.programs[p].offset_cycles;
    prog.code = cp::link(*prog.compiled, base);
    for (const auto& w : prog.compiled->writes) {
      prog.written.push_back(w.slot);
      if (w.slot == fixed_[static_cast<std::size_t>(cfgns::FixedRole::kCoolantMist)]) coolant_mist_owned_ = true;
      if (w.slot == fixed_[static_cast<std::size_t>(cfgns::FixedRole::kCoolantFlood)]) coolant_flood_owned_ = true;
    }
    mem_.insert(mem_.end(), prog.compiled->locals_init.begin(), prog.compiled->locals_init.end());
    base += prog.compiled->locals;
    max_stack = std::max(max_stack, static_cast<std::size_t>(prog.compiled->max_stack));
    programs_.push_back(std::move(prog));
  }
  init_ = mem_;
  stack_.assign(max_stack, cp::int_cell(0));
  forced_.assign(mem_.size(), 0);
  forced_value_.assign(mem_.size(), cp::int_cell(0));
  stats_.assign(programs_.size(), PlcScanStats{});
  latched_.assign(kMaxLatched, PlcFault{});

  // Bindings.
  std::vector<drivers::gpio::LineSpec> gpio_in, gpio_out;
  std::vector<bool> gpio_safe;
  struct DevAddr {
    std::vector<int> di, ir, hr_in, coils, hr_out;
  };
  std::vector<DevAddr> dev(pc.modbus.size());
  std::map<int, std::size_t> node_pos;  // CiA 401 node -> position
  for (std::int32_t slot = 0; slot < n; ++slot) {
    const cfgns::PlcImageEntry& e = entries_[static_cast<std::size_t>(slot)];
    if (e.kind != cfgns::PlcEntryKind::kSignal) continue;
    const cfgns::PlcSignalConfig& s = pc.signals[static_cast<std::size_t>(e.index)];
    const cfgns::PlcBinding& b = s.binding;
    const bool in = s.direction == cfgns::PlcDirection::kInput;
    InputBinding ib;
    ib.slot = slot;
    ib.type = s.type;
    ib.bit = b.bit;
    ib.invert = b.invert;
    ib.is_signed = b.is_signed;
    ib.scale = b.scale;
    ib.def = s.initial;
    OutputBinding ob;
    ob.slot = slot;
    ob.type = s.type;
    ob.bit = b.bit;
    ob.invert = b.invert;
    ob.is_signed = b.is_signed;
    ob.scale = b.scale;
    switch (b.kind) {
      case cfgns::PlcBindingKind::kMemory:
        break;
      case cfgns::PlcBindingKind::kGpio:
        if (in) {
          ib.kind = InputBinding::kGpio;
          ib.index = static_cast<int>(gpio_in.size());
          gpio_in.push_back(b.line);
          inputs_.push_back(ib);
        } else {
          ob.kind = OutputBinding::kGpio;
          ob.index = static_cast<int>(gpio_out.size());
          gpio_out.push_back(b.line);
          gpio_safe.push_back(s.initial.i != 0);
          outputs_.push_back(ob);
        }
        break;
      case cfgns::PlcBindingKind::kModbus: {
        DevAddr& d = dev.at(static_cast<std::size_t>(b.device));
        const int regs = s.type == Type::kDint ? 2 : 1;
        ib.src = ob.src = b.device;
        ib.index = ob.index = b.address;  // rebased below, once the spans are known
        switch (b.table) {
          case cfgns::ModbusTable::kDiscreteInput:
            ib.kind = InputBinding::kDiscrete;
            d.di.push_back(b.address);
            inputs_.push_back(ib);
            break;
          case cfgns::ModbusTable::kInputRegister:
            ib.kind = InputBinding::kInputReg;
            for (int r = 0; r < regs; ++r) d.ir.push_back(b.address + r);
            inputs_.push_back(ib);
            break;
          case cfgns::ModbusTable::kHoldingRegister:
            if (in) {
              ib.kind = InputBinding::kHoldingReg;
              for (int r = 0; r < regs; ++r) d.hr_in.push_back(b.address + r);
              inputs_.push_back(ib);
            } else {
              ob.kind = OutputBinding::kHoldingReg;
              for (int r = 0; r < regs; ++r) d.hr_out.push_back(b.address + r);
              outputs_.push_back(ob);
            }
            break;
          case cfgns::ModbusTable::kCoil:
            ob.kind = OutputBinding::kCoil;
            d.coils.push_back(b.address);
            outputs_.push_back(ob);
            break;
        }
        break;
      }
      case cfgns::PlcBindingKind::kCia402: {
        int axis = -1;
        for (std::size_t a = 0; a < cfg_.machine.axes.size(); ++a)
          if (lower(cfg_.machine.axes[a].name) == lower(b.axis_name)) axis = static_cast<int>(a);
        if (axis < 0 || axis >= kMaxAxes) {
          err(s, "cia402.axis '" + b.axis_name + "' is not an axis of machine.axes");
          break;
        }
        if (in) {
          ib.kind = InputBinding::kCia402;
          ib.src = axis;
          inputs_.push_back(ib);
        } else {
          ob.kind = OutputBinding::kCia402;
          ob.src = axis;
          outputs_.push_back(ob);
        }
        break;
      }
      case cfgns::PlcBindingKind::kCia401: {
        if (b.address < 1 || b.address > kCia401Subs) {
          err(s, "cia401 sub-index " + std::to_string(b.address) + ": this engine maps 1.." +
                     std::to_string(kCia401Subs));
          break;
        }
        auto it = node_pos.find(b.node_id);
        if (it == node_pos.end()) {
          if (node_pos.size() >= kMaxCia401Nodes) {
            err(s, "more than " + std::to_string(kMaxCia401Nodes) + " CiA 401 nodes");
            break;
          }
          it = node_pos.emplace(b.node_id, node_pos.size()).first;
          cia401_nodes_[it->second] = static_cast<std::uint8_t>(b.node_id);
          cia401_count_ = node_pos.size();
        }
        const int pos = static_cast<int>(it->second);
        const bool digital = b.object == cfgns::Cia401Object::kDigitalInput ||
                             b.object == cfgns::Cia401Object::kDigitalOutput;
        if (in) {
          ib.kind = digital ? InputBinding::kCia401Di : InputBinding::kCia401Ai;
          ib.src = pos;
          ib.index = b.address - 1;
          inputs_.push_back(ib);
        } else {
          ob.kind = digital ? OutputBinding::kCia401Do : OutputBinding::kCia401Ao;
          ob.src = pos;
          ob.index = b.address - 1;
          outputs_.push_back(ob);
        }
        break;
      }
      case cfgns::PlcBindingKind::kSim:
        if (cfg_.bus.type != "sim") {
          err(s, "sim: binds the built-in simulated machine: only with bus.type: sim");
          break;
        }
        if (!sim_) sim_ = std::make_unique<PlcSimPlant>(cfg_);
        if (in) {
          ib.kind = InputBinding::kSim;
          ib.index = static_cast<int>(b.point);
          inputs_.push_back(ib);
        } else {
          ob.kind = OutputBinding::kSim;
          ob.index = static_cast<int>(b.point);
          outputs_.push_back(ob);
        }
        break;
    }
  }
  if (!errors.empty()) throw config::ConfigError(errors);

  // Couplers: spans, then rebase the bindings onto them.
  for (std::size_t d = 0; d < pc.modbus.size(); ++d) {
    const cfgns::PlcModbusDevice& md = pc.modbus[d];
    const DevAddr& a = dev[d];
    dm::IoCouplerSettings st;
    st.name = md.name;
    st.transport = md.transport;
    st.poll_hz = md.poll_hz;
    st.stale_after = md.stale_after;
    auto span = [](const std::vector<int>& v) {
      if (v.empty()) return dm::CouplerSpan{};
      const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
      return dm::CouplerSpan{static_cast<std::uint16_t>(*lo), static_cast<std::uint16_t>(*hi - *lo + 1)};
    };
    st.discrete_inputs = span(a.di);
    st.input_registers = span(a.ir);
    st.holding_inputs = span(a.hr_in);
    for (int c : a.coils) st.coils.push_back(static_cast<std::uint16_t>(c));
    for (int r : a.hr_out) st.holding_outputs.push_back(static_cast<std::uint16_t>(r));
    Coupler c;
    c.stale_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(md.stale_after).count();
    // Safe outputs: every output signal of this coupler at its default.
    dm::CouplerOutputs safe{};
    try {
      c.dev = std::make_unique<dm::IoCoupler>(st, safe);
    } catch (const std::invalid_argument& e) {
      throw config::ConfigError({md.where + ": plc.modbus '" + md.name + "': " + e.what()});
    }
    for (auto& ib : inputs_) {
      if (ib.src != static_cast<int>(d)) continue;
      if (ib.kind == InputBinding::kDiscrete) ib.index -= st.discrete_inputs.start;
      if (ib.kind == InputBinding::kInputReg) ib.index -= st.input_registers.start;
      if (ib.kind == InputBinding::kHoldingReg) ib.index -= st.holding_inputs.start;
    }
    for (auto& ob : outputs_) {
      if (ob.src != static_cast<int>(d)) continue;
      if (ob.kind == OutputBinding::kCoil) ob.index -= c.dev->coil_base();
      if (ob.kind == OutputBinding::kHoldingReg) ob.index -= c.dev->holding_output_base();
    }
    couplers_.push_back(std::move(c));
  }
  // The safe (default) outputs of each coupler, now that the bindings are rebased.
  for (std::size_t d = 0; d < couplers_.size(); ++d) {
    dm::CouplerOutputs safe{};
    for (const auto& ob : outputs_) {
      if (ob.src != static_cast<int>(d) || (ob.kind != OutputBinding::kCoil && ob.kind != OutputBinding::kHoldingReg))
        continue;
      const Cell v = at(ob.slot);
      if (ob.kind == OutputBinding::kCoil) safe.coils[static_cast<std::size_t>(ob.index)] = (v.i != 0) != ob.invert ? 1 : 0;
    }
    couplers_[d].out = safe;
    const auto st = couplers_[d].dev->settings();
    couplers_[d].dev = std::make_unique<dm::IoCoupler>(st, safe);
  }
  if (!gpio_in.empty() || !gpio_out.empty()) {
    if (gpio == nullptr) {
      if (cfg_.gpio.backend == "sim") {
        own_sim_gpio_ = drivers::gpio::SimGpio::create();
        gpio = own_sim_gpio_.get();
      } else {
        own_gpiod_ = std::make_unique<drivers::gpio::GpiodBackend>(cfg_.gpio.consumer);
        gpio = own_gpiod_.get();
      }
    }
    gpio_ = std::make_unique<PlcGpio>(*gpio, gpio_in, gpio_out, gpio_safe,
                                      std::chrono::milliseconds(pc.gpio_poll_ms), log_);
  }

  // Snapshot slots, sized once.
  pub_ = std::make_unique<Published[]>(3);
  for (int k = 0; k < 3; ++k) {
    Published& p = pub_[static_cast<std::size_t>(k)];
    p.values.assign(mem_.begin(), mem_.begin() + static_cast<std::ptrdiff_t>(entries_.size()));
    p.forced.assign(entries_.size(), 0);
    p.programs.assign(programs_.size(), PlcScanStats{});
    p.device_state.assign(couplers_.size(), 0);
    p.device_age_ns.assign(couplers_.size(), 0);
    p.faults.assign(kMaxLatched, PlcFault{});
  }
}

PlcEngine::~PlcEngine() { stop(); }

void PlcEngine::start() {
  if (started_) return;
  started_ = true;
  const std::int64_t now = wall_now_ns();
  for (auto& c : couplers_) {
    c.started_ns = now;
    c.dev->start();
  }
  if (gpio_) gpio_->start();
  if (log_) {
    log_("plc: " + std::to_string(programs_.size()) + " program(s), " +
         std::to_string(entries_.size()) + " image entries, " + std::to_string(couplers_.size()) +
         " Modbus coupler(s)" + (forcing_allowed_ ? ", forcing allowed" : ""));
  }
}

void PlcEngine::stop() {
  if (!started_) return;
  started_ = false;
  for (auto& c : couplers_) c.dev->stop();  // each writes its safe outputs
  if (gpio_) gpio_->stop();
}

int PlcEngine::find(const std::string& name) const {
  const cp::ExternalSymbol* s = compiled_->symbols.find(name);
  return s == nullptr ? -1 : s->slot;
}

bool PlcEngine::handles_mcode(int m) const noexcept {
  return m >= 0 && m < static_cast<int>(mcode_timeout_s_.size()) &&
         mcode_timeout_s_[static_cast<std::size_t>(m)] > 0.0;
}

// ---- RT ---------------------------------------------------------------------------------------
void PlcEngine::scan(const PlcNcInput& in, PlcCycleOutput& out) noexcept {
  const std::int64_t t0 = wall_now_ns();
  cycle_ = in.cycle;
  out = PlcCycleOutput{};
  apply_forces();
  read_inputs(in, t0, out);
  run_programs(in.cycle);
  write_outputs(in, out);
  handshakes(in.cycle, out);
  const std::int64_t t1 = wall_now_ns();
  record(scan_stats_, static_cast<std::uint32_t>(std::min<std::int64_t>(t1 - t0, 0xFFFFFFFF)), 0,
         std::numeric_limits<double>::infinity());
  if (in.cycle % kPublishEvery == 0) publish();
}

void PlcEngine::apply_forces() noexcept {
  ForceCommand fc;
  while (force_ring_.pop(fc)) {
    if (fc.slot < 0) {
      std::fill(forced_.begin(), forced_.end(), 0);
      forced_count_ = 0;
      continue;
    }
    auto& f = forced_[static_cast<std::size_t>(fc.slot)];
    if (fc.on && f == 0) ++forced_count_;
    if (!fc.on && f != 0) --forced_count_;
    f = fc.on ? 1 : 0;
    forced_value_[static_cast<std::size_t>(fc.slot)] = fc.value;
  }
}

void PlcEngine::read_inputs(const PlcNcInput& in, std::int64_t wall_ns, PlcCycleOutput& out) noexcept {
  // Couplers: the latest record, its age.
  for (std::size_t d = 0; d < couplers_.size(); ++d) {
    Coupler& c = couplers_[d];
    c.reading = c.dev->read(wall_ns, c.in);
    const bool never = c.reading.state == dm::CouplerState::kNoData;
    const std::int64_t age = never ? wall_ns - c.started_ns : c.reading.age_ns;
    c.ok = c.reading.state == dm::CouplerState::kOk;
    if (!c.ok && started_ && age > c.stale_ns && !c.fault_latched) {
      c.fault_latched = true;
      latch({PlcFaultKind::kIoStale, static_cast<int>(d), 0, static_cast<double>(age) * 1e-9,
             static_cast<double>(c.stale_ns) * 1e-9},
            out);
    }
  }
  if (gpio_) gpio_->read(gpio_in_);
  for (std::size_t k = 0; k < cia401_count_; ++k) {
    cia401_in_[k] = nullptr;
    for (const auto& node : in.cia401)
      if (node.node_id == cia401_nodes_[k] && node.valid) cia401_in_[k] = &node;
  }
  if (sim_) sim_->step(static_cast<double>(period_ns_) * 1e-9, {in.pos_mm[0], in.pos_mm[1], in.pos_mm[2]});

  for (const InputBinding& b : inputs_) {
    Cell v = b.def;
    switch (b.kind) {
      case InputBinding::kDiscrete: {
        const Coupler& c = couplers_[static_cast<std::size_t>(b.src)];
        if (c.ok) v = cp::int_cell((c.in.discrete[static_cast<std::size_t>(b.index)] != 0) != b.invert ? 1 : 0);
        break;
      }
      case InputBinding::kInputReg:
      case InputBinding::kHoldingReg: {
        const Coupler& c = couplers_[static_cast<std::size_t>(b.src)];
        if (!c.ok) break;
        const auto& regs = b.kind == InputBinding::kInputReg ? c.in.input_registers : c.in.holding;
        const auto i = static_cast<std::size_t>(b.index);
        v = decode_register(b.type, regs[i], i + 1 < regs.size() ? regs[i + 1] : 0, b.bit, b.invert,
                            b.is_signed, b.scale);
        break;
      }
      case InputBinding::kGpio:
        if (gpio_in_.seq != 0) v = cp::int_cell(gpio_in_.v[static_cast<std::size_t>(b.index)]);
        break;
      case InputBinding::kCia402:
        if (in.drive_inputs_valid[static_cast<std::size_t>(b.src)])
          v = cp::int_cell((in.drive_inputs[static_cast<std::size_t>(b.src)] >> b.bit) & 1u);
        break;
      case InputBinding::kCia401Di: {
        const Cia401Inputs* n = cia401_in_[static_cast<std::size_t>(b.src)];
        if (n != nullptr) v = cp::int_cell((n->digital[static_cast<std::size_t>(b.index)] >> b.bit) & 1);
        break;
      }
      case InputBinding::kCia401Ai: {
        const Cia401Inputs* n = cia401_in_[static_cast<std::size_t>(b.src)];
        if (n == nullptr) break;
        const std::int16_t raw = n->analog[static_cast<std::size_t>(b.index)];
        v = cp::is_real(b.type) ? cp::normalise(b.type, cp::real_cell(raw * b.scale)) : cp::int_cell(raw);
        break;
      }
      case InputBinding::kSim:
        v = cp::int_cell(sim_->get(static_cast<cp::PlantPoint>(b.index)));
        break;
    }
    at(b.slot) = v;
  }

  // NC status.
  auto put_b = [&](cfgns::NcField f, bool v) {
    const std::int32_t s = nc_[static_cast<std::size_t>(f)];
    if (s >= 0) at(s).i = v ? 1 : 0;
  };
  auto put_i = [&](cfgns::NcField f, std::int64_t v) {
    const std::int32_t s = nc_[static_cast<std::size_t>(f)];
    if (s >= 0) at(s).i = v;
  };
  auto put_r = [&](cfgns::NcField f, double v) {
    const std::int32_t s = nc_[static_cast<std::size_t>(f)];
    if (s >= 0) at(s).r = v;
  };
  using F = cfgns::NcField;
  const MachineState st = in.state;
  put_i(F::kState, static_cast<std::int64_t>(st));
  put_b(F::kReady, st == MachineState::kReady || st == MachineState::kRunning || st == MachineState::kHold);
  put_b(F::kProgramRunning, in.program_running);
  put_b(F::kFeedHold, st == MachineState::kHold);
  put_b(F::kFault, st == MachineState::kFault);
  put_b(F::kEstop, st == MachineState::kEstop);
  put_b(F::kSpindleOn, in.spindle_on);
  put_b(F::kSpindleAtSpeed, in.spindle_at_speed);
  put_r(F::kSpindleRpm, in.spindle_rpm);
  put_b(F::kCoolantMist, in.coolant_mist);
  put_b(F::kCoolantFlood, in.coolant_flood);
  bool all_homed = in.axes > 0;
  for (int a = 0; a < in.axes && a < kMaxAxes; ++a) all_homed = all_homed && in.homed[static_cast<std::size_t>(a)];
  put_b(F::kHomed, all_homed);
  put_i(F::kTool, in.tool);
  put_b(F::kToolChangeReq, tool_.req);
  put_i(F::kToolNumber, tool_.number);
  put_b(F::kMcodeReq, mcode_.req);
  put_i(F::kMcode, mcode_.number);
  put_r(F::kMcodeP, mcode_.p);
  put_r(F::kMcodeQ, mcode_.q);
  for (std::size_t a = 0; a < kMaxAxes; ++a) {
    if (nc_axis_[0][a] >= 0) at(nc_axis_[0][a]).r = in.pos_mm[a];
    if (nc_axis_[1][a] >= 0) at(nc_axis_[1][a]).i = in.homed[a] ? 1 : 0;
  }
  // Fixed roles: the NC's lines mirrored; the coolant valves follow M7/M8/M9 unless owned.
  auto put_fixed = [&](cfgns::FixedRole r, bool v) {
    const std::int32_t s = fixed_[static_cast<std::size_t>(r)];
    if (s >= 0) at(s).i = v ? 1 : 0;
  };
  put_fixed(cfgns::FixedRole::kEstop, in.estop_input);
  put_fixed(cfgns::FixedRole::kDriveEnable, in.drive_enable);
  put_fixed(cfgns::FixedRole::kSpindleEnable, in.spindle_enable);
  put_fixed(cfgns::FixedRole::kAlive, in.alive);
  if (!coolant_mist_owned_) put_fixed(cfgns::FixedRole::kCoolantMist, in.coolant_mist);
  if (!coolant_flood_owned_) put_fixed(cfgns::FixedRole::kCoolantFlood, in.coolant_flood);

  if (forced_count_ > 0) {
    for (std::int32_t s : user_slots_)
      if (forced_[static_cast<std::size_t>(s)] != 0) at(s) = forced_value_[static_cast<std::size_t>(s)];
  }
}

void PlcEngine::run_programs(std::uint64_t cycle) noexcept {
  const std::int64_t now = static_cast<std::int64_t>(cycle) * period_ns_;
  for (std::size_t p = 0; p < programs_.size(); ++p) {
    Program& prog = programs_[p];
    if (prog.stopped) continue;
    if (cycle % static_cast<std::uint64_t>(prog.period) != static_cast<std::uint64_t>(prog.offset)) continue;
    const std::int64_t t0 = wall_now_ns();
    const cp::RunResult r = cp::run(prog.code, mem_, stack_, now);
    const std::int64_t t1 = wall_now_ns();
    PlcScanStats& s = stats_[p];
    record(s, static_cast<std::uint32_t>(std::min<std::int64_t>(t1 - t0, 0xFFFFFFFF)), r.executed,
           scan_budget_ns_);
    if (r.status != cp::RunStatus::kOk) {
      prog.stopped = true;
      s.state = 1;
      s.error_line = prog.compiled->lines[r.pc];
      s.error_status = static_cast<std::uint8_t>(r.status);
      // What it drove goes back to its defaults (safe values) while it is stopped.
      for (std::int32_t slot : prog.written) at(slot) = init_[static_cast<std::size_t>(slot)];
      pending_runtime_error_ = {PlcFaultKind::kRuntimeError, static_cast<int>(p), s.error_line,
                                static_cast<double>(r.status), 0.0};
    }
  }
}

void PlcEngine::write_outputs(const PlcNcInput& in, PlcCycleOutput& out) noexcept {
  if (pending_runtime_error_) {
    latch(pending_runtime_error_, out);
    pending_runtime_error_ = {};
  }
  if (forced_count_ > 0) {
    for (std::int32_t s : user_slots_)
      if (forced_[static_cast<std::size_t>(s)] != 0) at(s) = forced_value_[static_cast<std::size_t>(s)];
  }
  for (auto& c : couplers_) {
    std::fill(c.out.holding.begin(), c.out.holding.end(), std::uint16_t{0});
  }
  for (const OutputBinding& b : outputs_) {
    const Cell v = at(b.slot);
    const auto i = static_cast<std::size_t>(b.index);
    switch (b.kind) {
      case OutputBinding::kCoil:
        couplers_[static_cast<std::size_t>(b.src)].out.coils[i] = (v.i != 0) != b.invert ? 1 : 0;
        break;
      case OutputBinding::kHoldingReg: {
        auto& regs = couplers_[static_cast<std::size_t>(b.src)].out.holding;
        switch (b.type) {
          case Type::kBool:
            if ((v.i != 0) != b.invert) regs[i] = static_cast<std::uint16_t>(regs[i] | (1u << b.bit));
            break;
          case Type::kDint: {
            const auto u = static_cast<std::uint32_t>(v.i);
            regs[i] = static_cast<std::uint16_t>(u >> 16);
            if (i + 1 < regs.size()) regs[i + 1] = static_cast<std::uint16_t>(u & 0xFFFFu);
            break;
          }
          case Type::kReal:
          case Type::kLreal:
            regs[i] = static_cast<std::uint16_t>(encode_scaled(v.r, b.scale, b.is_signed) & 0xFFFF);
            break;
          default:
            regs[i] = static_cast<std::uint16_t>(v.i & 0xFFFF);
            break;
        }
        break;
      }
      case OutputBinding::kGpio:
        gpio_out_.v[i] = v.i != 0 ? 1 : 0;
        break;
      case OutputBinding::kCia402: {
        const auto a = static_cast<std::size_t>(b.src);
        const std::uint32_t bit = 1u << b.bit;
        out.drive_output_mask[a] |= bit;
        if (v.i != 0) out.drive_outputs[a] |= bit;
        break;
      }
      case OutputBinding::kCia401Do: {
        auto& d = out.cia401[static_cast<std::size_t>(b.src)].digital[i];
        if (v.i != 0) d = static_cast<std::uint8_t>(d | (1u << b.bit));
        break;
      }
      case OutputBinding::kCia401Ao:
        out.cia401[static_cast<std::size_t>(b.src)].analog[i] = static_cast<std::int16_t>(
            cp::is_real(b.type) ? encode_scaled(v.r, b.scale, true) : std::clamp<std::int64_t>(v.i, -32768, 32767));
        break;
      case OutputBinding::kSim:
        sim_->set(static_cast<cp::PlantPoint>(b.index), v.i);
        break;
    }
  }
  for (auto& c : couplers_) c.dev->write(c.out);
  if (gpio_) gpio_->write(gpio_out_);
  out.cia401_count = cia401_count_;
  for (std::size_t k = 0; k < cia401_count_; ++k) out.cia401[k].node_id = cia401_nodes_[k];

  // Requests.
  using F = cfgns::NcField;
  auto req = [&](F f) { return slot_bool(nc_[static_cast<std::size_t>(f)]); };
  PlcRequests& r = out.requests;
  r.feed_hold = req(F::kFeedHoldReq);
  r.inhibit_start = req(F::kInhibitStart);
  const bool stop = req(F::kStopReq);
  r.stop = stop && !stop_req_prev_;
  stop_req_prev_ = stop;
  r.estop = req(F::kEstopReq);
  r.spindle_inhibit = req(F::kSpindleInhibit);
  r.fault = req(F::kFaultReq);
  const std::int32_t fc = nc_[static_cast<std::size_t>(F::kFaultCode)];
  r.fault_code = fc >= 0 ? static_cast<std::int32_t>(at(fc).i) : 0;
  for (std::size_t a = 0; a < kMaxAxes; ++a) r.axis_fault[a] = slot_bool(nc_axis_[2][a]);
  const std::int32_t mist = fixed_[static_cast<std::size_t>(cfgns::FixedRole::kCoolantMist)];
  const std::int32_t flood = fixed_[static_cast<std::size_t>(cfgns::FixedRole::kCoolantFlood)];
  out.coolant_mist = mist >= 0 ? slot_bool(mist) : in.coolant_mist;
  out.coolant_flood = flood >= 0 ? slot_bool(flood) : in.coolant_flood;
}

void PlcEngine::handshakes(std::uint64_t cycle, PlcCycleOutput& out) noexcept {
  using F = cfgns::NcField;
  auto step = [&](HandshakeState& h, F done_field, PlcFaultKind timeout_kind, double timeout_s) {
    const bool done = slot_bool(nc_[static_cast<std::size_t>(done_field)]);
    if (h.phase == Handshake::kPending && !done) {
      h.phase = Handshake::kWaiting;  // the request goes up at the next scan's inputs
      h.req = true;
    } else if (h.phase == Handshake::kWaiting && done) {
      h.phase = Handshake::kDone;
      h.req = false;
    }
    if ((h.phase == Handshake::kPending || h.phase == Handshake::kWaiting) &&
        cycle - h.started_cycle > h.timeout_cycles) {
      h.phase = Handshake::kTimedOut;
      h.req = false;
      latch({timeout_kind, -1, h.number, static_cast<double>(cycle - h.started_cycle) * static_cast<double>(period_ns_) * 1e-9,
             timeout_s},
            out);
    }
  };
  step(mcode_, F::kMcodeDone, PlcFaultKind::kMcodeTimeout,
       handles_mcode(mcode_.number) ? mcode_timeout_s_[static_cast<std::size_t>(mcode_.number)] : 0.0);
  step(tool_, F::kToolChangeDone, PlcFaultKind::kToolChangeTimeout, tool_change_timeout_s_);
}

bool PlcEngine::start_mcode(int m, double p, double q) noexcept {
  if (!handles_mcode(m) || mcode_.phase != Handshake::kIdle) return false;
  mcode_.phase = Handshake::kPending;
  mcode_.number = m;
  mcode_.p = std::isnan(p) ? 0.0 : p;
  mcode_.q = std::isnan(q) ? 0.0 : q;
  mcode_.req = false;
  mcode_.started_cycle = cycle_;
  mcode_.timeout_cycles = static_cast<std::uint64_t>(
      std::ceil(mcode_timeout_s_[static_cast<std::size_t>(m)] * 1e9 / static_cast<double>(period_ns_)));
  return true;
}

bool PlcEngine::start_tool_change(std::int32_t tool) noexcept {
  if (!tool_change_enabled_ || tool_.phase != Handshake::kIdle) return false;
  tool_.phase = Handshake::kPending;
  tool_.number = tool;
  tool_.req = false;
  tool_.started_cycle = cycle_;
  tool_.timeout_cycles = static_cast<std::uint64_t>(
      std::ceil(tool_change_timeout_s_ * 1e9 / static_cast<double>(period_ns_)));
  return true;
}

void PlcEngine::release_mcode() noexcept {
  mcode_.phase = Handshake::kIdle;
  mcode_.req = false;
}
void PlcEngine::release_tool_change() noexcept {
  tool_.phase = Handshake::kIdle;
  tool_.req = false;
}

void PlcEngine::latch(const PlcFault& f, PlcCycleOutput& out) noexcept {
  if (!out.fault) out.fault = f;
  if (latched_count_ < latched_.size()) latched_[latched_count_++] = f;
}

bool PlcEngine::causes_gone() const noexcept {
  using F = cfgns::NcField;
  if (slot_bool(nc_[static_cast<std::size_t>(F::kEstopReq)]) ||
      slot_bool(nc_[static_cast<std::size_t>(F::kFaultReq)]))
    return false;
  for (std::size_t a = 0; a < kMaxAxes; ++a)
    if (slot_bool(nc_axis_[2][a])) return false;
  for (const auto& c : couplers_)
    if (c.fault_latched && !c.ok) return false;
  return true;
}

void PlcEngine::reset() noexcept {
  for (auto& c : couplers_)
    if (c.ok) c.fault_latched = false;
  for (std::size_t p = 0; p < programs_.size(); ++p) {
    Program& prog = programs_[p];
    if (!prog.stopped) continue;
    const auto b = static_cast<std::size_t>(prog.base);
    std::copy(init_.begin() + static_cast<std::ptrdiff_t>(b),
              init_.begin() + static_cast<std::ptrdiff_t>(b + static_cast<std::size_t>(prog.compiled->locals)),
              mem_.begin() + static_cast<std::ptrdiff_t>(b));
    prog.stopped = false;
    stats_[p].state = 0;
  }
  // Keep only the coupler faults whose cause remains.
  std::size_t k = 0;
  for (std::size_t i = 0; i < latched_count_; ++i) {
    const PlcFault& f = latched_[i];
    if (f.kind == PlcFaultKind::kIoStale && couplers_[static_cast<std::size_t>(f.index)].fault_latched)
      latched_[k++] = f;
  }
  latched_count_ = k;
  if (mcode_.phase == Handshake::kTimedOut) release_mcode();
  if (tool_.phase == Handshake::kTimedOut) release_tool_change();
}

void PlcEngine::record(PlcScanStats& s, std::uint32_t ns, std::uint64_t instr, double budget_ns) noexcept {
  s.last_ns = ns;
  if (s.runs == 0 || ns < s.min_ns) s.min_ns = ns;
  if (ns > s.max_ns) s.max_ns = ns;
  s.recent_ns[s.runs % PlcScanStats::kRecent] = ns;
  ++s.runs;
  if (static_cast<double>(ns) > budget_ns) ++s.overruns;
  s.instructions_last = instr;
  s.instructions_max = std::max(s.instructions_max, instr);
}

void PlcEngine::publish() noexcept {
  Published& p = pub_[pub_back_];
  p.cycle = cycle_;
  std::copy(mem_.begin(), mem_.begin() + static_cast<std::ptrdiff_t>(entries_.size()), p.values.begin());
  std::copy(forced_.begin(), forced_.begin() + static_cast<std::ptrdiff_t>(entries_.size()), p.forced.begin());
  std::copy(stats_.begin(), stats_.end(), p.programs.begin());
  p.scan = scan_stats_;
  for (std::size_t d = 0; d < couplers_.size(); ++d) {
    p.device_state[d] = static_cast<std::uint8_t>(couplers_[d].reading.state);
    p.device_age_ns[d] = couplers_[d].reading.age_ns;
  }
  p.mcode = mcode_.phase;
  p.mcode_number = mcode_.number;
  p.tool = tool_.phase;
  p.tool_number = tool_.number;
  std::copy(latched_.begin(), latched_.begin() + static_cast<std::ptrdiff_t>(latched_count_), p.faults.begin());
  p.nfaults = latched_count_;
  const std::uint8_t prev =
      pub_middle_.exchange(static_cast<std::uint8_t>(pub_back_ | kDirty), std::memory_order_acq_rel);
  pub_back_ = prev & kIndex;
}

// ---- non-RT -----------------------------------------------------------------------------------
namespace {
std::optional<Cell> parse_value(Type t, const std::string& text, std::string& why) {
  const std::string u = cp::upper(text);
  try {
    std::size_t used = 0;
    switch (t) {
      case Type::kBool:
        if (u == "TRUE" || u == "1" || u == "ON") return cp::int_cell(1);
        if (u == "FALSE" || u == "0" || u == "OFF") return cp::int_cell(0);
        why = "a BOOL is TRUE or FALSE (1 or 0)";
        return std::nullopt;
      case Type::kInt:
      case Type::kDint: {
        const long long v = std::stoll(text, &used, 0);
        const long long lo = t == Type::kInt ? -32768 : -2147483648LL;
        const long long hi = t == Type::kInt ? 32767 : 2147483647LL;
        if (used != text.size() || v < lo || v > hi) {
          why = std::string("an ") + cp::type_name(t) + " in " + std::to_string(lo) + ".." + std::to_string(hi);
          return std::nullopt;
        }
        return cp::int_cell(v);
      }
      case Type::kReal:
      case Type::kLreal: {
        const double v = std::stod(text, &used);
        if (used != text.size() || !std::isfinite(v)) {
          why = "a finite number";
          return std::nullopt;
        }
        return cp::normalise(t, cp::real_cell(v));
      }
      case Type::kTime: {  // T#2.5s / 2500 (ms) / 2.5s / 100ms
        std::string s = u.rfind("T#", 0) == 0 ? u.substr(2) : u;
        const double v = std::stod(s, &used);
        const std::string unit = s.substr(used);
        double scale = 1e6;
        if (unit == "S") scale = 1e9;
        else if (unit == "MS" || unit.empty()) scale = 1e6;
        else if (unit == "M") scale = 60e9;
        else if (unit == "H") scale = 3600e9;
        else {
          why = "a TIME as T#2.5s, T#100ms or milliseconds";
          return std::nullopt;
        }
        return cp::int_cell(std::llround(v * scale));
      }
      default:
        break;
    }
  } catch (const std::exception&) {
    why = std::string("not a ") + cp::type_name(t) + " value";
  }
  if (why.empty()) why = "bad value";
  return std::nullopt;
}
}  // namespace

std::string PlcEngine::force(const std::string& name, const std::string& value) {
  if (!forcing_allowed_)
    return "forcing is allowed only on the sim bus or with plc.allow_forcing: true";
  const int slot = find(name);
  if (slot < 0) return "unknown signal '" + name + "'";
  const cfgns::PlcImageEntry& e = entries_[static_cast<std::size_t>(slot)];
  if (e.kind != cfgns::PlcEntryKind::kSignal)
    return "'" + e.name + "' is " +
           (e.kind == cfgns::PlcEntryKind::kNc ? "an NC signal" : "a fixed role owned by the NC") +
           ": only plc.signals entries can be forced";
  std::string why;
  const auto v = parse_value(e.type, value, why);
  if (!v) return "'" + e.name + "' is " + cp::type_name(e.type) + ": '" + value + "' is not " + why;
  std::lock_guard lk(force_mu_);
  if (!force_ring_.push({slot, true, *v})) return "force queue full; try again";
  if (log_) log_("plc: FORCED " + e.name + " = " + value);
  return {};
}

std::string PlcEngine::unforce(const std::string& name) {
  int slot = -1;
  if (name != "*" && name != "all") {
    slot = find(name);
    if (slot < 0) return "unknown signal '" + name + "'";
  }
  std::lock_guard lk(force_mu_);
  if (!force_ring_.push({slot, false, {}})) return "force queue full; try again";
  if (log_) log_("plc: unforced " + (slot < 0 ? std::string("every signal") : entries_[static_cast<std::size_t>(slot)].name));
  return {};
}

PlcSnapshot PlcEngine::snapshot() const {
  std::lock_guard lk(snapshot_mu_);
  if (pub_middle_.load(std::memory_order_relaxed) & kDirty) {
    const std::uint8_t prev = pub_middle_.exchange(pub_front_, std::memory_order_acq_rel);
    pub_front_ = prev & kIndex;
  }
  const Published& p = pub_[pub_front_];
  const cfgns::PlcConfig& pc = cfg_.plc;
  PlcSnapshot s;
  s.cycle = p.cycle;
  s.forcing_allowed = forcing_allowed_;
  for (std::size_t i = 0; i < entries_.size(); ++i) {
    const cfgns::PlcImageEntry& e = entries_[i];
    PlcSignalView v;
    v.name = e.name;
    v.type = e.type;
    v.value = p.values[i];
    v.forced = p.forced[i] != 0;
    if (e.kind == cfgns::PlcEntryKind::kSignal) {
      const cfgns::PlcSignalConfig& sc = pc.signals[static_cast<std::size_t>(e.index)];
      v.forceable = true;
      v.description = sc.description;
      v.direction = sc.direction == cfgns::PlcDirection::kInput    ? "input"
                    : sc.direction == cfgns::PlcDirection::kOutput ? "output"
                                                                   : "memory";
      const cfgns::PlcBinding& b = sc.binding;
      switch (b.kind) {
        case cfgns::PlcBindingKind::kMemory:
          v.source = "memory";
          break;
        case cfgns::PlcBindingKind::kGpio:
          v.source = "gpio " + b.line.describe();
          break;
        case cfgns::PlcBindingKind::kModbus: {
          static const char* const kTab[] = {"coil", "di", "hr", "ir"};
          v.source = "modbus " + pc.modbus[static_cast<std::size_t>(b.device)].name + " " +
                     kTab[static_cast<int>(b.table)] + " " + std::to_string(b.address) +
                     (b.bit >= 0 ? "." + std::to_string(b.bit) : std::string());
          break;
        }
        case cfgns::PlcBindingKind::kCia402:
          // "axis x 0x60FD bit 1": the drive of machine.axes' axis, the object and its bit.
          v.source = "axis " + lower(b.axis_name) +
                     (sc.direction == cfgns::PlcDirection::kInput ? " 0x60FD" : " 0x60FE:01") +
                     " bit " + std::to_string(b.bit);
          break;
        case cfgns::PlcBindingKind::kCia401: {
          char idx[16];
          std::snprintf(idx, sizeof idx, "0x%04X:%02X", cfgns::cia401_index(b.object), b.address);
          v.source = "cia401 node " + std::to_string(b.node_id) + " " + idx +
                     (b.bit >= 0 ? " bit " + std::to_string(b.bit) : std::string());
          break;
        }
        case cfgns::PlcBindingKind::kSim:
          v.source = std::string("sim ") + cp::plant_point(b.point).name;
          break;
      }
    } else if (e.kind == cfgns::PlcEntryKind::kNc) {
      const cfgns::NcFieldInfo& f = cfgns::nc_field(static_cast<cfgns::NcField>(e.index));
      v.direction = f.request ? "nc_request" : "nc_status";
      v.source = "NC";
      v.description = f.what;
    } else {
      const auto role = static_cast<cfgns::FixedRole>(e.index);
      const bool coolant = role == cfgns::FixedRole::kCoolantMist || role == cfgns::FixedRole::kCoolantFlood;
      v.direction = coolant ? "output" : role == cfgns::FixedRole::kEstop ? "input" : "nc_owned";
      v.source = "gpio role " + e.name;
      v.description = coolant ? "follows the NC's M7/M8/M9 unless a program writes it"
                              : "owned by the NC (read-only)";
    }
    s.signals.push_back(std::move(v));
  }
  auto median_us = [](const PlcScanStats& st) {
    const std::size_t n = std::min<std::uint64_t>(st.runs, PlcScanStats::kRecent);
    if (n == 0) return 0.0;
    std::vector<std::uint32_t> v(st.recent_ns.begin(), st.recent_ns.begin() + static_cast<std::ptrdiff_t>(n));
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(n / 2), v.end());
    return static_cast<double>(v[n / 2]) * 1e-3;
  };
  for (std::size_t i = 0; i < programs_.size(); ++i) {
    PlcProgramView pv;
    pv.name = programs_[i].compiled->name;
    pv.file = pc.programs[i].path;
    pv.period_cycles = programs_[i].period;
    pv.worst_case = programs_[i].compiled->worst_case;
    pv.stats = p.programs[i];
    pv.median_us = median_us(pv.stats);
    s.programs.push_back(std::move(pv));
  }
  s.scan = p.scan;
  s.scan_median_us = median_us(p.scan);
  for (std::size_t d = 0; d < couplers_.size(); ++d) {
    PlcDeviceView dv;
    dv.name = pc.modbus[d].name;
    const auto& t = pc.modbus[d].transport;
    dv.endpoint = t.transport == dm::Transport::kTcp ? t.host + ":" + std::to_string(t.port) : t.device;
    dv.state = dm::to_string(static_cast<dm::CouplerState>(p.device_state[d]));
    dv.age_s = static_cast<double>(p.device_age_ns[d]) * 1e-9;
    dv.status = couplers_[d].dev->status();
    s.devices.push_back(std::move(dv));
  }
  s.mcode = p.mcode;
  s.mcode_number = p.mcode_number;
  s.tool_change = p.tool;
  s.tool_number = p.tool_number;
  s.faults.assign(p.faults.begin(), p.faults.begin() + static_cast<std::ptrdiff_t>(p.nfaults));
  return s;
}

}  // namespace contour::daemon
