#include "tool/tool.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace surgsim::tool {

namespace {
// A fixed orthonormal frame (axis, e1, e2) from the base axis, independent of the pose.
void trocar_frame(const Eigen::Vector3d& axis, Eigen::Vector3d& e1, Eigen::Vector3d& e2) {
  const Eigen::Vector3d helper = std::abs(axis.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  e1 = axis.cross(helper).normalized();
  e2 = axis.cross(e1).normalized();
}
}  // namespace

ToolGeometry tool_geometry(const ToolSpec& spec, const Pose5& pose) {
  ToolGeometry g;
  const Eigen::Vector3d axis = spec.axis.normalized();
  Eigen::Vector3d e1, e2;
  trocar_frame(axis, e1, e2);

  // Pitch about e1 then yaw about e2 (both through the trocar).
  const Eigen::AngleAxisd pitch(pose.pitch, e1);
  const Eigen::AngleAxisd yaw(pose.yaw, e2);
  const Eigen::Matrix3d r = (yaw * pitch).toRotationMatrix();
  g.trocar = spec.trocar;
  g.direction = (r * axis).normalized();
  g.tip = spec.trocar + pose.insertion * g.direction;

  // Roll turns the jaw plane about the shaft.
  const Eigen::Vector3d n0 = r * e1;
  g.jaw_normal = Eigen::AngleAxisd(pose.roll, g.direction) * n0;
  const double half = 0.5 * std::max(0.0, pose.jaw);
  for (int s = 0; s < 2; ++s) {
    const double a = s == 0 ? half : -half;
    const Eigen::Vector3d d = std::cos(a) * g.direction + std::sin(a) * g.jaw_normal;
    g.jaw_tips[s] = g.tip + spec.jaw_length * d;
  }

  // Contact points: the tip first, then back along the shaft (never behind the trocar).
  g.point_count = std::clamp(spec.shaft_points, 1, kMaxShaftPoints);
  for (int i = 0; i < g.point_count; ++i) {
    const double back = std::min(i * spec.shaft_spacing, std::max(0.0, pose.insertion));
    g.points[i] = g.tip - back * g.direction;
  }
  return g;
}

}  // namespace surgsim::tool
