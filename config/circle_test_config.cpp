#include "config/circle_test_config.hpp"

namespace contour::config {

namespace {
CircleTestConfig parse_root(const YAML::Node& root, const std::string& name,
                            const std::string& base_dir) {
  Diagnostics diag(name);
  CircleTestConfig c;
  {
    Section top(root, "", diag);
    if (!top.present()) diag.error(root, "", "empty circle-test configuration");
    const double period_s = top.number("period_us", 1000.0, 125.0, 20000.0) * 1e-6;
    Section axes = top.child("axes");
    const char* names[] = {"X", "Y"};
    for (std::size_t i = 0; i < 2; ++i) {
      if (!axes.has(names[i])) {
        axes.error(names[i], std::string("axis ") + names[i] + " is required");
        continue;
      }
      Section a = axes.child(names[i]);
      auto& ax = c.axes[i];
      ax.drive.gain_per_s = a.required_number("gain_per_s", 1e-3, 1e5);
      ax.position_gain = a.number("position_gain", 1.0, 1e-6, 1e6);
      ax.drive.tau_s = a.number("tau_ms", 10.0, 0.0, 10000.0) / 1000.0;
      ax.drive.blu_mm = a.number("blu_um", 0.1, 0.0, 1000.0) / 1000.0;
      ax.drive.delay_cycles =
          static_cast<int>(a.integer("delay_cycles", 0, 0, control::FeedDrive::kMaxDelay));
      ax.drive.period_s = period_s;
      a.finish();
    }
    axes.finish();
    Section t = top.child("test");
    c.radius_mm = t.number("radius_mm", 100.0, 0.1, 10000.0);
    c.feed_mm_min = t.number("feed_mm_min", 3000.0, 1.0, 200000.0);
    c.direction = t.choice("direction", "cw", {"cw", "ccw", "both"});
    if (t.has("center_mm")) {
      const auto v = t.numbers("center_mm", 2, 2);
      if (v.size() == 2) c.center_mm = {v[0], v[1]};
    } else {
      t.accept("center_mm");
    }
    c.z_mm = t.number("z_mm", 0.0, -1e5, 1e5);
    c.noise_um = t.number("noise_um", 0.1, 0.0, 1000.0);
    c.seed = t.integer("seed", 1, 0, 1L << 40);
    c.revolutions = static_cast<int>(t.integer("revolutions", 1, 1, 20));
    const std::string g = t.string("geometry", "");
    if (!g.empty()) c.geometry_file = (g.front() == '/' || base_dir.empty()) ? g : base_dir + "/" + g;
    t.finish();
  }
  diag.throw_if_any();
  return c;
}
}  // namespace

CircleTestConfig load_circle_test_config(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash);
  return parse_root(load_yaml_file(path), path, dir);
}

CircleTestConfig load_circle_test_config_string(const std::string& text, const std::string& name) {
  return parse_root(load_yaml_string(text, name), name, "");
}

}  // namespace contour::config
