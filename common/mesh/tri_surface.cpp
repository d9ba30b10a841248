// Measures and checks of a TriSurface: topology (edges, fans, components), enclosed volume, area, triangle quality.
#include "mesh/tri_surface.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/union_find.h"

using namespace surgsim::core;

namespace surgsim::mesh {

TriSurfaceTopology tri_surface_topology(const TriSurface& mesh) {
  TriSurfaceTopology t;
  const int nv = static_cast<int>(mesh.vertices.rows());
  const int nf = static_cast<int>(mesh.tris.rows());
  // Directed half-edges (from, to, face), sorted by undirected edge.
  struct HalfEdge {
    int a, b, face;
  };
  std::vector<HalfEdge> half;
  half.reserve(static_cast<std::size_t>(3 * nf));
  std::vector<char> used(static_cast<std::size_t>(nv), 0);
  for (int f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      half.push_back({mesh.tris(f, k), mesh.tris(f, (k + 1) % 3), f});
      used[static_cast<std::size_t>(mesh.tris(f, k))] = 1;
    }
  }
  t.vertices = static_cast<int>(std::count(used.begin(), used.end(), 1));
  auto key = [](const HalfEdge& h) { return std::minmax(h.a, h.b); };
  std::sort(half.begin(), half.end(), [&key](const HalfEdge& x, const HalfEdge& y) { return key(x) < key(y); });

  std::vector<int> face_parent(static_cast<std::size_t>(nf));
  std::iota(face_parent.begin(), face_parent.end(), 0);
  for (std::size_t i = 0; i < half.size();) {
    std::size_t j = i;
    while (j < half.size() && key(half[j]) == key(half[i])) ++j;
    ++t.edges;
    const std::size_t n = j - i;
    if (n == 1) ++t.boundary_edges;
    if (n > 2 || (n == 2 && half[i].a == half[i + 1].a)) ++t.nonmanifold_edges;
    const int first_face = half[i].face;
    for (auto it = half.begin() + static_cast<std::ptrdiff_t>(i) + 1; it != half.begin() + static_cast<std::ptrdiff_t>(j); ++it)
      face_parent[static_cast<std::size_t>(find_root(face_parent, it->face))] = find_root(face_parent, first_face);
    i = j;
  }
  for (int f = 0; f < nf; ++f)
    if (find_root(face_parent, f) == f) ++t.components;

  // Fans: around each vertex, join its triangles that share an edge through it; more than one group = pinched.
  std::vector<std::vector<int>> vertex_faces(static_cast<std::size_t>(nv));
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) vertex_faces[static_cast<std::size_t>(mesh.tris(f, k))].push_back(f);
  for (int v = 0; v < nv; ++v) {
    const auto& faces = vertex_faces[static_cast<std::size_t>(v)];
    if (faces.size() < 2) continue;
    std::vector<int> parent(faces.size());
    std::iota(parent.begin(), parent.end(), 0);
    for (std::size_t x = 0; x < faces.size(); ++x) {
      for (std::size_t y = x + 1; y < faces.size(); ++y) {
        int shared = 0;
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b)
            if (mesh.tris(faces[x], a) == mesh.tris(faces[y], b) && mesh.tris(faces[x], a) != v) ++shared;
        if (shared > 0) parent[static_cast<std::size_t>(find_root(parent, static_cast<int>(x)))] = find_root(parent, static_cast<int>(y));
      }
    }
    int groups = 0;
    for (std::size_t x = 0; x < faces.size(); ++x)
      if (find_root(parent, static_cast<int>(x)) == static_cast<int>(x)) ++groups;
    if (groups > 1) ++t.nonmanifold_vertices;
  }
  t.euler = t.vertices - t.edges + nf;
  return t;
}

double tri_surface_volume(const TriSurface& mesh) {
  double v = 0.0;
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.tris(f, 0));
    const Eigen::Vector3d b = mesh.vertices.row(mesh.tris(f, 1));
    const Eigen::Vector3d c = mesh.vertices.row(mesh.tris(f, 2));
    v += a.dot(b.cross(c)) / 6.0;
  }
  return v;
}

double tri_surface_area(const TriSurface& mesh) {
  double area = 0.0;
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.tris(f, 0));
    const Eigen::Vector3d b = mesh.vertices.row(mesh.tris(f, 1));
    const Eigen::Vector3d c = mesh.vertices.row(mesh.tris(f, 2));
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

double tri_surface_min_quality(const TriSurface& mesh) {
  double worst = 1.0;
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.tris(f, 0));
    const Eigen::Vector3d b = mesh.vertices.row(mesh.tris(f, 1));
    const Eigen::Vector3d c = mesh.vertices.row(mesh.tris(f, 2));
    const double l2 = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
    const double q = l2 > 0.0 ? 2.0 * std::sqrt(3.0) * (b - a).cross(c - a).norm() / l2 : 0.0;
    worst = std::min(worst, q);
  }
  return worst;
}

void compact_tri_surface(TriSurface& mesh) {
  std::vector<int> remap(static_cast<std::size_t>(mesh.vertices.rows()), -1);
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f)
    for (int k = 0; k < 3; ++k) remap[static_cast<std::size_t>(mesh.tris(f, k))] = 0;
  int n = 0;
  for (int& r : remap)
    if (r == 0) r = n++;
  Eigen::MatrixX3d vertices(n, 3);
  for (std::size_t v = 0; v < remap.size(); ++v)
    if (remap[v] >= 0) vertices.row(remap[v]) = mesh.vertices.row(static_cast<Eigen::Index>(v));
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f)
    for (int k = 0; k < 3; ++k) mesh.tris(f, k) = remap[static_cast<std::size_t>(mesh.tris(f, k))];
  mesh.vertices = std::move(vertices);
}

void check_closed_surface(const TriSurface& mesh, const std::string& what) {
  if (mesh.tris.rows() == 0) throw_error(what, ": the surface has no triangles");
  if (!mesh.vertices.allFinite()) throw_error(what, ": the surface has non-finite coordinates");
  const TriSurfaceTopology t = tri_surface_topology(mesh);
  if (!t.closed_manifold())
    throw_error(what, ": the surface is not a closed 2-manifold (", t.boundary_edges, " open edges, ",
                t.nonmanifold_edges, " non-manifold or inconsistently oriented edges, ", t.nonmanifold_vertices,
                " pinched vertices)");
  if (t.components != 1) throw_error(what, ": the surface has ", t.components, " separate parts (expected one)");
  if (!(tri_surface_volume(mesh) > 0.0)) throw_error(what, ": the surface encloses no positive volume (faces inward?)");
}

}  // namespace surgsim::mesh
