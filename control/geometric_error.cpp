#include "control/geometric_error.hpp"

#include <Eigen/Geometry>
#include <cmath>

namespace contour::control {

namespace {
Eigen::Matrix4d axis_transform(const Eigen::Vector3d& nominal_mm, const AxisGeometricErrors& e,
                               double q_mm) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  const double ex = e.rotation_rad[0].eval(q_mm);
  const double ey = e.rotation_rad[1].eval(q_mm);
  const double ez = e.rotation_rad[2].eval(q_mm);
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(ex, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(ey, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(ez, Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  t.block<3, 3>(0, 0) = r;
  for (int j = 0; j < 3; ++j) {
    t(j, 3) = nominal_mm(j) + e.translation_mm[static_cast<std::size_t>(j)].eval(q_mm);
  }
  return t;
}
}  // namespace

Eigen::Vector3d GeometricErrorModel::tool_tip_mm(const Eigen::Vector3d& q) const noexcept {
  const Eigen::Vector3d ax(q.x(), 0.0, 0.0);
  const Eigen::Vector3d ay(p_.squareness_xy_rad * q.y(), q.y(), 0.0);
  const Eigen::Vector3d az(p_.squareness_zx_rad * q.z(), p_.squareness_yz_rad * q.z(), q.z());
  const Eigen::Matrix4d t = axis_transform(ax, p_.axes[0], q.x()) *
                            axis_transform(ay, p_.axes[1], q.y()) *
                            axis_transform(az, p_.axes[2], q.z());
  const Eigen::Vector4d tip = t * p_.tool_offset_mm.homogeneous();
  return tip.head<3>();
}

GeometricErrorModel GeometricErrorModel::scaled(double factor) const {
  GeometricErrorParams p = p_;
  for (auto& axis : p.axes) {
    for (auto& poly : axis.translation_mm) {
      for (double& c : poly.c) c *= factor;
    }
    for (auto& poly : axis.rotation_rad) {
      for (double& c : poly.c) c *= factor;
    }
  }
  p.squareness_xy_rad *= factor;
  p.squareness_yz_rad *= factor;
  p.squareness_zx_rad *= factor;
  return GeometricErrorModel(p);
}

}  // namespace contour::control
