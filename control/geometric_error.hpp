#pragma once
// Geometric error synthesis model of a 3-axis (X, Y, Z) Cartesian machine (seed 003, refs 4-5 of
// the paper: error synthesis by homogeneous transforms).
//
// Each linear axis i in {X, Y, Z} carries six error components, each a polynomial of that axis'
// own nominal position q_i (mm):
//   translation[j](q_i), j = x, y, z (mm): j == i is the positioning error, j != i straightness;
//   rotation[j](q_i),    j = x, y, z (rad): roll/pitch/yaw about the machine axes.
// Squareness (rad): the real Y axis moves along (s_xy, 1, 0), the real Z axis along
// (s_zx, s_yz, 1) (first order), i.e. s_xy > 0 adds s_xy * y to the X coordinate.
//
// Composition (serial chain X -> Y -> Z -> tool, every error in the frame of the preceding body):
//   P = T_x(x) * T_y(y) * T_z(z) * [tool_offset; 1],
//   T_i(q) = Trans(q * a_i + delta_i(q)) * Rot(eps_i(q)),  a_i = nominal (squareness-tilted) direction
// Rot is the exact product Rx*Ry*Rz of the small angles. tool_tip_mm() is the actual tool tip
// position relative to the table frame for nominal axis positions; error_mm() = actual - nominal.
//
// Not RT code, but tool_tip_mm() is noexcept and allocation-free (fixed-size Eigen only).
#include <Eigen/Core>
#include <array>
#include <cstddef>

namespace contour::control {

struct ErrorPolynomial {
  static constexpr std::size_t kMaxCoefficients = 8;
  // c[k] multiplies q^k (q in mm); units: mm/mm^k (translations) or rad/mm^k (rotations).
  std::array<double, kMaxCoefficients> c{};

  [[nodiscard]] double eval(double q_mm) const noexcept {
    double v = 0.0;
    for (std::size_t k = kMaxCoefficients; k-- > 0;) v = v * q_mm + c[k];
    return v;
  }
};

struct AxisGeometricErrors {
  std::array<ErrorPolynomial, 3> translation_mm{};  // delta_x, delta_y, delta_z (mm)
  std::array<ErrorPolynomial, 3> rotation_rad{};    // eps_x, eps_y, eps_z (rad)
};

struct GeometricErrorParams {
  std::array<AxisGeometricErrors, 3> axes{};  // X, Y, Z
  double squareness_xy_rad = 0.0;
  double squareness_yz_rad = 0.0;
  double squareness_zx_rad = 0.0;
  Eigen::Vector3d tool_offset_mm = Eigen::Vector3d::Zero();  // tool tip in the Z carriage frame
};

class GeometricErrorModel {
 public:
  GeometricErrorModel() = default;
  explicit GeometricErrorModel(const GeometricErrorParams& p) : p_(p) {}

  // Actual tool tip (table frame, mm) for nominal axis positions q (mm). The nominal tool tip is
  // q + tool_offset.
  [[nodiscard]] Eigen::Vector3d tool_tip_mm(const Eigen::Vector3d& q_mm) const noexcept;
  // Actual minus nominal tool tip (mm).
  [[nodiscard]] Eigen::Vector3d error_mm(const Eigen::Vector3d& q_mm) const noexcept {
    return tool_tip_mm(q_mm) - q_mm - p_.tool_offset_mm;
  }

  // Every error coefficient (and squareness) multiplied by factor: a "model 10 % wrong" is
  // scaled(1.1). The tool offset is kept.
  [[nodiscard]] GeometricErrorModel scaled(double factor) const;

  [[nodiscard]] const GeometricErrorParams& params() const noexcept { return p_; }
  [[nodiscard]] GeometricErrorParams& params() noexcept { return p_; }

 private:
  GeometricErrorParams p_{};
};

}  // namespace contour::control
