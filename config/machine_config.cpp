#include "config/machine_config.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace contour::config {

namespace {

void parse_home(Section& a, AxisConfig& ax) {
  Section h = a.child("home");
  HomeConfig& c = ax.home;
  if (!h.present()) {
    h.finish();
    return;
  }
  c.present = true;
  const std::string method = h.choice("method", "switch", {"switch", "drive", "absolute", "none"});
  c.method = method == "absolute" ? HomeConfig::Method::kAbsolute
             : method == "none"   ? HomeConfig::Method::kNone
             : method == "drive"  ? HomeConfig::Method::kDrive
                                  : HomeConfig::Method::kSwitch;
  const double vmax = ax.max_velocity_mm_min;
  c.home_offset_mm = h.number("home_offset_mm", 0.0, -1e6, 1e6);
  c.sequence = static_cast<int>(h.integer("sequence", 0, 0, 9));
  c.unhomed_jog_mm_s = h.number("unhomed_jog_mm_min", 600.0, 1.0, vmax) / 60.0;
  if (c.method == HomeConfig::Method::kSwitch) {
    c.search_vel_mm_s = h.required_number("search_vel_mm_min", -vmax, vmax) / 60.0;
    c.latch_vel_mm_s = h.required_number("latch_vel_mm_min", -vmax, vmax) / 60.0;
    if (c.search_vel_mm_s == 0.0) h.error("search_vel_mm_min", "must not be 0 (its sign is the search direction)");
    if (c.latch_vel_mm_s == 0.0) h.error("latch_vel_mm_min", "must not be 0");
    if (std::abs(c.latch_vel_mm_s) > std::abs(c.search_vel_mm_s)) {
      h.error("latch_vel_mm_min", "must not be faster than search_vel_mm_min");
    }
    const double range = ax.max_mm - ax.min_mm;
    c.search_distance_mm = h.number("search_distance_mm", 1.2 * range, 0.001, 1e6);
    c.home_position_mm = h.number("home_position_mm", c.home_offset_mm, ax.min_mm, ax.max_mm);
    c.use_index = h.boolean("use_index", false);
  } else if (c.method == HomeConfig::Method::kDrive) {
    c.drive_method = static_cast<int>(h.required_integer("drive_method", -128, 127));
    if (!drive_method_supported(c.drive_method)) {
      h.error("drive_method",
              std::to_string(c.drive_method) +
                  " is not a CiA 402 homing method (0x6098) contourd supports: 17/18 limit switch, "
                  "19..22 home switch, 33/34 index, 35/37 current position");
    }
    const bool moves = c.drive_method != 35 && c.drive_method != 37;
    // The drive's speeds: magnitudes (the method decides the direction); 0 only without motion.
    c.search_vel_mm_s = std::abs(h.number("search_vel_mm_min", moves ? 0.0 : 60.0, -vmax, vmax)) / 60.0;
    c.latch_vel_mm_s = std::abs(h.number("latch_vel_mm_min", moves ? 0.0 : 60.0, -vmax, vmax)) / 60.0;
    if (moves && c.search_vel_mm_s == 0.0) h.error("search_vel_mm_min", "required and not 0 for drive_method " + std::to_string(c.drive_method) + " (the drive's 0x6099:01)");
    if (moves && c.latch_vel_mm_s == 0.0) h.error("latch_vel_mm_min", "required and not 0 for drive_method " + std::to_string(c.drive_method) + " (the drive's 0x6099:02)");
    if (c.latch_vel_mm_s > c.search_vel_mm_s) h.error("latch_vel_mm_min", "must not be faster than search_vel_mm_min");
    c.drive_accel_mm_s2 = h.number("accel_mm_s2", std::min(500.0, ax.max_accel_mm_s2), 0.001, ax.max_accel_mm_s2);
    c.drive_timeout_s = h.number("drive_timeout_s", 60.0, 0.1, 3600.0);
    c.home_position_mm = h.number("home_position_mm", c.home_offset_mm, ax.min_mm, ax.max_mm);
    if (h.boolean("use_index", false)) h.error("use_index", "method drive: choose an index method in drive_method (33/34) instead");
  } else {
    if (h.boolean("use_index", false)) h.error("use_index", "needs method switch (the index follows the switch)");
    // No motion: the axis is where its encoder says (absolute) or nowhere known (none).
    c.home_position_mm = c.home_offset_mm;
  }
  h.finish();
}

}  // namespace

bool drive_method_supported(int method) noexcept {
  for (const int m : kDriveMethods) {
    if (m == method) return true;
  }
  return false;
}

