#include "imaging/marching_cubes.h"

#include <Eigen/Geometry>
#include <array>
#include <unordered_map>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::imaging {
namespace {

constexpr int kMaxCaseEntries = 16;  // up to 5 triangles (15 edge indices) and the -1 terminator

// Edge e = 4 * axis + m joins the corner with bits (m & 1) on axis (axis + 1) % 3 and (m >> 1) on (axis + 2) % 3
// to the same corner with the axis bit set.
int edge_corner(int edge, int end) {
  const int axis = edge / 4, m = edge % 4;
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  return ((m & 1) << u) | ((m >> 1) << v) | (end << axis);
}

// The edge joining two corners that differ in one bit.
int edge_between(int c0, int c1) {
  const int diff = c0 ^ c1;
  const int axis = diff == 1 ? 0 : (diff == 2 ? 1 : 2);
  const int base = c0 & ~diff;
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  return 4 * axis + ((base >> u) & 1) + 2 * ((base >> v) & 1);
}

// True when two cube edges lie on a common face (a face is a corner bit held fixed).
bool share_face(int e0, int e1) {
  const int a0 = edge_corner(e0, 0), b0 = edge_corner(e0, 1), a1 = edge_corner(e1, 0), b1 = edge_corner(e1, 1);
  for (int axis = 0; axis < 3; ++axis) {
    const int bit = 1 << axis;
    for (int side = 0; side < 2; ++side) {
      const int want = side ? bit : 0;
      if ((a0 & bit) == want && (b0 & bit) == want && (a1 & bit) == want && (b1 & bit) == want) return true;
    }
  }
  return false;
}

Eigen::Vector3d corner_position(int c) { return Eigen::Vector3d(c & 1, (c >> 1) & 1, (c >> 2) & 1); }

Eigen::Vector3d edge_midpoint(int e) {
  return 0.5 * (corner_position(edge_corner(e, 0)) + corner_position(edge_corner(e, 1)));
}

using Table = std::array<std::array<std::int8_t, kMaxCaseEntries>, 256>;

// Builds the table from the face rule (see the header): per face, cuts (directed segments between two cut edges);
// the segments of a configuration are chained into loops and each loop is fanned from its first vertex.
Table build_table() {
  Table table;
  for (int config = 0; config < 256; ++config) {
    auto inside = [config](int c) { return ((config >> c) & 1) != 0; };
    std::array<int, 12> next;  // directed segment tail edge -> head edge, -1 where the edge is not cut
    next.fill(-1);
    for (int axis = 0; axis < 3; ++axis) {
      for (int side = 0; side < 2; ++side) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        // Corners counter-clockwise seen from +axis; the face's outward normal is +axis on side 1, -axis on side 0.
        const std::array<int, 4> q = {side << axis, (side << axis) | (1 << u), (side << axis) | (1 << u) | (1 << v),
                                      (side << axis) | (1 << v)};
        const Eigen::Vector3d normal = (side ? 1.0 : -1.0) * Eigen::Vector3d::Unit(axis);
        std::array<int, 4> e;  // e[m] joins q[m] and q[m + 1]
        for (int m = 0; m < 4; ++m) e[m] = edge_between(q[m], q[(m + 1) % 4]);
        // Each inside corner whose face neighbours are outside is cut off on its own (this separates diagonal
        // inside corners); a run of two adjacent inside corners is cut off together; three inside corners are the
        // outside corner's cut.
        std::vector<std::array<int, 3>> cuts;  // (edge, edge, an inside corner beside the cut)
        int count = 0;
        for (int m = 0; m < 4; ++m) count += inside(q[m]);
        for (int m = 0; m < 4; ++m) {
          const bool in = inside(q[m]), prev = inside(q[(m + 3) % 4]), nxt = inside(q[(m + 1) % 4]);
          if (count == 1 && in) cuts.push_back({e[(m + 3) % 4], e[m], q[m]});
          if (count == 3 && !in) cuts.push_back({e[(m + 3) % 4], e[m], nxt ? q[(m + 1) % 4] : q[(m + 3) % 4]});
          if (count == 2 && in && nxt) cuts.push_back({e[(m + 3) % 4], e[(m + 1) % 4], q[m]});
          if (count == 2 && in && !prev && !nxt) cuts.push_back({e[(m + 3) % 4], e[m], q[m]});
        }
        // Direct each cut p -> q so that the inside corner lies on its right seen from outside the cube: then the
        // loop runs counter-clockwise around the outward normal of the surface (pointing away from the inside).
        for (const auto& cut : cuts) {
          const Eigen::Vector3d p = edge_midpoint(cut[0]), r = edge_midpoint(cut[1]);
          const Eigen::Vector3d c = corner_position(cut[2]);
          const bool forward = (r - p).cross(c - p).dot(normal) < 0.0;
          const int tail = forward ? cut[0] : cut[1], head = forward ? cut[1] : cut[0];
          if (next[tail] != -1) throw_error("marching cubes table: edge ", tail, " starts two cuts (internal error)");
          next[tail] = head;
        }
      }
    }
    // Loops, each starting at its smallest edge; fans of (size - 2) triangles.
    std::array<bool, 12> done{};
    std::vector<int> entries;
    for (int start = 0; start < 12; ++start) {
      if (next[start] == -1 || done[start]) continue;
      std::vector<int> loop;
      for (int edge = start; !done[edge]; edge = next[edge]) {
        if (next[edge] == -1) throw_error("marching cubes table: open loop in case ", config, " (internal error)");
        done[edge] = true;
        loop.push_back(edge);
      }
      // Fan apex: the first loop vertex none of whose diagonals lies on a cube face. A diagonal on a face would be
      // an edge the neighbouring cube might also draw (four triangles on one edge) and a triangle lying in the face.
      const std::size_t n = loop.size();
      std::size_t apex = n;
      for (std::size_t a = 0; a < n && apex == n; ++a) {
        bool ok = true;
        for (std::size_t k = 2; k + 1 < n && ok; ++k) ok = !share_face(loop[a], loop[(a + k) % n]);
        if (ok) apex = a;
      }
      if (apex == n) throw_error("marching cubes table: no fan for a loop of case ", config, " (internal error)");
      for (std::size_t k = 1; k + 1 < n; ++k)
        entries.insert(entries.end(), {loop[apex], loop[(apex + k) % n], loop[(apex + k + 1) % n]});
    }
    if (entries.size() + 1 > kMaxCaseEntries)
      throw_error("marching cubes table: case ", config, " needs ", entries.size() / 3, " triangles (internal error)");
    table[config].fill(-1);
    for (std::size_t k = 0; k < entries.size(); ++k) table[config][k] = static_cast<std::int8_t>(entries[k]);
  }
  return table;
}

