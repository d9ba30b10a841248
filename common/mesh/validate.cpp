// validate_mesh: coordinates, connectivity, volumes (orientation repaired when allowed), unused nodes, neighbours
// on opposite sides of their shared face and a manifold boundary, each refusal naming the file and the element at
// fault.
#include "mesh/mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "core/error.h"
#include "mesh/mesh_internal.h"

using namespace surgsim::core;

namespace surgsim::mesh {

using internal::Face;
using internal::mesh_name;
using internal::node_name;
using internal::sorted_faces;
using internal::tet_name;

namespace {

std::string tet_nodes_text(const TetMesh& mesh, const Eigen::MatrixX4i& tets, int t) {
  std::string s = " (nodes";
  for (int k = 0; k < 4; ++k) {
    const int v = tets(t, k);
    s += ' ';
    s += (v >= 0 && v < mesh.nodes.rows() && static_cast<std::size_t>(v) < mesh.ids.size())
             ? std::to_string(mesh.ids[v])
             : std::to_string(v);
  }
  return s + ")";
}

// The side of the plane through face.key (in its sorted order) on which the tet's apex, the node opposite the face,
// lies: +1 or -1, the sign of det[k1 - k0, k2 - k0, apex - k0]. The tet is positively oriented (the volume check has
// flipped the others), and that determinant is the tet's own under a permutation of its nodes, so the side is the
// permutation's parity: read from the node order, not evaluated again in floating point, it cannot disagree with the
// sign the volume check judged.
int apex_side(const Eigen::MatrixX4i& tets, const Face& face) {
  std::array<int, 4> order{};  // positions in the tet of key[0], key[1], key[2] and the apex
  for (int k = 0; k < 3; ++k) {
    for (int a = 0; a < 4; ++a) {
      if (tets(face.tet, a) == face.key[k]) order[k] = a;
    }
  }
  order[3] = face.local;
  int inversions = 0;
  for (int a = 0; a < 4; ++a) {
    for (int b = a + 1; b < 4; ++b) inversions += order[a] > order[b] ? 1 : 0;
  }
  return inversions % 2 == 0 ? 1 : -1;
}

// Two tets on the same side of their shared face (`tets` as repaired, `vol` the volumes before the repair).
[[noreturn]] void throw_folded(const TetMesh& mesh, const Eigen::MatrixX4i& tets, const std::vector<double>& vol,
                               const Face& f1, const Face& f2) {
  const auto& k = f1.key;
  const int apex1 = tets(f1.tet, f1.local), apex2 = tets(f2.tet, f2.local);
  std::string why;
  if (apex1 == apex2) {
    why = "they are the same element twice: remove the duplicate or re-mesh";
  } else {
    why = "their apexes " + node_name(mesh, apex1) + " and " + node_name(mesh, apex2) +
          " lie on the same side of it, so the elements overlap (e.g. a node pushed through the face)";
    for (const int t : {f1.tet, f2.tet}) {
      if (vol[t] < 0) why += "; " + tet_name(mesh, t) + " was inverted and flipped by fix_orientation";
    }
    why += ": re-mesh, or move the node back to its side of the face";
  }
  throw_error(mesh_name(mesh), ": ", tet_name(mesh, f1.tet), tet_nodes_text(mesh, mesh.tets, f1.tet), " and ",
              tet_name(mesh, f2.tet), tet_nodes_text(mesh, mesh.tets, f2.tet), " are folded over their shared face (",
              node_name(mesh, k[0]), ", ", node_name(mesh, k[1]), ", ", node_name(mesh, k[2]), "): ", why);
}

}  // namespace

void validate_mesh(TetMesh& mesh, const MeshValidation& opts) {
  const std::string file = mesh_name(mesh);
  const auto nv = static_cast<int>(mesh.nodes.rows());
  const auto nt = static_cast<int>(mesh.tets.rows());
  if (nt == 0) throw_error(file, ": the mesh has no tetrahedra: mesh the volume, not only its surface");
  if (!mesh.ids.empty() && mesh.ids.size() != static_cast<std::size_t>(nv)) {
    throw_error(file, ": ", mesh.ids.size(), " node ids for ", nv, " nodes: ids must be empty or one per node");
  }
  if (!mesh.tet_ids.empty() && mesh.tet_ids.size() != static_cast<std::size_t>(nt)) {
    throw_error(file, ": ", mesh.tet_ids.size(), " element ids for ", nt,
                " tets: tet_ids must be empty or one per tet");
  }

  // Coordinates.
  for (int i = 0; i < nv; ++i) {
    if (!mesh.nodes.row(i).allFinite()) {
      throw_error(file, ": ", node_name(mesh, i), " has a non-finite coordinate (", mesh.nodes(i, 0), ", ",
                  mesh.nodes(i, 1), ", ", mesh.nodes(i, 2), "): fix the file or the program that generated it");
    }
  }

  // Connectivity of each tet.
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.tets(t, k);
      if (v < 0 || v >= nv) {
        throw_error(file, ": ", tet_name(mesh, t), " references node index ", v, " but the mesh has ", nv,
                    " nodes (valid 0..", nv - 1, "): the element list does not match the node list");
      }
    }
    for (int a = 0; a < 4; ++a) {
      for (int b = a + 1; b < 4; ++b) {
        if (mesh.tets(t, a) == mesh.tets(t, b)) {
          throw_error(file, ": ", tet_name(mesh, t), tet_nodes_text(mesh, mesh.tets, t), " uses ",
                      node_name(mesh, mesh.tets(t, a)), " twice: remove the collapsed element or re-mesh");
        }
      }
    }
  }

  // Volumes: degenerate tets are refused; inverted ones are flipped (on a copy, committed only on success).
  std::vector<double> vol(static_cast<std::size_t>(nt));
  double mean = 0;
  for (int t = 0; t < nt; ++t) {
    vol[t] = tet_volume(mesh, t);
    mean += std::abs(vol[t]);
  }
  mean /= nt;
  Eigen::MatrixX4i tets = mesh.tets;
  for (int t = 0; t < nt; ++t) {
    if (vol[t] == 0 || std::abs(vol[t]) < opts.min_volume_ratio * mean) {
      throw_error(file, ": ", tet_name(mesh, t), tet_nodes_text(mesh, tets, t), " has zero volume (", vol[t],
                  " m^3, mean ", mean,
                  " m^3): remove the flat element or re-mesh with quality optimization "
                  "(e.g. gmsh -3 -optimize_netgen)");
    }
    if (vol[t] < 0) {
      if (!opts.fix_orientation) {
        throw_error(file, ": ", tet_name(mesh, t), tet_nodes_text(mesh, tets, t), " is inverted (volume ", vol[t],
                    " m^3): its node order is reversed; set fix_orientation or swap two of its nodes");
      }
      std::swap(tets(t, 1), tets(t, 2));
    }
  }

  // Every node belongs to some tet (a stray node would get no stiffness and make K singular).
  std::vector<char> used(static_cast<std::size_t>(nv), 0);
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 4; ++k) used[tets(t, k)] = 1;
  }
  const auto unused = std::count(used.begin(), used.end(), 0);
  if (unused > 0) {
    const int first = static_cast<int>(std::find(used.begin(), used.end(), 0) - used.begin());
    throw_error(file, ": ", node_name(mesh, first), " is not used by any tetrahedron (", unused,
                " unused node(s) in all): remove them, e.g. export only the volume mesh");
  }

  // Each face belongs to one or two tets, and two tets sharing a face lie on opposite sides of it. Two positive
  // tets with their apexes on the same side overlap: a node pushed through a face (a tangled mesh whose inverted
  // element fix_orientation flipped, or whose writer re-ordered it) or the same element twice.
  const std::vector<Face> faces = sorted_faces(tets);
  std::vector<std::array<int, 3>> boundary;
  std::vector<int> boundary_tet;
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i > 2) {
      const auto& k = faces[i].key;
      throw_error(file, ": the face (", node_name(mesh, k[0]), ", ", node_name(mesh, k[1]), ", ", node_name(mesh, k[2]),
                  ") is shared by ", j - i, " tets, e.g. ", tet_name(mesh, faces[i].tet), " and ",
                  tet_name(mesh, faces[i + 2].tet), ": overlapping or duplicated elements; re-mesh");
    }
    if (j - i == 2 && apex_side(tets, faces[i]) == apex_side(tets, faces[i + 1])) {
      throw_folded(mesh, tets, vol, faces[i], faces[i + 1]);
    }
    if (j - i == 1) {
      boundary.push_back(faces[i].key);
      boundary_tet.push_back(faces[i].tet);
    }
    i = j;
  }

  // Each boundary edge belongs to exactly two boundary faces (a closed 2-manifold surface).
  struct Edge {
    int a, b, face;
  };
  std::vector<Edge> edges;
  edges.reserve(boundary.size() * 3);
  for (std::size_t f = 0; f < boundary.size(); ++f) {
    const auto& k = boundary[f];  // sorted, so each pair is (low, high)
    edges.push_back({k[0], k[1], static_cast<int>(f)});
    edges.push_back({k[0], k[2], static_cast<int>(f)});
    edges.push_back({k[1], k[2], static_cast<int>(f)});
  }
  std::sort(edges.begin(), edges.end(),
            [](const Edge& x, const Edge& y) { return std::tie(x.a, x.b, x.face) < std::tie(y.a, y.b, y.face); });
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j].a == edges[i].a && edges[j].b == edges[i].b) ++j;
    if (j - i != 2) {
      throw_error(file, ": the boundary edge (", node_name(mesh, edges[i].a), ", ", node_name(mesh, edges[i].b),
                  ") belongs to ", j - i, " boundary faces instead of 2, e.g. a face of ",
                  tet_name(mesh, boundary_tet[edges[i].face]),
                  ": the surface is non-manifold there (tets touching along an edge only); re-mesh or remove the "
                  "dangling elements");
    }
    i = j;
  }
  mesh.tets = std::move(tets);
}

}  // namespace surgsim::mesh
