// Cutting a tetrahedral mesh along a blade's swept surface: the geometric core of cutting (the elasticity of the
// cut mesh is rebuilt elsewhere). Pure: no I/O, no threads. Defined in cut.cpp.
//
// The method is element splitting along the blade's plane with logical node snapping, then node separation:
//  1. Each blade triangle B has a plane n.x = c. A node at signed distance d from it is "on the plane" when
//     |d| <= snap h, h the mean length of the node's edges in the mesh given (a new node's h is interpolated from
//     its edge's ends); the node is NOT moved, so rest positions of existing nodes never change. Snapping keeps a
//     split point away from an edge's ends, so no split makes a sliver out of a near miss.
//  2. A tet with a node strictly on each side whose convex hull overlaps B (separating axis test) is crossed. Every
//     edge of a crossed tet whose ends lie strictly on opposite sides gets a node at its intersection with the
//     plane, t = d_a / (d_a - d_b), and is bisected there in every tet around it (an edge bisection applied to all
//     its tets keeps the mesh conforming, and a point strictly inside an edge makes two tets of positive volumes
//     t V and (1 - t) V: the volume is conserved up to rounding). Once all of a tet's sign-changing edges are split
//     each of its pieces lies on one side of the plane (an edge between a + and a - node would be sign-changing),
//     so the plane's section of the tet is made of faces: the 1 + 3 and 2 + 2 cases fall out without a table. A
//     tet outside B that shares a split edge is only bisected: it stays whole across the plane, so the cut ends
//     there.
//  3. A face is opened when it is interior, its three nodes are on the plane of some blade triangle, the nodes of
//     its two tets opposite it lie strictly on the plane's two sides (a thin piece within snap of the plane, as
//     where two triangles of a bent blade meet, is not cut loose) and its centroid projects inside that triangle. Each
//     node of an opened face is separated: the tets around it are grouped through the faces around it that stay closed,
//     and each group past the first gets its own copy of the node. A node where the blade stopped (its tets still
//     joined around the crack's end) keeps one copy: the crack is open only where the blade passed, and a blade through
//     the whole mesh separates it into pieces. Where the opened faces would leave a boundary edge on other than two
//     boundary faces (a crack narrower than one element), the faces on that edge are closed again, until none is left.
//  4. Pieces of split tets that the validator would refuse or of quality below options.min_quality are removed
//     (counted, with their volume), unreferenced nodes dropped, and the result validated (validate_mesh, no
//     orientation repair); when removing the low-quality pieces leaves an invalid mesh (e.g. two holes sharing an
//     edge), the cut is made again keeping them. The cut works on a copy: a refused cut leaves the mesh as it was.
// Deterministic: ordered containers only, one thread, so the same input gives bit-identical output.
// Limits: each blade triangle cuts along its own plane; where two triangles of a non-planar swept surface meet at
// an angle, the faces near their common edge may stay closed (a bridge a few elements wide).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace surgsim::cut {

/// A blade's swept surface: triangles in the mesh's frame (m), e.g. two per quad swept between two ticks.
struct Blade {
  std::vector<Eigen::Matrix3d> triangles;  // each 3 x 3, one vertex per row, m
};

/// The quad (p0, p1, p2, p3), in order around it, as two triangles (p0, p1, p2) and (p0, p2, p3).
Blade blade_quad(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& p2,
                 const Eigen::Vector3d& p3);

struct CutOptions {
  double snap = 0.1;                 // a node within snap * (its mean edge length) of a blade plane is on it
  double min_quality = 1e-3;         // a piece of a split tet below this tet_quality is removed
  std::vector<int> protected_nodes;  // nodes the blade may not cut through (e.g. the fixed set): the cut is refused
};

/// Where a node of the cut mesh comes from, in the cut's working numbering: the input nodes 0..N-1 and then the
/// created nodes in creation order (working index N + i is origins[i]). Parents always come earlier.
struct NodeOrigin {
  enum class Kind { kEdge, kCopy };
  Kind kind = Kind::kEdge;
  int a = -1;  // kEdge: x = (1 - t) x_a + t x_b; kCopy: a copy of node a (the same position)
  int b = -1;
  double t = 0;
};

enum class CutStatus {
  kApplied,  // the mesh was replaced by the cut one (which may equal the input when the blade missed it)
  kRefused,  // the mesh is unchanged; `reason` says why
};

struct CutResult {
  CutStatus status = CutStatus::kRefused;
  std::string reason;               // why the cut was refused ("" when applied)
  int elements_split = 0;           // tets of the input that were split
  int elements_created = 0;         // pieces of split tets in the result
  int elements_removed = 0;         // pieces removed (validator or min_quality), counted in volume_removed
  int nodes_created = 0;            // split points on edges
  int nodes_duplicated = 0;         // copies made to separate the two sides of the opened faces
  int faces_opened = 0;             // interior faces that became two boundary faces
  double volume_before = 0;         // m^3, sum of tet volumes
  double volume_after = 0;          // m^3
  double volume_removed = 0;        // m^3, the removed pieces
  std::uint64_t topology_hash = 0;  // cut_topology_hash of the result
  std::vector<NodeOrigin> origins;  // one per created node, in working numbering (see NodeOrigin)
  std::vector<int> node_map;        // working index -> node of the result (-1: dropped with removed pieces)
};

/// Cuts `mesh` (valid, as validate_mesh leaves it) along `blade`; see the top of this file for the method.
/// Refuses (status kRefused, mesh unchanged) a blade with a non-finite or degenerate triangle, bad options, a cut
/// that would open a face at a protected node, or a result validate_mesh refuses. Node and element ids (when the
/// mesh has them) carry over; created nodes and tets get ids past the largest.
CutResult apply_cut(mesh::TetMesh& mesh, const Blade& blade, const CutOptions& options = {});

/// A field on the input's nodes (#N x C), carried to the cut mesh's nodes through result.origins and node_map
/// (linear along split edges, copied to duplicates): e.g. displacements. Rows = the result's node count.
Eigen::MatrixXd carry_node_field(const CutResult& result, const Eigen::MatrixXd& input_field);

/// Hash of a mesh's topology: node count and tets (not positions).
std::uint64_t cut_topology_hash(const mesh::TetMesh& mesh);

}  // namespace surgsim::cut
