// Point, segment and triangle primitives shared by the organs' collision code (liver bucket grid, intestine probe
// and self-collisions).
#pragma once
#include <Eigen/Core>

namespace surgsim::mesh {

/// Moller-Trumbore: segment [p0,p1] against triangle (a,b,c). Returns true with s in [0,1] and barycentric (k1..k3).
bool segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                      const Eigen::Vector3d& b, const Eigen::Vector3d& c, double& s, Eigen::Vector3d& bary);

/// Closest point on triangle (a,b,c) to p (Ericson, Real-Time Collision Detection 5.1.5); returns barycentrics.
Eigen::Vector3d closest_point_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c, Eigen::Vector3d& bary);

}  // namespace surgsim::mesh