MachineConfig parse_machine(Section& s, double period_s) {
  MachineConfig m;
  m.period_s = period_s;
  const char* default_names[] = {"X", "Y", "Z"};
  if (!s.present()) {
    // No machine section: the seed-000 Table 1 machine (X, Y, Z with the simulated drives'
    // defaults), so tools that only need another section still run on a sane machine.
    for (int i = 0; i < 3; ++i) {
      AxisConfig ax;
      ax.name = default_names[i];
      ax.drive.gain_per_s = i == 2 ? 115.0 : 120.0;
      ax.drive.tau_s = i == 2 ? 0.025 : 0.030;
      ax.drive.blu_mm = 0.0005;
      ax.drive.delay_cycles = 1;
      ax.drive.period_s = period_s;
      m.axes.push_back(ax);
    }
    return m;
  }
  auto axes = s.list("axes");
  if (axes.empty() || axes.size() > 3) s.error("axes", "expected a list of 1 to 3 axes");
  for (std::size_t i = 0; i < axes.size(); ++i) {
    Section& a = axes[i];
    AxisConfig ax;
    ax.name = a.choice("name", i < 3 ? default_names[i] : "X", {"X", "Y", "Z"});
    ax.node_id = static_cast<int>(a.integer("node_id", 0, 0, 127));
    ax.counts_per_mm = a.number("counts_per_mm", 2000.0, 1e-3, 1e9);
    ax.min_mm = a.number("min_mm", -1000.0, -1e6, 1e6);
    ax.max_mm = a.number("max_mm", 1000.0, -1e6, 1e6);
    if (ax.max_mm <= ax.min_mm) a.error("max_mm", "must be greater than min_mm");
    ax.max_velocity_mm_min = a.number("max_velocity_mm_min", 10000.0, 1.0, 1e6);
    ax.max_accel_mm_s2 = a.number("max_accel_mm_s2", 2000.0, 1.0, 1e6);
    Section d = a.child("sim");
    ax.drive.gain_per_s = d.number("gain_per_s", i == 2 ? 115.0 : 120.0, 1e-3, 1e5);
    ax.drive.tau_s = d.number("tau_ms", i == 2 ? 25.0 : 30.0, 0.0, 10000.0) / 1000.0;
    ax.drive.blu_mm = d.number("blu_um", 0.5, 0.0, 1000.0) / 1000.0;
    ax.drive.delay_cycles =
        static_cast<int>(d.integer("delay_cycles", 1, 0, control::FeedDrive::kMaxDelay));
    ax.drive.period_s = m.period_s;
    ax.sim_power_up_mm = d.number("power_up_mm", 0.0, -1e6, 1e6);
    ax.sim_index_pitch_mm = d.number("index_pitch_mm", 0.0, 0.0, 1e6);
    ax.sim_index_phase_mm = d.number("index_phase_mm", 0.0, -1e6, 1e6);
    d.finish();
    Section idf = a.child("identified");
    if (idf.present()) {
      ax.identified.present = true;
      ax.identified.gain_per_s = idf.required_number("gain_per_s", 1e-3, 1e5);
      ax.identified.tau_s = idf.required_number("tau_ms", 0.0, 10000.0) / 1000.0;
      ax.identified.delay_cycles = static_cast<int>(
          idf.required_integer("delay_cycles", 0, control::FeedDrive::kMaxDelay));
      ax.identified.date = idf.string("date", "");
    }
    idf.finish();
    parse_home(a, ax);
    for (const auto& other : m.axes) {
      if (other.name == ax.name) a.error("name", "axis " + ax.name + " is defined twice");
    }
    m.axes.push_back(ax);
  }
  bool any_home = false;
  for (const auto& ax : m.axes) any_home = any_home || ax.home.present;
  m.allow_unhomed = s.boolean("allow_unhomed", !any_home);
  if (!m.allow_unhomed) {
    for (std::size_t i = 0; i < m.axes.size(); ++i) {
      if (m.axes[i].home.method != HomeConfig::Method::kNone) continue;
      axes[i].error(m.axes[i].home.present ? "home" : "name",
                    "axis " + m.axes[i].name +
                        " has no homing (home.method none or no home: section): give it a home "
                        "method or set machine.allow_unhomed: true (programs then run unhomed)");
    }
  }
  return m;
}

std::vector<std::string> identification_warnings(const MachineConfig& m) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < m.axes.size(); ++i) {
    const AxisConfig& a = m.axes[i];
    if (!a.identified.present) continue;
    const std::string where = "machine.axes[" + std::to_string(i) + "] (" + a.name + ")";
    const std::string when = a.identified.date.empty() ? "" : " on " + a.identified.date;
    if (a.identified.delay_cycles != a.drive.delay_cycles) {
      out.push_back(where + ": the drive's transport delay was measured as " +
                    std::to_string(a.identified.delay_cycles) + " cycles" + when +
                    ", but sim.delay_cycles is " + std::to_string(a.drive.delay_cycles) +
                    ": the Smith predictor assumes the configured delay (identify the axis again "
                    "or correct delay_cycles; control/CHATTER.md)");
    }
    const double k_dev = a.identified.gain_per_s / a.drive.gain_per_s - 1.0;
    if (std::abs(k_dev) > 0.05) {
      std::ostringstream o;
      o << where << ": the drive's gain was measured as " << a.identified.gain_per_s << " 1/s" << when
        << ", sim.gain_per_s is " << a.drive.gain_per_s << " (" << (k_dev > 0 ? "+" : "")
        << std::lround(k_dev * 100.0) << " %)";
      out.push_back(o.str());
    }
    if (a.drive.tau_s > 0.0) {
      const double t_dev = a.identified.tau_s / a.drive.tau_s - 1.0;
      if (std::abs(t_dev) > 0.10) {
        std::ostringstream o;
        o << where << ": the drive's time constant was measured as " << a.identified.tau_s * 1e3
          << " ms" << when << ", sim.tau_ms is " << a.drive.tau_s * 1e3 << " ("
          << (t_dev > 0 ? "+" : "") << std::lround(t_dev * 100.0) << " %)";
        out.push_back(o.str());
      }
    }
  }
  return out;
}

}  // namespace contour::config
