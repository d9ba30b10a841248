// Structured tetrahedral meshes (boxes and cylinders) for tests, benchmarks and the patch test.
// They need no mesher: every tet is positively oriented and the meshes are conforming.
#pragma once
#include <Eigen/Core>

#include "mesh/mesh.h"

namespace surgsim::mesh {

/// How each cube of a box mesh is cut into tetrahedra.
enum class BoxSplit {
  kSix,   // Kuhn split along the cube's main diagonal: 6 tets, the same in every cube
  kFive,  // one central tet and four corner tets, mirrored in alternate cubes so that faces match
};

/// Box [origin, origin + size] (m) divided into nx x ny x nz cubes (each >= 1), cut by `split`.
/// Node (i, j, k), 0 <= i <= nx etc., has index i + (nx + 1) * (j + (ny + 1) * k) and sits at
/// origin + (i size.x / nx, j size.y / ny, k size.z / nz). Throws surgsim::core::Error on a bad count or size.
TetMesh make_box_mesh(int nx, int ny, int nz, const Eigen::Vector3d& size,
                      const Eigen::Vector3d& origin = Eigen::Vector3d::Zero(), BoxSplit split = BoxSplit::kSix);

/// Index of node (i, j, k) in a mesh made by make_box_mesh(nx, ny, nz, ...).
inline int box_node(int nx, int ny, int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); }

/// A box of the given size (m) with about `target_nodes` nodes (cells as close to cubes as the size allows),
/// for benchmarks that need meshes of a given node count.
TetMesh make_box_mesh_with_nodes(int target_nodes, const Eigen::Vector3d& size);

/// Cylinder of `radius` (m) about the z axis from z = 0 to z = height (m). The cross-section is a disk of
/// `rings` concentric rings (ring r has 6 r nodes at radius r * radius / rings, the first at angle 0, i.e. on +x);
/// `layers` prism layers along z, each prism cut into 3 tets consistently. Node index = layer * nodes_per_layer
/// + disk index; disk index 0 is the centre. Lateral nodes lie exactly on the circle.
TetMesh make_cylinder_mesh(double radius, double height, int rings, int layers);

/// Nodes per layer of make_cylinder_mesh(..., rings, ...): 1 + 3 rings (rings + 1).
inline int cylinder_layer_nodes(int rings) { return 1 + 3 * rings * (rings + 1); }

}  // namespace surgsim::mesh
