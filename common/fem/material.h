// An elastic body's material and its fixed (clamped) region (docs/DESIGN.md, section 'Liver: precomputed linear
// elasticity'). Read from YAML by scene/; nothing here knows about scenes.
#pragma once
#include <Eigen/Core>
#include <utility>
#include <vector>

#include "mesh/placement.h"

namespace surgsim::fem {

struct Material {
  double young_modulus = 3000.0;  // Pa, > 0
  double poisson_ratio = 0.45;    // [0, 0.5)
};

/// Fixed (clamped) nodes: the union of an index list, axis-aligned boxes and the negative side of a plane.
/// YAML: `fixed: {nodes: [..], box: {min, max}, boxes: [{min, max}, ..], plane: {point, normal}}`, all optional.
/// The single `box` key is one more entry of `boxes` (after it, before the list's boxes): one representation.
struct FixedRegion {
  std::vector<int> nodes;                                          // 0-based node indices in file order
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> boxes;  // (min, max) per box, m; min < max
  bool has_plane = false;
  Eigen::Vector3d plane_point = Eigen::Vector3d::Zero();    // m
  Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitZ();  // unit; nodes with (x - point) . normal >= 0 are fixed
  /// The frame the boxes and the plane are written in: the organ's own (a placed organ's mesh is in the scene's
  /// frame; its nodes are tested at frame.to_organ(x)). Identity for an organ at the origin.
  mesh::Placement frame;

  /// True if node `index` at rest position `x` (m, the scene's frame) is fixed: listed, inside a box (bounds inclusive) or on
  /// the fixed side of the plane.
  bool fixes(int index, const Eigen::Vector3d& x) const;
  /// True if nothing at all is fixed by this region.
  bool empty() const { return nodes.empty() && boxes.empty() && !has_plane; }
};

}  // namespace surgsim::fem
