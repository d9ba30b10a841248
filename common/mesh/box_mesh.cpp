#include "mesh/box_mesh.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <utility>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim::mesh {
namespace {

using Tet = std::array<int, 4>;

double signed_volume(const Eigen::MatrixX3d& x, const Tet& t) {
  Eigen::Matrix3d m;
  m.col(0) = (x.row(t[1]) - x.row(t[0])).transpose();
  m.col(1) = (x.row(t[2]) - x.row(t[0])).transpose();
  m.col(2) = (x.row(t[3]) - x.row(t[0])).transpose();
  return m.determinant() / 6.0;
}

// Copies tets into the mesh, swapping two nodes of each negatively oriented one.
void store_tets(TetMesh& mesh, const std::vector<Tet>& tets) {
  mesh.tets.resize(static_cast<Eigen::Index>(tets.size()), 4);
  for (std::size_t e = 0; e < tets.size(); ++e) {
    Tet t = tets[e];
    if (signed_volume(mesh.nodes, t) < 0) std::swap(t[2], t[3]);
    for (int a = 0; a < 4; ++a) mesh.tets(static_cast<Eigen::Index>(e), a) = t[static_cast<std::size_t>(a)];
  }
}

}  // namespace

TetMesh make_box_mesh(int nx, int ny, int nz, const Eigen::Vector3d& size, const Eigen::Vector3d& origin,
                      BoxSplit split) {
  if (nx < 1 || ny < 1 || nz < 1) throw_error("box mesh: cell counts must be >= 1, got ", nx, " x ", ny, " x ", nz);
  if (!(size.minCoeff() > 0) || !size.allFinite()) throw_error("box mesh: size must be positive and finite");
  TetMesh mesh;
  const int n = (nx + 1) * (ny + 1) * (nz + 1);
  mesh.nodes.resize(n, 3);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        mesh.nodes.row(box_node(nx, ny, i, j, k)) =
            (origin + Eigen::Vector3d(size.x() * i / nx, size.y() * j / ny, size.z() * k / nz)).transpose();

  // Cube corner c (bits x, y, z) of cell (i, j, k).
  std::vector<Tet> tets;
  tets.reserve(static_cast<std::size_t>(nx) * ny * nz * (split == BoxSplit::kSix ? 6 : 5));
  static const int kKuhn[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  static const int kFiveEven[5][4] = {{1, 2, 4, 7}, {0, 1, 2, 4}, {3, 1, 2, 7}, {5, 1, 4, 7}, {6, 2, 4, 7}};
  static const int kFiveOdd[5][4] = {{0, 3, 5, 6}, {1, 0, 3, 5}, {2, 0, 3, 6}, {4, 0, 5, 6}, {7, 3, 5, 6}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        int corner[8];
        for (int c = 0; c < 8; ++c) corner[c] = box_node(nx, ny, i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
        auto add = [&](const int (*pattern)[4], int count) {
          for (int t = 0; t < count; ++t)
            tets.push_back({corner[pattern[t][0]], corner[pattern[t][1]], corner[pattern[t][2]], corner[pattern[t][3]]});
        };
        if (split == BoxSplit::kSix)
          add(kKuhn, 6);
        else
          add(((i + j + k) % 2 == 0) ? kFiveEven : kFiveOdd, 5);
      }
  store_tets(mesh, tets);
  return mesh;
}

TetMesh make_box_mesh_with_nodes(int target_nodes, const Eigen::Vector3d& size) {
  if (target_nodes < 8) throw_error("box mesh: target node count must be >= 8, got ", target_nodes);
  // Cell edge h such that prod(size / h + 1) ~ target: bisect on h.
  auto count = [&](double h) {
    double p = 1;
    for (int a = 0; a < 3; ++a) p *= std::max(1.0, std::round(size[a] / h)) + 1;
    return p;
  };
  double lo = 1e-6 * size.maxCoeff(), hi = size.maxCoeff();
  for (int it = 0; it < 100; ++it) {
    const double mid = std::sqrt(lo * hi);
    (count(mid) > target_nodes ? lo : hi) = mid;
  }
  const double h = (std::abs(count(lo) - target_nodes) < std::abs(count(hi) - target_nodes)) ? lo : hi;
  auto cells = [&](int a) { return static_cast<int>(std::max(1.0, std::round(size[a] / h))); };
  return make_box_mesh(cells(0), cells(1), cells(2), size);
}

TetMesh make_cylinder_mesh(double radius, double height, int rings, int layers) {
  if (rings < 1 || layers < 1) throw_error("cylinder mesh: rings and layers must be >= 1, got ", rings, ", ", layers);
  if (!(radius > 0) || !(height > 0)) throw_error("cylinder mesh: radius and height must be positive");
  const double kPi = 3.14159265358979323846;

  // Disk: centre, then ring r (1..rings) of 6 r nodes starting on +x.
  std::vector<Eigen::Vector2d> disk{Eigen::Vector2d::Zero()};
  std::vector<int> ring_start{0, 1};
  for (int r = 1; r <= rings; ++r) {
    const int count = 6 * r;
    for (int p = 0; p < count; ++p) {
      const double a = 2 * kPi * p / count;
      disk.emplace_back(radius * r / rings * std::cos(a), radius * r / rings * std::sin(a));
    }
    ring_start.push_back(ring_start.back() + count);
  }

  // Triangles between consecutive rings, by walking both rings in angle ("zipper").
  std::vector<std::array<int, 3>> tris;
  for (int p = 0; p < 6; ++p) tris.push_back({0, 1 + p, 1 + (p + 1) % 6});
  for (int r = 2; r <= rings; ++r) {
    const int inner = 6 * (r - 1), outer = 6 * r;
    const int a0 = ring_start[static_cast<std::size_t>(r - 1)], b0 = ring_start[static_cast<std::size_t>(r)];
    int ia = 0, ib = 0;
    while (ia < inner || ib < outer) {
      // Advance on the ring whose next node comes first in angle: (ib + 1) / outer <= (ia + 1) / inner.
      const bool advance_outer = ia == inner || (ib < outer && (ib + 1) * inner <= (ia + 1) * outer);
      if (advance_outer) {
        tris.push_back({a0 + ia % inner, b0 + ib % outer, b0 + (ib + 1) % outer});
        ++ib;
      } else {
        tris.push_back({a0 + ia % inner, b0 + ib % outer, a0 + (ia + 1) % inner});
        ++ia;
      }
    }
  }

  TetMesh mesh;
  const int per_layer = static_cast<int>(disk.size());
  mesh.nodes.resize(per_layer * (layers + 1), 3);
  for (int l = 0; l <= layers; ++l)
    for (int p = 0; p < per_layer; ++p)
      mesh.nodes.row(l * per_layer + p) << disk[static_cast<std::size_t>(p)].x(), disk[static_cast<std::size_t>(p)].y(),
          height * l / layers;

  // Each prism (a, b, c) -> (a', b', c') with a < b < c is cut so that the diagonal of every quad face runs from the
  // lower-index bottom node to the higher-index top node; neighbouring prisms then agree on shared faces.
  std::vector<Tet> tets;
  tets.reserve(tris.size() * 3 * static_cast<std::size_t>(layers));
  for (int l = 0; l < layers; ++l)
    for (auto t : tris) {
      std::sort(t.begin(), t.end());
      const int a = l * per_layer + t[0], b = l * per_layer + t[1], c = l * per_layer + t[2];
      const int a1 = a + per_layer, b1 = b + per_layer, c1 = c + per_layer;
      tets.push_back({a, b, c, c1});
      tets.push_back({a, b, b1, c1});
      tets.push_back({a, a1, b1, c1});
    }
  store_tets(mesh, tets);
  return mesh;
}

}  // namespace surgsim::mesh
