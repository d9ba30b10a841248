// Internal to common/mesh (no other folder includes it): what mesh.cpp shares with validate.cpp and the format
// writers. Names of meshes, nodes and tets for messages, the index check of the writers and boundary_surface, and
// the tets' faces sorted so that equal faces are adjacent (boundary and manifold checks).
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace surgsim::mesh::internal {

/// The mesh's source file, or "<in-memory mesh>".
std::string mesh_name(const TetMesh& mesh);

/// Messages name nodes and tets by their file ids when the mesh came from a file.
std::string node_name(const TetMesh& mesh, int i);
std::string tet_name(const TetMesh& mesh, int t);

/// Throws surgsim::core::Error naming the mesh, the tet and `caller` when a tet references a node that does not exist.
void check_indices(const TetMesh& mesh, const char* caller);

struct Face {
  std::array<int, 3> key;  // sorted node indices
  int tet;
  int local;  // index of the opposite vertex in the tet
};

// All tet faces sorted by key, so that equal faces are adjacent.
std::vector<Face> sorted_faces(const Eigen::MatrixX4i& tets);

}  // namespace surgsim::mesh::internal
