#include "config/dynamometer_config.hpp"

#include <chrono>

namespace contour::config {

namespace dm = drivers::modbus;

namespace {

dm::RegisterType parse_type(const std::string& t) {
  if (t == "int16") return dm::RegisterType::kInt16;
  if (t == "uint16") return dm::RegisterType::kUint16;
  if (t == "int32") return dm::RegisterType::kInt32;
  return dm::RegisterType::kFloat32;
}

dm::WordOrder parse_order(const std::string& o) {
  if (o == "badc") return dm::WordOrder::kBadc;
  if (o == "cdab") return dm::WordOrder::kCdab;
  if (o == "dcba") return dm::WordOrder::kDcba;
  return dm::WordOrder::kAbcd;
}

dm::ChannelMap parse_channel(Section& c) {
  dm::ChannelMap ch;
  ch.enabled = true;
  ch.address = static_cast<std::uint16_t>(c.required_integer("address", 0, 65534));
  ch.type = parse_type(c.choice("type", "float32", {"int16", "uint16", "int32", "float32"}));
  ch.order = parse_order(c.choice("word_order", "abcd", {"abcd", "badc", "cdab", "dcba"}));
  ch.scale = c.number("scale", 1.0);
  if (ch.scale == 0.0) c.error("scale", "must not be 0");
  ch.offset_N = c.number("offset_n", 0.0);
  if (ch.address + dm::register_count(ch.type) > 65536u)
    c.error("address", "value runs past 65535");
  return ch;
}

}  // namespace

DynamometerConfig parse_dynamometer(Section& s) {
  DynamometerConfig cfg;
  if (!s.present()) return cfg;
  cfg.enabled = s.boolean("enabled", true);
  dm::DynamometerSettings& r = cfg.reader;
  dm::TransportSettings& t = r.transport;
  const std::string transport = s.choice("transport", "tcp", {"tcp", "rtu"});
  t.transport = transport == "tcp" ? dm::Transport::kTcp : dm::Transport::kRtu;
  t.host = s.string("host", "127.0.0.1");
  t.port = static_cast<int>(s.integer("port", 502, 1, 65535));
  t.device = s.string("device", "/dev/ttyUSB0");
  t.baud = static_cast<int>(s.integer("baud", 115200, 1200, 4000000));
  const std::string parity = s.choice("parity", "none", {"none", "even", "odd"});
  t.parity = parity == "none" ? 'N' : parity == "even" ? 'E' : 'O';
  t.unit_id = static_cast<int>(s.integer("unit_id", 1, 0, 247));
  if (transport == "rtu" && t.unit_id == 0) s.error("unit_id", "RTU unit id must be 1..247");
  if (transport == "tcp" && s.has("device")) s.error("device", "only for transport: rtu");
  if (transport == "rtu" && s.has("host")) s.error("host", "only for transport: tcp");
  t.response_timeout = std::chrono::microseconds(
      static_cast<long>(1000.0 * s.number("timeout_ms", 20.0, 1.0, 5000.0)));

  r.map.function = s.choice("function", "input", {"input", "holding"}) == "input"
                       ? dm::RegisterFunction::kInput
                       : dm::RegisterFunction::kHolding;
  {
    Section ch = s.child("channels");
    if (!ch.present()) s.error("channels", "at least one of fx, fy, fz is required");
    const char* names[] = {"fx", "fy", "fz"};
    for (std::size_t i = 0; i < dm::kForceChannels; ++i) {
      if (!ch.has(names[i])) {
        ch.accept(names[i]);
        continue;
      }
      Section c = ch.child(names[i]);
      r.map.channels[i] = parse_channel(c);
    }
  }
  if (s.has("status")) {
    Section st = s.child("status");
    r.map.status.enabled = true;
    r.map.status.address = static_cast<std::uint16_t>(st.required_integer("address", 0, 65535));
    r.map.status.valid_bit = static_cast<unsigned>(st.integer("valid_bit", 0, 0, 15));
    r.map.status.valid_when_set = st.choice("valid_when", "set", {"set", "clear"}) == "set";
  } else {
    s.accept("status");
  }
  const dm::RegisterBlock block = dm::register_block(r.map);
  if (block.count > dm::kMaxBlockRegisters)
    s.error("channels", "channels and status span " + std::to_string(block.count) +
                            " registers; they must lie within " +
                            std::to_string(dm::kMaxBlockRegisters) + " consecutive registers");

  r.poll_rate_hz = s.number("poll_rate_hz", 200.0, 1.0, 2000.0);
  const double period_ms = 1000.0 / r.poll_rate_hz;
  r.stale_after = std::chrono::microseconds(static_cast<long>(
      1000.0 * s.number("stale_ms", std::max(50.0, 4.0 * period_ms), 1.0, 10000.0)));
  if (r.stale_after.count() < static_cast<long>(1000.0 * period_ms))
    s.error("stale_ms", "must be at least one poll period (" + std::to_string(period_ms) + " ms)");
  r.reconnect_min = std::chrono::milliseconds(s.integer("reconnect_min_ms", 50, 1, 60000));
  r.reconnect_max = std::chrono::milliseconds(s.integer("reconnect_max_ms", 2000, 1, 600000));
  if (r.reconnect_max < r.reconnect_min) s.error("reconnect_max_ms", "must be >= reconnect_min_ms");

  dm::ForceFilterSettings& f = r.filter;
  f.sample_rate_hz = r.poll_rate_hz;
  {
    Section fs = s.child("filter");
    r.filter_enabled = fs.boolean("enabled", true);
    f.moving_average = fs.boolean("moving_average", true);
    f.teeth = static_cast<int>(fs.integer("teeth", 4, 1, 64));
    f.min_spindle_rpm = fs.number("min_spindle_rpm", 100.0, 1.0, 1e6);
    f.butterworth_order = static_cast<int>(fs.integer("butterworth_order", 2, 0, 4));
    if (f.butterworth_order == 1 || f.butterworth_order == 3)
      fs.error("butterworth_order", "must be 0 (off), 2 or 4");
    f.cutoff_hz = fs.number("cutoff_hz", 10.0, 0.01, 1e6);
    if (f.butterworth_order != 0 && f.cutoff_hz >= 0.45 * f.sample_rate_hz)
      fs.error("cutoff_hz", "must be below 0.45 * poll_rate_hz (" +
                                std::to_string(0.45 * f.sample_rate_hz) + " Hz)");
    const double window = f.sample_rate_hz * 60.0 / (f.teeth * f.min_spindle_rpm);
    if (f.moving_average && window > 100000)
      fs.error("min_spindle_rpm", "tooth period at this speed exceeds 100000 samples");
  }
  return cfg;
}

}  // namespace contour::config
