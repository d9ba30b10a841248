// Where an organ sits in the scene: a rigid transform from the organ's own frame (the frame its mesh, fixed region
// and generator parameters are written in) to the scene's (world) frame, x_world = rotation * x_organ + translation.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace surgsim::mesh {

struct Placement {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // proper rotation (orthonormal, det +1)
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();   // m

  bool identity() const { return rotation == Eigen::Matrix3d::Identity() && translation.isZero(0.0); }
  Eigen::Vector3d to_world(const Eigen::Vector3d& p) const { return rotation * p + translation; }
  Eigen::Vector3d to_organ(const Eigen::Vector3d& p) const { return rotation.transpose() * (p - translation); }
  Eigen::Vector3d direction_to_world(const Eigen::Vector3d& d) const { return rotation * d; }
  Eigen::Vector3d direction_to_organ(const Eigen::Vector3d& d) const { return rotation.transpose() * d; }

  /// From a translation and Euler angles in degrees, applied about the organ's x, then y, then z axes (extrinsic
  /// XYZ: R = Rz(z) Ry(y) Rx(x)), as a scene writes `placement: {translation: [...], rotation_deg: [x, y, z]}`.
  static Placement from_euler_deg(const Eigen::Vector3d& translation, const Eigen::Vector3d& rotation_deg) {
    constexpr double kDeg = 3.14159265358979323846 / 180.0;
    Placement p;
    p.rotation = (Eigen::AngleAxisd(rotation_deg.z() * kDeg, Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(rotation_deg.y() * kDeg, Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(rotation_deg.x() * kDeg, Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    p.translation = translation;
    return p;
  }
};

}  // namespace surgsim::mesh
