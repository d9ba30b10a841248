// Tetrahedral meshes: read_mesh (the format chosen by extension), boundary extraction, tet volume and quality,
// hashing. The formats are format_msh.cpp, format_vtk.cpp and format_obj.cpp; validate_mesh is validate.cpp.
#include "mesh/mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/hash.h"
#include "core/text.h"
#include "mesh/mesh_internal.h"

using namespace surgsim::core;

namespace surgsim::mesh {
namespace internal {

std::string mesh_name(const TetMesh& mesh) { return mesh.source.empty() ? "<in-memory mesh>" : mesh.source; }

// Messages name nodes and tets by their file ids when the mesh came from a file.
std::string node_name(const TetMesh& mesh, int i) {
  if (i >= 0 && static_cast<std::size_t>(i) < mesh.ids.size()) return "node " + std::to_string(mesh.ids[i]);
  return "node index " + std::to_string(i);
}

std::string tet_name(const TetMesh& mesh, int t) {
  if (t >= 0 && static_cast<std::size_t>(t) < mesh.tet_ids.size()) return "element " + std::to_string(mesh.tet_ids[t]);
  return "tet " + std::to_string(t) + " (0-based)";
}

void check_indices(const TetMesh& mesh, const char* caller) {
  const auto nv = mesh.nodes.rows();
  for (int t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.tets(t, k);
      if (v < 0 || v >= nv) {
        throw_error(mesh_name(mesh), ": ", tet_name(mesh, t), " references node index ", v, " but the mesh has ", nv,
                    " nodes (", caller, "): call validate_mesh first");
      }
    }
  }
}

// All tet faces sorted by key, so that equal faces are adjacent.
std::vector<mesh::internal::Face> sorted_faces(const Eigen::MatrixX4i& tets) {
  std::vector<mesh::internal::Face> faces;
  faces.reserve(static_cast<std::size_t>(tets.rows()) * 4);
  for (int t = 0; t < tets.rows(); ++t) {
    for (int f = 0; f < 4; ++f) {
      Face face{{}, t, f};
      int j = 0;
      for (int k = 0; k < 4; ++k) {
        if (k != f) face.key[j++] = tets(t, k);
      }
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) {
    return std::tie(a.key, a.tet, a.local) < std::tie(b.key, b.tet, b.local);
  });
  return faces;
}

}  // namespace internal

namespace {

// Face of tet t opposite vertex f, oriented so that its normal points away from that vertex.
std::array<int, 3> outward_face(const Eigen::MatrixX3d& nodes, const Eigen::MatrixX4i& tets, int t, int f) {
  std::array<int, 3> tri{};
  int j = 0;
  for (int k = 0; k < 4; ++k) {
    if (k != f) tri[j++] = tets(t, k);
  }
  const Eigen::Vector3d a = nodes.row(tri[0]).transpose();
  const Eigen::Vector3d b = nodes.row(tri[1]).transpose();
  const Eigen::Vector3d c = nodes.row(tri[2]).transpose();
  const Eigen::Vector3d d = nodes.row(tets(t, f)).transpose();
  if ((b - a).cross(c - a).dot(d - a) > 0) std::swap(tri[1], tri[2]);
  return tri;
}

}  // namespace

using internal::check_indices;
using internal::Face;
using internal::sorted_faces;

TetMesh read_mesh(const std::string& path) {
  const std::size_t slash = path.find_last_of("/\\");
  const std::size_t dot = path.find_last_of('.');
  const std::string ext = core::text::lower(
      (dot == std::string::npos || (slash != std::string::npos && dot < slash)) ? "" : path.substr(dot));
  if (ext == ".msh") return read_msh(path);
  if (ext == ".vtk") return read_vtk(path);
  throw_error(path, ": unsupported mesh file extension '", ext,
              "': supported are .msh (Gmsh v1, v2, v4 ASCII) and .vtk (VTK legacy ASCII unstructured grid)");
}

