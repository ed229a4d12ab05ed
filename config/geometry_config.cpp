#include "config/geometry_config.hpp"

namespace contour::config {

namespace {
void read_poly(Section& s, const std::string& key, double scale, control::ErrorPolynomial& p) {
  const std::vector<double> c = s.numbers(key, 0, control::ErrorPolynomial::kMaxCoefficients);
  for (std::size_t k = 0; k < c.size() && k < p.c.size(); ++k) p.c[k] = c[k] * scale;
}

control::GeometricErrorModel parse_root(const YAML::Node& root, const std::string& name) {
  Diagnostics diag(name);
  control::GeometricErrorParams p;
  {
    Section top(root, "", diag);
    if (!top.present()) diag.error(root, "", "empty geometric-error file");
    p = parse_geometry(top);
  }
  diag.throw_if_any();
  return control::GeometricErrorModel(p);
}
}  // namespace

control::GeometricErrorParams parse_geometry(Section& top) {
  control::GeometricErrorParams p;
  if (top.has("tool_offset_mm")) {
    const std::vector<double> t = top.numbers("tool_offset_mm", 3, 3);
    if (t.size() == 3) p.tool_offset_mm = Eigen::Vector3d(t[0], t[1], t[2]);
  } else {
    top.accept("tool_offset_mm");
  }
  {
    Section sq = top.child("squareness_urad");
    p.squareness_xy_rad = sq.number("xy", 0.0, -1e5, 1e5) * 1e-6;
    p.squareness_yz_rad = sq.number("yz", 0.0, -1e5, 1e5) * 1e-6;
    p.squareness_zx_rad = sq.number("zx", 0.0, -1e5, 1e5) * 1e-6;
    sq.finish();
  }
  Section axes = top.child("axes");
  const char* names[] = {"X", "Y", "Z"};
  for (std::size_t i = 0; i < 3; ++i) {
    Section a = axes.child(names[i]);
    auto& e = p.axes[i];
    read_poly(a, "dx_um", 1e-3, e.translation_mm[0]);
    read_poly(a, "dy_um", 1e-3, e.translation_mm[1]);
    read_poly(a, "dz_um", 1e-3, e.translation_mm[2]);
    read_poly(a, "ex_urad", 1e-6, e.rotation_rad[0]);
    read_poly(a, "ey_urad", 1e-6, e.rotation_rad[1]);
    read_poly(a, "ez_urad", 1e-6, e.rotation_rad[2]);
    a.finish();
  }
  axes.finish();
  return p;
}

control::GeometricErrorModel load_geometry_file(const std::string& path) {
  return parse_root(load_yaml_file(path), path);
}

control::GeometricErrorModel load_geometry_string(const std::string& text,
                                                  const std::string& name) {
  return parse_root(load_yaml_string(text, name), name);
}

}  // namespace contour::config
