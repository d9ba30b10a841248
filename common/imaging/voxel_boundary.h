// Distance to a mask's voxel boundary: the staircase surface made of the voxel faces between inside and outside
// voxels (the mask padded with outside voxels). It is the reference the smoothing and the reduction must stay close
// to ("within a stated distance of the voxel boundary").
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "imaging/volume.h"

namespace surgsim::imaging {

class VoxelBoundaryDistance {
 public:
  /// Precomputes, per voxel, which of its +i/+j/+k faces are boundary faces. The mask is not referenced afterwards.
  explicit VoxelBoundaryDistance(const VoxelMask& mask);

  /// Exact Euclidean distance (m) from a grid-frame point (m) to the nearest boundary face, searching only within
  /// `limit` (m): returns `limit` when no face is that close. `closest`, if given, receives the nearest point on
  /// the boundary when one was found within the limit.
  double distance(const Eigen::Vector3d& p, double limit, Eigen::Vector3d* closest = nullptr) const;

  /// True when some boundary face is within `d` (m) of p (stops at the first one found).
  bool within(const Eigen::Vector3d& p, double d) const;

  /// Boundary faces (for tests and reports).
  std::int64_t face_count() const { return face_count_; }

 private:
  // Visits the voxels whose faces may lie within `limit` of p; `visit(face distance^2, i, j, k, axis)` returns
  // false to stop.
  template <typename Visit>
  void scan(const Eigen::Vector3d& p, double limit, const Visit& visit) const;

  Eigen::Vector3i size_;                // mask size; faces are stored for voxels -1 .. size-1 on each axis
  Eigen::Vector3d spacing_;             // m
  std::vector<std::uint8_t> faces_;     // (size + 1)^3 entries, bit a: the face towards +a is a boundary face
  std::int64_t face_count_ = 0;
};

}  // namespace surgsim::imaging
