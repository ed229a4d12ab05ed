#include "config/curve_file.hpp"

#include <muParser.h>

#include <array>
#include <cmath>
#include <optional>

namespace contour::config {

namespace {

class MuCurve final : public control::ParametricCurve {
 public:
  MuCurve(double u0, double u1, double scale) : u0_(u0), u1_(u1), scale_(scale) {}
  MuCurve(const MuCurve&) = delete;
  MuCurve& operator=(const MuCurve&) = delete;

  // Throws mu::Parser::exception_type on a bad expression.
  void set(std::size_t axis, const std::string& expr, bool derivative) {
    mu::Parser& p = derivative ? d_[axis].emplace() : x_[axis];
    p.DefineConst("pi", M_PI);
    p.DefineVar("u", &u_);
    p.SetExpr(expr);
    u_ = u0_;
    (void)p.Eval();  // surfaces unknown names and syntax errors now, not mid-run
  }

  [[nodiscard]] control::Vec3 point(double u) const override {
    u_ = u;
    return control::Vec3(x_[0].Eval(), x_[1].Eval(), x_[2].Eval()) * scale_;
  }
  [[nodiscard]] control::Vec3 d1(double u) const override {
    if (!d_[0] || !d_[1] || !d_[2]) return ParametricCurve::d1(u);
    u_ = u;
    return control::Vec3(d_[0]->Eval(), d_[1]->Eval(), d_[2]->Eval()) * scale_;
  }
  [[nodiscard]] double u_begin() const override { return u0_; }
  [[nodiscard]] double u_end() const override { return u1_; }

 private:
  mutable double u_ = 0.0;
  double u0_, u1_, scale_;
  std::array<mu::Parser, 3> x_;
  std::array<std::optional<mu::Parser>, 3> d_;
};

CurveFile parse(const YAML::Node& root, const std::string& name) {
  Diagnostics diag(name);
  CurveFile out;
  {
    Section top(root, "", diag);
    Section c = top.child("curve");
    if (!c.present()) c.error("", "missing 'curve:' map");
    out.name = c.string("name", "curve");
    const std::string units = c.choice("units", "mm", {"blu", "um", "mm"});
    const double blu_um = c.number("blu_um", 0.5, 1e-6, 1e6);
    out.scale_to_mm = units == "mm" ? 1.0 : units == "um" ? 1e-3 : blu_um * 1e-3;
    std::vector<double> range;
    if (c.has("u")) {
      range = c.numbers("u", 2, 2);
    } else {
      c.accept("u");  // default [0, 1]
    }
    double u0 = 0.0, u1 = 1.0;
    if (range.size() == 2) {
      u0 = range[0];
      u1 = range[1];
      if (!(u1 > u0)) c.error("u", "expected [u_begin, u_end] with u_end > u_begin");
    }
    auto curve = std::make_unique<MuCurve>(u0, u1, out.scale_to_mm);
    const char* keys[] = {"x", "y", "z"};
    const char* dkeys[] = {"dx", "dy", "dz"};
    int derivs = 0;
    for (std::size_t i = 0; i < 3; ++i) {
      const std::string e = c.required_string(keys[i]);
      try {
        if (!e.empty()) curve->set(i, e, false);
      } catch (const mu::Parser::exception_type& ex) {
        c.error(keys[i], "bad expression '" + e + "': " + ex.GetMsg() + " (at character " +
                             std::to_string(ex.GetPos() + 1) + ")");
      }
      if (c.has(dkeys[i])) {
        ++derivs;
        const std::string de = c.string(dkeys[i], "");
        try {
          curve->set(i, de, true);
        } catch (const mu::Parser::exception_type& ex) {
          c.error(dkeys[i], "bad expression '" + de + "': " + ex.GetMsg() + " (at character " +
                                std::to_string(ex.GetPos() + 1) + ")");
        }
      } else {
        c.accept(dkeys[i]);
      }
    }
    if (derivs != 0 && derivs != 3) c.error("dx", "give all of dx, dy, dz or none");
    if (diag.errors().empty()) {
      // Values must be finite over the whole range (e.g. sqrt of a negative number).
      for (int k = 0; k <= 100; ++k) {
        const double u = u0 + (u1 - u0) * k / 100.0;
        if (!curve->point(u).allFinite()) {
          c.error("x", "curve is not finite at u = " + std::to_string(u));
          break;
        }
      }
    }
    c.finish();
    top.finish();
    out.curve = std::move(curve);
  }
  diag.throw_if_any();
  return out;
}

}  // namespace

CurveFile load_curve_file(const std::string& path) { return parse(load_yaml_file(path), path); }

CurveFile load_curve_string(const std::string& text, const std::string& name) {
  return parse(load_yaml_string(text, name), name);
}

}  // namespace contour::config
