#pragma once
// True contour error: the distance from the tool to the programmed path, independent of the
// real-time model (contour_error.hpp). The reference for the model-accuracy figure of seed 000
// (§3.1: "true error by Newton-Raphson on the curve").
//
// CurveDistance: nearest point on a ParametricCurve by a table search (around the previous answer,
//   or the whole table) and safeguarded Newton on g'(u) = (x(u) - P).x'(u) = 0 inside the bracket
//   of the best table point (bisection when a Newton step leaves it). Converges to |du| < 1e-15
//   of the u range; the distance is then exact to rounding (~1e-12 mm) for analytic derivatives.
// SegmentPathDistance: exact distance to lines and arcs (control/path.hpp distance_to_segment).
//
// Both report whether the nearest point is the end point with P beyond it along the end tangent
// (`beyond_end`): the reference of seed 000 stops dead, so every controller overshoots the end along
// the path; that is tracking error, reported separately (interpretation.md), not contour error.
//
// Not RT: offline metric (the table is built at construction; queries do not allocate).
#include <span>
#include <vector>

#include "control/path.hpp"
#include "control/reference_path.hpp"

namespace contour::control {

struct TrueError {
  double distance_mm = 0.0;
  Vec3 foot = Vec3::Zero();
  double u = 0.0;            // curve parameter (CurveDistance) or segment index (segments)
  bool beyond_end = false;   // nearest point is the end point, P past it along the end tangent
};

class CurveDistance {
 public:
  // table_points: samples for the coarse search (>= 16), uniform in u.
  explicit CurveDistance(const ParametricCurve& curve, int table_points = 20000);
  // hint: the previous answer's u (or NaN for a global search).
  [[nodiscard]] TrueError query(const Vec3& p, double hint_u) const noexcept;
  [[nodiscard]] TrueError query(const Vec3& p) const noexcept;

 private:
  const ParametricCurve& c_;
  std::vector<double> u_;
  std::vector<Vec3> x_;
};

class SegmentPathDistance {
 public:
  explicit SegmentPathDistance(std::vector<PathSegment> segments);
  [[nodiscard]] TrueError query(const Vec3& p) const noexcept;
  [[nodiscard]] const std::vector<PathSegment>& segments() const { return segs_; }

 private:
  std::vector<PathSegment> segs_;
};

// Polyline helper (vertices -> line segments).
std::vector<PathSegment> polyline_segments(std::span<const Vec3> vertices);

}  // namespace contour::control
