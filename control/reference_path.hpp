#pragma once
// Reference-point generation for the contour tests (seed 000 §3): parametric curves interpolated
// at constant feed along the arc length, and G01 polylines followed without acc/dec (Table 2).
//
// Parametric: u(k+1) = u(k) + du with du from a second-order Taylor inversion of the arc length
//   ds = s' du + s'' du^2 / 2 = F T  (s' = |x'|, s'' = x'.x''/|x'|), accurate to ~0.1 % per step
//   (interpretation.md). The last point is exactly x(u_end).
// Polyline: every block of length L is split into ceil(L / (F T)) equal steps, so every vertex is
//   a reference point and no step is longer than F T (never faster than programmed).
// Both produce the whole list up front (setup-time, allocates; the daemon's interpolator is
// separate). Units mm, mm/s, s.
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <vector>

#include "control/contour_error.hpp"

namespace contour::control {

// A parametric space curve x(u), u in [u_begin, u_end], in mm.
class ParametricCurve {
 public:
  virtual ~ParametricCurve() = default;
  [[nodiscard]] virtual Vec3 point(double u) const = 0;
  // Derivatives dx/du and d2x/du2; defaults are central differences of point().
  [[nodiscard]] virtual Vec3 d1(double u) const;
  [[nodiscard]] virtual Vec3 d2(double u) const;
  [[nodiscard]] virtual double u_begin() const { return 0.0; }
  [[nodiscard]] virtual double u_end() const { return 1.0; }
};

// Curve from three function objects (tests, property tests, hard-coded paper curves).
class FunctionCurve final : public ParametricCurve {
 public:
  using Fn = std::function<Vec3(double)>;
  // d1/d2 may be empty: numeric derivatives are then used.
  FunctionCurve(Fn x, Fn d1, Fn d2, double u0 = 0.0, double u1 = 1.0)
      : x_(std::move(x)), d1_(std::move(d1)), d2_(std::move(d2)), u0_(u0), u1_(u1) {}
  [[nodiscard]] Vec3 point(double u) const override { return x_(u); }
  [[nodiscard]] Vec3 d1(double u) const override { return d1_ ? d1_(u) : ParametricCurve::d1(u); }
  [[nodiscard]] Vec3 d2(double u) const override { return d2_ ? d2_(u) : ParametricCurve::d2(u); }
  [[nodiscard]] double u_begin() const override { return u0_; }
  [[nodiscard]] double u_end() const override { return u1_; }

 private:
  Fn x_, d1_, d2_;
  double u0_, u1_;
};

struct ReferencePoint {
  Vec3 r_mm = Vec3::Zero();
  Vec3 v_mm_s = Vec3::Zero();  // reference velocity (for feed-forward)
  double u = 0.0;              // curve parameter (parametric) or polyline arc length (mm)
};

// Throws std::invalid_argument on feed <= 0, period <= 0, or a curve with zero speed |x'| = 0
// over a whole step (a standstill reference cannot be stepped in arc length).
std::vector<ReferencePoint> sample_curve(const ParametricCurve& c, double feed_mm_s,
                                         double period_s);
// vertices[0] is the start point. Zero-length blocks are skipped.
std::vector<ReferencePoint> sample_polyline(const std::vector<Vec3>& vertices, double feed_mm_s,
                                            double period_s);

}  // namespace contour::control
