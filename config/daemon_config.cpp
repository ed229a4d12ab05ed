#include "config/daemon_config.hpp"

namespace contour::config {

LoopConfig parse_loop(Section& s) {
  LoopConfig c;
  c.period_us = static_cast<int>(s.integer("period_us", 1000, 125, 20000));
  c.priority = static_cast<int>(s.integer("priority", 80, 0, 99));
  c.cpu = static_cast<int>(s.integer("cpu", -1, -1, 1023));
  c.require_realtime = s.boolean("require_realtime", false);
  c.lock_memory = s.boolean("lock_memory", true);
  c.tpdo_deadline_us = static_cast<int>(s.integer("tpdo_deadline_us", 750, 50, 20000));
  if (c.tpdo_deadline_us >= c.period_us) {
    s.error("tpdo_deadline_us", "must be shorter than period_us");
  }
  return c;
}

SafetyConfig parse_safety(Section& s) {
  SafetyConfig c;
  c.ferror_mm = s.number("ferror_mm", 1.0, 1e-4, 100.0);
  c.min_ferror_mm = s.number("min_ferror_mm", 0.1, 1e-4, 100.0);
  if (c.min_ferror_mm > c.ferror_mm) s.error("min_ferror_mm", "must not exceed ferror_mm");
  c.contour_error_limit_mm = s.number("contour_error_limit_mm", 0.5, 1e-4, 100.0);
  c.missed_tpdo_streak = static_cast<int>(s.integer("missed_tpdo_streak", 3, 1, 1000));
  c.stop_decel_mm_s2 = s.number("stop_decel_mm_s2", 1000.0, 1.0, 1e6);
  c.jog_max_velocity_mm_min = s.number("jog_max_velocity_mm_min", 3000.0, 1.0, 1e6);
  c.jog_deadman_ms = s.number("jog_deadman_ms", 500.0, 50.0, 10000.0);
  c.standstill_velocity_mm_s = s.number("standstill_velocity_mm_s", 1.0, 1e-3, 100.0);
  c.standstill_time_s = s.number("standstill_time_s", 0.05, 0.0, 10.0);
  c.standstill_timeout_s = s.number("standstill_timeout_s", 2.0, 0.01, 60.0);
  if (c.standstill_timeout_s <= c.standstill_time_s)
    s.error("standstill_timeout_s", "must be longer than standstill_time_s");
  if (s.has("chatter")) {
    Section ch = s.child("chatter");
    auto& w = c.chatter;
    w.enable = ch.boolean("enable", true);
    w.window_s = ch.number("window_ms", 100.0, 10.0, 10000.0) / 1e3;
    w.warn_mm_s = ch.number("warn_mm_s", 5.0, 1e-3, 1e5);
    w.warn_clamps_per_s = ch.number("warn_clamps_per_s", 50.0, 1e-3, 1e6);
    w.warn_s = ch.number("warn_ms", 250.0, 0.0, 60000.0) / 1e3;
    w.fault_mm_s = ch.number("fault_mm_s", 40.0, 1e-3, 1e5);
    w.fault_clamps_per_s = ch.number("fault_clamps_per_s", 300.0, 1e-3, 1e6);
    w.fault_s = ch.number("fault_ms", 500.0, 0.0, 60000.0) / 1e3;
    if (w.fault_mm_s < w.warn_mm_s) ch.error("fault_mm_s", "must not be below warn_mm_s");
    if (w.fault_clamps_per_s < w.warn_clamps_per_s) {
      ch.error("fault_clamps_per_s", "must not be below warn_clamps_per_s");
    }
  }
  return c;
}

TelemetryConfig parse_telemetry(Section& s) {
  TelemetryConfig c;
  c.directory = s.string("directory", c.directory);
  c.decimation = static_cast<int>(s.integer("decimation", 1, 1, 10000));
  c.ring_capacity = static_cast<int>(s.integer("ring_capacity", 65536, 64, 1 << 24));
  if ((c.ring_capacity & (c.ring_capacity - 1)) != 0) {
    s.error("ring_capacity", "must be a power of two");
  }
  return c;
}

SocketConfig parse_socket(Section& s) {
  SocketConfig c;
  c.path = s.string("path", c.path);
  if (c.path.empty() || c.path.size() > 107) s.error("path", "must be 1..107 characters");
  if (s.has("mode")) {
    // Accept "0660" (octal string) or a number written in octal digits (660 / 0660).
    const std::string m = s.string("mode", "0660");
    int v = 0;
    bool ok = !m.empty() && m.size() <= 4;  // checked before the loop: no int overflow
    for (std::size_t i = 0; ok && i < m.size(); ++i) {
      const char ch = m[i];
      if (ch < '0' || ch > '7') ok = false;
      v = v * 8 + (ch - '0');
    }
    if (!ok) {
      s.error("mode", "expected an octal permission like \"0660\"");
    } else if ((v & 0007) != 0) {
      s.error("mode", "must not give 'other' any access (the socket controls the machine)");
    } else {
      c.mode = v;
    }
  }
  c.group = s.string("group", "");
  c.max_clients = static_cast<int>(s.integer("max_clients", 16, 1, 1024));
  c.max_line_bytes = static_cast<int>(s.integer("max_line_bytes", 65536, 256, 16 << 20));
  c.idle_timeout_s = s.number("idle_timeout_s", 60.0, 0.1, 86400.0);
  c.max_requests_per_s = static_cast<int>(s.integer("max_requests_per_s", 500, 1, 100000));
  c.max_buffered_bytes =
      static_cast<int>(s.integer("max_buffered_bytes", 4 << 20, 64 << 10, 1 << 30));
  c.max_program_bytes = static_cast<long>(s.integer("max_program_bytes", 16L << 20, 1024, 1L << 30));
  return c;
}

LogConfig parse_log(Section& s) {
  LogConfig c;
  c.level = s.choice("level", "info", {"trace", "debug", "info", "warn", "error"});
  c.journald_format = s.boolean("journald_format", false);
  return c;
}

}  // namespace contour::config