double tet_volume(const TetMesh& mesh, int t) {
  const Eigen::Vector3d x0 = mesh.nodes.row(mesh.tets(t, 0)).transpose();
  const Eigen::Vector3d x1 = mesh.nodes.row(mesh.tets(t, 1)).transpose();
  const Eigen::Vector3d x2 = mesh.nodes.row(mesh.tets(t, 2)).transpose();
  const Eigen::Vector3d x3 = mesh.nodes.row(mesh.tets(t, 3)).transpose();
  return (x1 - x0).dot((x2 - x0).cross(x3 - x0)) / 6.0;
}

double tet_quality(const TetMesh& mesh, int t) {
  double sum = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) sum += (mesh.nodes.row(mesh.tets(t, a)) - mesh.nodes.row(mesh.tets(t, b))).squaredNorm();
  const double l_rms = std::sqrt(sum / 6);
  return l_rms > 0 ? 6 * std::sqrt(2.0) * std::abs(tet_volume(mesh, t)) / (l_rms * l_rms * l_rms) : 0.0;
}

NodeTriangles node_triangles(const SurfaceMesh& surface, int node_count) {
  NodeTriangles t;
  t.start.assign(static_cast<std::size_t>(node_count) + 1, 0);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f)
    for (int e = 0; e < 3; ++e) ++t.start[static_cast<std::size_t>(surface.tris(f, e)) + 1];
  for (int n = 0; n < node_count; ++n) t.start[static_cast<std::size_t>(n) + 1] += t.start[static_cast<std::size_t>(n)];
  t.list.resize(static_cast<std::size_t>(t.start.back()));
  std::vector<int> fill(t.start.begin(), t.start.end() - 1);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f)
    for (int e = 0; e < 3; ++e)
      t.list[static_cast<std::size_t>(fill[static_cast<std::size_t>(surface.tris(f, e))]++)] = static_cast<int>(f);
  return t;
}

SurfaceMesh boundary_surface(const TetMesh& mesh) {
  check_indices(mesh, "boundary_surface");
  const std::vector<Face> faces = sorted_faces(mesh.tets);
  // A face met once belongs to one tet only: it is on the boundary.
  std::vector<std::pair<int, int>> owners;  // (tet, local face), in tet order
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) owners.emplace_back(faces[i].tet, faces[i].local);
    i = j;
  }
  std::sort(owners.begin(), owners.end());
  SurfaceMesh s;
  s.tris.resize(static_cast<Eigen::Index>(owners.size()), 3);
  for (std::size_t f = 0; f < owners.size(); ++f) {
    const std::array<int, 3> tri = outward_face(mesh.nodes, mesh.tets, owners[f].first, owners[f].second);
    for (int k = 0; k < 3; ++k) {
      s.tris(static_cast<Eigen::Index>(f), k) = tri[k];
      s.nodes.push_back(tri[k]);
    }
  }
  std::sort(s.nodes.begin(), s.nodes.end());
  s.nodes.erase(std::unique(s.nodes.begin(), s.nodes.end()), s.nodes.end());
  return s;
}

std::uint64_t mesh_hash(const TetMesh& mesh) {
  Hasher h;
  h.value<std::uint64_t>(static_cast<std::uint64_t>(mesh.nodes.rows()));
  for (Eigen::Index i = 0; i < mesh.nodes.rows(); ++i) {
    for (int c = 0; c < 3; ++c) {
      // +0 and -0 compare equal, so they hash equal.
      const double v = mesh.nodes(i, c) == 0.0 ? 0.0 : mesh.nodes(i, c);
      h.value(v);
    }
  }
  h.value<std::uint64_t>(static_cast<std::uint64_t>(mesh.tets.rows()));
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) h.value<std::int32_t>(mesh.tets(t, k));
  }
  return h.digest();
}

}  // namespace surgsim::mesh
