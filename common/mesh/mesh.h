// Tetrahedral meshes: reading (Gmsh .msh v1/v2/v4 ASCII, VTK legacy unstructured grid), writing VTK,
// boundary extraction and validation. Pure: no DDS, no GL. Defined in mesh.cpp (read_mesh, boundary, volumes,
// quality, hash), validate.cpp, and one file per format: format_msh.cpp, format_vtk.cpp, format_obj.cpp.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/tri_surface.h"

namespace surgsim::mesh {

/// A linear (P1) tetrahedral mesh. Node indices are 0-based in file order (gaps in file ids are compacted).
struct TetMesh {
  Eigen::MatrixX3d nodes;          // #V x 3, m
  Eigen::MatrixX4i tets;           // #T x 4, indices into nodes, positively oriented after validation/repair
  std::vector<std::int64_t> ids;   // #V, the node id used in the source file (for messages); may be empty
  std::string source;              // file it came from ("" when generated in memory), used in messages
  std::vector<std::int64_t> tet_ids;  // #T, the element id used in the source file (for messages); may be empty
};

/// The boundary of a TetMesh as triangles indexing the tet mesh's own nodes (not compacted): it owns no vertices.
/// Not TriSurface (mesh/tri_surface.h), which is a triangle surface with its own vertices (e.g. read from .obj).
struct SurfaceMesh {
  Eigen::MatrixX3i tris;            // #F x 3, counter-clockwise seen from outside (outward normals)
  std::vector<int> nodes;           // sorted unique node indices used by tris (the surface nodes)
};

/// Reads .msh (v1, v2 or v4 ASCII) or .vtk (legacy ASCII unstructured grid), chosen by extension.
/// Keeps tetrahedra only (other element types are skipped; a file with none is an error). Second-order tets
/// (Gmsh type 11, VTK type 24) and binary files are refused. Does not validate: call validate_mesh next.
/// Throws surgsim::core::Error naming the file and line on any malformed input ("FILE:LINE: what").
TetMesh read_mesh(const std::string& path);
TetMesh read_msh(const std::string& path);
TetMesh read_vtk(const std::string& path);

/// Writes a VTK legacy ASCII unstructured grid; optional per-node vector field (e.g. displacement, #V x 3).
void write_vtk(const std::string& path, const TetMesh& mesh, const Eigen::MatrixX3d* node_vectors = nullptr,
               const std::string& vector_name = "displacement");
/// Writes a triangle surface (e.g. the deformed visible surface) as a VTK legacy ASCII unstructured grid of
/// triangles. points: #P x 3 (m); tris: #F x 3 indices into points. Throws surgsim::core::Error naming the path.
void write_vtk_surface(const std::string& path, const Eigen::MatrixX3d& points, const Eigen::MatrixX3i& tris);
/// Reads a Wavefront .obj surface (v and f lines; polygons are fanned into triangles; vt/vn/other lines ignored;
/// negative (relative) indices accepted). Throws surgsim::core::Error "FILE:LINE: ..." on a bad number, an index out of
/// range, non-finite coordinates, or a file without faces.
TriSurface read_obj(const std::string& path);

/// Writes a Gmsh v2.2 ASCII mesh (tets only).
void write_msh(const std::string& path, const TetMesh& mesh);

/// Boundary faces (faces belonging to exactly one tet), oriented outward.
SurfaceMesh boundary_surface(const TetMesh& mesh);

/// The surface triangles around each mesh node (CSR over all `node_count` nodes, triangles in ascending order):
/// the triangles of node n are list[start[n]] .. list[start[n + 1] - 1].
struct NodeTriangles {
  std::vector<int> start;  // node_count + 1
  std::vector<int> list;   // 3 #F
};
NodeTriangles node_triangles(const SurfaceMesh& surface, int node_count);

/// Signed volume of tet t (positive when nodes 1,2,3 are counter-clockwise seen from node 0... i.e.
/// det[x1-x0, x2-x0, x3-x0] / 6 > 0).
double tet_volume(const TetMesh& mesh, int t);

/// Shape quality of tet t: 6 sqrt(2) |V| / l_rms^3 with l_rms the root mean square of its six edge lengths; 1 for
/// the regular tet, 0 for a flat one (slivers, needles and caps all score low). Scale invariant.
double tet_quality(const TetMesh& mesh, int t);

struct MeshValidation {
  bool fix_orientation = true;      // flip negatively oriented tets instead of refusing them
  double min_volume_ratio = 1e-12;  // |vol| below ratio * mean |vol| is a zero-volume error
};

/// Validates (and, if allowed, repairs orientation of) a mesh: non-finite coordinates, out-of-range indices,
/// repeated nodes in a tet, zero-volume tets, inverted tets (when not fixing), unreferenced nodes, folded tets (two
/// tets whose apexes lie on the same side of their shared face, so that they overlap though both have positive
/// volume, e.g. an inverted tet that fix_orientation flipped), non-manifold boundary (an edge shared by other than
/// two boundary faces; a face shared by more than two tets).
/// Throws surgsim::core::Error naming the file and the element (file id) at fault; on error the mesh is left unchanged.
void validate_mesh(TetMesh& mesh, const MeshValidation& opts = {});

/// Content hash of nodes and tets (used by scenes, caches, SceneInfo).
std::uint64_t mesh_hash(const TetMesh& mesh);

}  // namespace surgsim::mesh
