// The pieces of a (cut) tetrahedral mesh: connected components through shared faces (two tets touching along an
// edge or at a node only are apart, as a cut leaves them), which of them hold a node of a given set (the fixed
// set: the others are free pieces), and compaction after removing elements. Defined in components.cpp.
#pragma once
#include <vector>

#include "mesh/mesh.h"

namespace surgsim::cut {

/// Face-connected components of a mesh's tets, numbered in the order of their lowest tet.
struct Components {
  int count = 0;
  std::vector<int> of_tet;  // #T, the component of each tet
};
Components face_components(const mesh::TetMesh& mesh);

/// For each component, whether one of its tets uses a node of `nodes` (indices into mesh.nodes): a component
/// without one is a free piece (nothing holds it).
std::vector<bool> anchored_components(const mesh::TetMesh& mesh, const Components& components,
                                      const std::vector<int>& nodes);

/// A mesh kept compact after dropping elements: the nodes no kept tet uses are dropped and the others renumbered
/// in their order.
struct Compacted {
  mesh::TetMesh mesh;
  std::vector<int> node_map;  // old node -> new node, -1 when dropped
  std::vector<int> tet_map;   // old tet -> new tet, -1 when dropped
};

/// The mesh without the tets in `tets` (indices; repeats allowed). Ids carry over.
Compacted remove_elements(const mesh::TetMesh& mesh, const std::vector<int>& tets);

/// The tets of one component alone.
Compacted extract_component(const mesh::TetMesh& mesh, const Components& components, int component);

}  // namespace surgsim::cut
