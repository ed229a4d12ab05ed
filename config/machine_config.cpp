#include "config/machine_config.hpp"

#include <cmath>
#include <sstream>

namespace contour::config {

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
    for (const auto& other : m.axes) {
      if (other.name == ax.name) a.error("name", "axis " + ax.name + " is defined twice");
    }
    m.axes.push_back(ax);
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
