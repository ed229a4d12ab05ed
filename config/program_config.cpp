#include "config/program_config.hpp"

#include <string>

namespace contour::config {

namespace {
std::array<double, 3> vec3(Section& s, const std::string& key) {
  std::array<double, 3> v{};
  if (!s.has(key)) {
    s.accept(key);
    return v;
  }
  const auto n = s.numbers(key, 3, 3);
  for (std::size_t i = 0; i < 3 && i < n.size(); ++i) v[i] = n[i];
  return v;
}
}  // namespace

ProgramConfig parse_program(Section& s) {
  ProgramConfig c;
  {
    Section w = s.child("work_offsets");
    static const char* kNames[6] = {"G54", "G55", "G56", "G57", "G58", "G59"};
    for (std::size_t i = 0; i < 6; ++i) c.work_offsets_mm[i] = vec3(w, kNames[i]);
    w.finish();
  }
  for (auto& t : s.list("tools")) {
    control::ToolEntry e;
    e.number = static_cast<int>(t.required_integer("number", 0, 99999));
    e.length_mm = t.required_number("length_mm", -1000.0, 1000.0);
    for (const auto& o : c.tools)
      if (o.number == e.number) t.error("number", "tool " + std::to_string(e.number) + " is defined twice");
    c.tools.push_back(e);
    t.finish();
  }
  c.g28_mm = vec3(s, "g28_mm");
  c.g30_mm = vec3(s, "g30_mm");
  c.start_mm = vec3(s, "start_mm");
  c.rapid_mm_min = s.number("rapid_mm_min", c.rapid_mm_min, 1.0, 1e6);
  c.arc_tolerance_mm = s.number("arc_tolerance_mm", c.arc_tolerance_mm, 1e-6, 1.0);
  s.finish();
  return c;
}

control::ProgramSetup to_program_setup(const ProgramConfig& p, const InterpolatorConfig& i) {
  control::ProgramSetup st;
  auto v = [](const std::array<double, 3>& a) { return Eigen::Vector3d(a[0], a[1], a[2]); };
  for (std::size_t k = 0; k < 6; ++k) st.work_offsets_mm[k] = v(p.work_offsets_mm[k]);
  st.tools = p.tools;
  st.g28_mm = v(p.g28_mm);
  st.g30_mm = v(p.g30_mm);
  st.start_mm = v(p.start_mm);
  st.rapid_mm_min = p.rapid_mm_min;
  st.arc_tolerance_mm = p.arc_tolerance_mm;
  st.default_blend = i.blend;
  st.default_tolerance_mm = i.tolerance_um * 1e-3;
  return st;
}

}  // namespace contour::config
