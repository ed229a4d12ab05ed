#pragma once
// Programmed path geometry (G-code blocks in machine coordinates, mm) and exact point-to-path
// distances. Used by the blend planner (control/blend_planner.hpp) to hold the tolerance and by the
// contour-error reports ("distance from the tool to the programmed path").
//
// A PathSegment is a straight line (G0/G1) or a circular / helical arc (G2/G3 in G17/G18/G19).
// Arcs: centre is in the arc plane at the start point's height along the plane normal; the
// normal-axis coordinate changes linearly with the swept angle (helix). `turns` adds full turns
// (G2/G3 P-word minus one, and full circles where start == end).
//
// distance_to_segment(p, s): Euclidean distance from p to the closest point of s, in mm.
//   Lines and planar arcs: closed form (exact to rounding). Helical arcs: Newton on the squared
//   distance from one start per turn at the point's own in-plane angle and from both ends
//   (points within r/2 of the axis: a scan of 64 samples per turn first); ~1e-9 mm.
//   Pure, noexcept, no allocation: callable from the RT thread.
// distance_to_path(p, segments): minimum over a span of segments (the contour-error metric of
//   issue 4: "exact point-to-polyline/arc distance for G-code").
#include <Eigen/Core>
#include <span>
#include <vector>

namespace contour::control {

enum class Plane { kXY, kZX, kYZ };  // G17, G18, G19

struct PathSegment {
  enum class Kind { kLine, kArc };
  Kind kind = Kind::kLine;
  Eigen::Vector3d start = Eigen::Vector3d::Zero();
  Eigen::Vector3d end = Eigen::Vector3d::Zero();
  // Arc only.
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // in-plane coordinates used; normal ignored
  Plane plane = Plane::kXY;
  bool ccw = false;  // G3
  int turns = 0;     // extra full turns

  static PathSegment line(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    PathSegment s;
    s.start = a;
    s.end = b;
    return s;
  }
};

// Axis indices (first, second in-plane axis, normal) of a plane, right-handed like RS274:
// G17: X Y Z, G18: Z X Y, G19: Y Z X. G3 is counter-clockwise seen from +normal.
struct PlaneAxes {
  int a, b, n;
};
PlaneAxes plane_axes(Plane p) noexcept;

// Swept angle of an arc, rad, > 0 (direction given by ccw). Full circle when start == end in plane.
double arc_sweep_rad(const PathSegment& s) noexcept;
double arc_radius_mm(const PathSegment& s) noexcept;
// Length along the path, mm.
double segment_length_mm(const PathSegment& s) noexcept;
// Point at fraction u in [0,1] of the swept angle (arcs) or of the line.
Eigen::Vector3d point_at(const PathSegment& s, double u) noexcept;

double distance_to_segment(const Eigen::Vector3d& p, const PathSegment& s) noexcept;
// The same distance, and in u the fraction in [0, 1] (of the line, or of the arc's swept angle)
// of a point of s at that distance (the closest point; on a planar full circle, on its first turn).
double closest_on_segment(const Eigen::Vector3d& p, const PathSegment& s, double& u) noexcept;
double distance_to_path(const Eigen::Vector3d& p, std::span<const PathSegment> path) noexcept;

// Distance from a point to the straight segment [a, b] (b == a allowed).
double distance_point_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b) noexcept;
// Minimum distance between a point and a polyline given by consecutive points (>= 1 point).
double distance_point_polyline(const Eigen::Vector3d& p,
                               std::span<const Eigen::Vector3d> pts) noexcept;

// Chord points of an arc so that the chord (sagitta) error is <= max_error_mm, excluding the
// start point and including the exact end point. Setup-time (allocates). Lines: just the end.
void chord_points(const PathSegment& s, double max_error_mm, std::vector<Eigen::Vector3d>& out);

}  // namespace contour::control
