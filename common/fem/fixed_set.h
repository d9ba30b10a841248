// The clamped degrees of freedom of an organ and the numbering of the free ones (docs/DESIGN.md, section 'Liver:
// precomputed linear elasticity': "fixed dofs F are removed"). Built once while starting; immutable afterwards.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh.h"
#include "fem/material.h"

namespace surgsim::fem {

/// Which dofs are fixed (zero displacement). dof = 3 * node + component (0 = x, 1 = y, 2 = z).
/// A scene fixes whole nodes; single components can be fixed too (e.g. a cylinder base held only axially).
class FixedSet {
 public:
  FixedSet() = default;
  /// Whole nodes fixed. Throws surgsim::core::Error for an index outside [0, node_count).
  FixedSet(int node_count, const std::vector<int>& fixed_nodes);
  /// Per node, a bit mask of fixed components (bit c = component c). size() = node count; masks < 8.
  explicit FixedSet(std::vector<std::uint8_t> component_masks);

  int node_count() const { return static_cast<int>(masks_.size()); }
  int dof_count() const { return 3 * node_count(); }
  int free_dof_count() const { return static_cast<int>(free_dofs_.size()); }

  std::uint8_t mask(int node) const { return masks_[static_cast<std::size_t>(node)]; }
  bool dof_fixed(int dof) const { return free_index_[static_cast<std::size_t>(dof)] < 0; }
  bool node_fully_free(int node) const { return mask(node) == 0; }
  bool node_touched(int node) const { return mask(node) != 0; }  // at least one component fixed

  /// #dofs: free-dof index of each dof, or -1 when fixed (the numbering of K_ff's rows and columns).
  const std::vector<int>& free_index() const { return free_index_; }
  /// #free dofs: the dof of each free index.
  const std::vector<int>& free_dofs() const { return free_dofs_; }
  /// Nodes with at least one fixed component, ascending.
  std::vector<int> fixed_nodes() const;
  /// Content hash (node count and masks), for caches.
  std::uint64_t hash() const;

 private:
  void number();
  std::vector<std::uint8_t> masks_;
  std::vector<int> free_index_;
  std::vector<int> free_dofs_;
};

/// Nodes a scene's FixedRegion fixes: listed indices (checked against the node count), nodes inside any box
/// (`box` or `boxes`, bounds inclusive) and nodes with (x - point) . normal >= 0 for the plane. Region tests use a
/// tolerance of 1e-9 times the mesh's bounding-box diagonal so nodes exactly on a face or plane are included.
/// Sorted, unique. Throws surgsim::core::Error for an out-of-range index.
std::vector<int> nodes_in_region(const mesh::TetMesh& mesh, const FixedRegion& region);

/// FixedSet fixing the nodes of nodes_in_region(mesh, region) completely.
FixedSet fixed_set_from_region(const mesh::TetMesh& mesh, const FixedRegion& region);

/// Throws surgsim::core::Error when the fixed dofs leave a rigid-body mode free in some mechanically independent part
/// of the mesh (the stiffness would then be singular). Parts are tetrahedra joined through shared faces (union-find
/// over sorted faces, O(T log T)); a vertex or an edge shared between parts is a hinge, so each part must be held by
/// its own fixed dofs. Refused: nothing fixed, a single fixed point, all fixed nodes on one line, a part with no fixed
/// node. The message says how many and which nodes are fixed, which motion is left free, which part (node count and
/// a few node indices), how it touches the other parts ("only at node 17 (a vertex hinge)", "along the edge 17-18 (an
/// edge hinge)", "not attached to anything") and how to fix the scene; `where` (e.g. the scene file) prefixes it.
void check_rigid_modes_removed(const mesh::TetMesh& mesh, const FixedSet& fixed, const std::string& where = "");

}  // namespace surgsim::fem