const Table& table() {
  static const Table t = build_table();
  return t;
}

}  // namespace

const std::int8_t* marching_cubes_case(int config) { return table().at(static_cast<std::size_t>(config & 255)).data(); }

int marching_cubes_edge_corner(int edge, int end) { return edge_corner(edge, end); }

TriSurface marching_cubes(const VoxelMask& mask) {
  const VoxelGrid& g = mask.grid;
  if (static_cast<std::int64_t>(mask.inside.size()) != g.voxel_count() || g.size.minCoeff() <= 0)
    throw_error(mask.source, ": marching cubes: the mask is empty or its size does not match its grid");
  const Table& cases = table();
  const int nx = g.size.x(), ny = g.size.y(), nz = g.size.z();
  auto inside = [&](int i, int j, int k) {
    return i >= 0 && j >= 0 && k >= 0 && i < nx && j < ny && k < nz && mask.at(i, j, k);
  };
  // Padded grid points run from -1 to n; a vertex is keyed by the padded index of its edge's first corner and axis.
  const std::int64_t px = nx + 2, py = ny + 2;
  auto edge_key = [&](int i, int j, int k, int axis) {
    return (((std::int64_t{k} + 1) * py + (j + 1)) * px + (i + 1)) * 3 + axis;
  };
  std::unordered_map<std::int64_t, int> vertex_of;
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3i> tris;
  for (int k = -1; k < nz; ++k) {
    for (int j = -1; j < ny; ++j) {
      for (int i = -1; i < nx; ++i) {
        int config = 0;
        for (int c = 0; c < 8; ++c)
          if (inside(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))) config |= 1 << c;
        if (config == 0 || config == 255) continue;
        const std::int8_t* entries = cases[static_cast<std::size_t>(config)].data();
        std::array<int, 3> tri;
        for (int n = 0; n < kMaxCaseEntries && entries[n] >= 0; ++n) {
          const int e = entries[n], c0 = edge_corner(e, 0), axis = e / 4;
          const int a = i + (c0 & 1), b = j + ((c0 >> 1) & 1), c = k + ((c0 >> 2) & 1);
          const auto [it, added] = vertex_of.emplace(edge_key(a, b, c, axis), static_cast<int>(vertices.size()));
          if (added) {
            Eigen::Vector3d p(a, b, c);
            p[axis] += 0.5;
            vertices.push_back(p.cwiseProduct(g.spacing));
          }
          tri[static_cast<std::size_t>(n % 3)] = it->second;
          if (n % 3 == 2) tris.emplace_back(tri[0], tri[1], tri[2]);
        }
      }
    }
  }
  TriSurface mesh;
  mesh.vertices.resize(static_cast<Eigen::Index>(vertices.size()), 3);
  for (std::size_t v = 0; v < vertices.size(); ++v) mesh.vertices.row(static_cast<Eigen::Index>(v)) = vertices[v];
  mesh.tris.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (std::size_t f = 0; f < tris.size(); ++f) mesh.tris.row(static_cast<Eigen::Index>(f)) = tris[f];
  return mesh;
}

}  // namespace surgsim::imaging
