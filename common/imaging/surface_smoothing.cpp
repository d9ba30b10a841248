#include "imaging/surface_smoothing.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::imaging {

std::vector<std::vector<int>> vertex_neighbours(const TriSurface& mesh) {
  std::vector<std::vector<int>> ring(static_cast<std::size_t>(mesh.vertices.rows()));
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      ring[static_cast<std::size_t>(mesh.tris(f, k))].push_back(mesh.tris(f, (k + 1) % 3));
      ring[static_cast<std::size_t>(mesh.tris(f, k))].push_back(mesh.tris(f, (k + 2) % 3));
    }
  }
  for (auto& r : ring) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }
  return ring;
}

SmoothingReport smooth_surface(TriSurface& mesh, const VoxelBoundaryDistance& boundary, const SmoothingOptions& options) {
  if (options.iterations < 0) throw_error("smoothing: iterations must be >= 0, got ", options.iterations);
  if (!(options.lambda > 0.0 && options.lambda < 1.0)) throw_error("smoothing: lambda must be in (0, 1)");
  if (!(options.mu < -options.lambda)) throw_error("smoothing: mu must be below -lambda");
  if (!(options.max_distance > 0.0)) throw_error("smoothing: the maximum distance must be positive");
  SmoothingReport report;
  const auto ring = vertex_neighbours(mesh);
  const Eigen::Index n = mesh.vertices.rows();
  const Eigen::MatrixX3d start = mesh.vertices;
  Eigen::MatrixX3d next(n, 3);
  const double d = options.max_distance;
  for (int step = 0; step < 2 * options.iterations; ++step) {
    const double factor = step % 2 == 0 ? options.lambda : options.mu;
    for (Eigen::Index v = 0; v < n; ++v) {
      const auto& r = ring[static_cast<std::size_t>(v)];
      if (r.empty()) {
        next.row(v) = mesh.vertices.row(v);
        continue;
      }
      Eigen::RowVector3d mean = Eigen::RowVector3d::Zero();
      for (int w : r) mean += mesh.vertices.row(w);
      mean /= static_cast<double>(r.size());
      next.row(v) = mesh.vertices.row(v) + factor * (mean - mesh.vertices.row(v));
    }
    // Clamp: a vertex farther than d from the voxel boundary goes back to distance d along the line to its nearest
    // boundary point. A step moves a vertex by less than the umbrella's size, so searching within d plus that
    // length finds the nearest point; if not (a degenerate ring), the vertex keeps its previous position.
    for (Eigen::Index v = 0; v < n; ++v) {
      const Eigen::Vector3d p = next.row(v).transpose();
      if (boundary.within(p, d)) continue;
      ++report.clamped;
      const double reach = d + 2.0 * (p - mesh.vertices.row(v).transpose()).norm();
      Eigen::Vector3d q;
      const double dist = boundary.distance(p, reach, &q);
      if (dist >= reach || dist <= 0.0) {
        next.row(v) = mesh.vertices.row(v);
      } else {
        next.row(v) = (q + (p - q) * (d * (1.0 - 1e-9) / dist)).transpose();
      }
    }
    mesh.vertices.swap(next);
    ++report.steps;
  }
  for (Eigen::Index v = 0; v < n; ++v) {
    report.max_distance = std::max(report.max_distance, boundary.distance(mesh.vertices.row(v).transpose(), 4.0 * d));
    report.mean_move += (mesh.vertices.row(v) - start.row(v)).norm();
  }
  if (n > 0) report.mean_move /= static_cast<double>(n);
  return report;
}

}  // namespace surgsim::imaging
