// Segmented volumes: a label per voxel on a regular grid, the selection of one organ's label as a binary mask, the
// clean-up of that mask, and the project's own test volumes (a closed triangle surface voxelized, optional noise).
// Pure: no file formats here (volume_io.h reads and writes them).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace surgsim::imaging {

/// Where the voxels are. Voxel (i, j, k) is the box of size `spacing` centred on
/// world = origin + axes * (spacing .* (i, j, k)). The pipeline works in the "grid frame" X = spacing .* (i, j, k)
/// (metres, axis-aligned, voxel (0,0,0)'s centre at 0) and maps to the world only at the end.
struct VoxelGrid {
  Eigen::Vector3i size = Eigen::Vector3i::Zero();       // voxels along i, j, k (i fastest in memory)
  Eigen::Vector3d spacing = Eigen::Vector3d::Ones();    // m, voxel edge lengths along i, j, k; > 0
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();     // m, world position of voxel (0, 0, 0)'s centre
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();   // world directions of i, j, k: orthonormal columns (det +-1)

  std::int64_t voxel_count() const { return std::int64_t{size.x()} * size.y() * size.z(); }
  std::int64_t index(int i, int j, int k) const { return (std::int64_t{k} * size.y() + j) * size.x() + i; }
  /// Grid frame (m) to world (m).
  Eigen::Vector3d to_world(const Eigen::Vector3d& grid_point) const { return origin + axes * grid_point; }
  /// Smallest voxel edge (m): the unit of the "voxels" distances the pipeline reports and takes.
  double voxel_unit() const { return spacing.minCoeff(); }
};

/// A segmented image: an integer label per voxel, 0 = background.
struct LabelVolume {
  VoxelGrid grid;
  std::vector<std::int32_t> labels;  // grid.voxel_count(), i fastest, then j, then k
  std::string source;                // file or folder it came from, named in every message
};

/// One organ: inside[v] != 0 for its voxels.
struct VoxelMask {
  VoxelGrid grid;
  std::vector<std::uint8_t> inside;  // grid.voxel_count(), same order as LabelVolume::labels
  std::string source;                // as LabelVolume::source
  std::int32_t label = 1;            // the label it was selected from

  bool at(int i, int j, int k) const { return inside[static_cast<std::size_t>(grid.index(i, j, k))] != 0; }
  std::int64_t count() const;        // voxels inside
};

/// Labels present and their voxel counts, ascending by label.
std::vector<std::pair<std::int32_t, std::int64_t>> label_counts(const LabelVolume& volume);

/// Selects one organ. With `label`, its voxels; without, the only non-zero label (any non-zero voxel of a binary
/// image). Throws surgsim::core::Error naming volume.source when: the volume is empty or inconsistent (sizes vs
/// labels); it holds no foreground (every voxel 0); every voxel is foreground (nothing to separate the organ from);
/// `label` is not present (the message lists the labels present with their counts); no label was given and
/// several foreground labels are present (listed).
VoxelMask select_label(const LabelVolume& volume, std::optional<std::int32_t> label = std::nullopt);

/// What clean_mask changed.
struct MaskCleanup {
  int components = 0;                 // 6-connected foreground components found
  std::int64_t removed_voxels = 0;    // foreground voxels outside the largest component, dropped
  int cavities = 0;                   // enclosed background components (not reaching the border), filled
  std::int64_t filled_voxels = 0;     // voxels of those cavities
};

/// Keeps the largest 6-connected foreground component and fills enclosed background (18-connected components that
/// do not reach the volume's border). This matches marching_cubes' connectivity (foreground voxels touching along
/// an edge only are separated), so the surface it then extracts is one closed, connected surface. Deterministic.
MaskCleanup clean_mask(VoxelMask& mask);

/// Majority vote over each voxel's 3 x 3 x 3 neighbourhood (inside when at least 14 of the 27 are), `passes`
/// times: removes isolated flipped voxels and one-voxel tunnels and bumps of a noisy segmentation, at the price of
/// rounding edges and corners by a fraction of a voxel. Outside the volume counts as outside. Returns the number of
/// voxels changed (over all passes).
std::int64_t majority_filter(VoxelMask& mask, int passes = 1);

/// A test volume from a closed, outward-oriented triangle surface (vertices in m, world frame): voxels of edge
/// `spacing` (m) on an axis-aligned grid covering the surface's bounding box plus `margin_voxels` on every side,
/// label `label` where the voxel centre is inside (parity of crossings along a z-line), 0 elsewhere.
LabelVolume voxelize(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& tris, double spacing,
                     int margin_voxels = 2, std::int32_t label = 1);

/// Segmentation noise: each voxel whose 6-neighbourhood holds another label takes one of its neighbours' labels
/// with probability `probability` (both sides of every boundary are disturbed, by one voxel at most), and
/// `speckles` isolated voxels far from the organ are set to the foreground label (stray islands that clean_mask
/// must remove). Seeded: the same seed gives the same volume.
void add_label_noise(LabelVolume& volume, double probability, int speckles, std::uint32_t seed);

}  // namespace surgsim::imaging
