#include "imaging/surface_smoothing.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::imaging {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Unit area-weighted vertex normals (zero for a vertex no triangle uses).
Eigen::MatrixX3d vertex_normals(const TriSurface& mesh) {
  Eigen::MatrixX3d normals = Eigen::MatrixX3d::Zero(mesh.vertices.rows(), 3);
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f) {
    const Eigen::RowVector3d a = mesh.vertices.row(mesh.tris(f, 0));
    const Eigen::RowVector3d n = (mesh.vertices.row(mesh.tris(f, 1)) - a).cross(mesh.vertices.row(mesh.tris(f, 2)) - a);
    for (int k = 0; k < 3; ++k) normals.row(mesh.tris(f, k)) += n;
  }
  for (Eigen::Index v = 0; v < normals.rows(); ++v) {
    const double len = normals.row(v).norm();
    if (len > 0.0) normals.row(v) /= len;
  }
  return normals;
}

// The bounds restore_volume keeps, checked on the moved surface against the surface it started from: a vertex, a
// triangle's centroid or an edge's midpoint that was within `max_distance` of the voxel boundary must stay so, and
// no triangle may turn by more than the angle whose cosine is `cos_turn`. (What was out of bound at the start, a
// smoothing clamp being per vertex, is not the offset's doing.)
class VolumeBounds {
 public:
  VolumeBounds(const TriSurface& start, const VoxelBoundaryDistance& boundary, double max_distance, double cos_turn)
      : start_(start), boundary_(boundary), d_(max_distance), cos_turn_(cos_turn) {
    vertex_within_.resize(static_cast<std::size_t>(start.vertices.rows()));
    for (Eigen::Index v = 0; v < start.vertices.rows(); ++v)
      vertex_within_[static_cast<std::size_t>(v)] = within(start.vertices.row(v));
    face_within_.resize(static_cast<std::size_t>(start.tris.rows()));
    for (Eigen::Index f = 0; f < start.tris.rows(); ++f) {
      const auto points = face_points(start.vertices, f);
      for (std::size_t k = 0; k < points.size(); ++k) face_within_[static_cast<std::size_t>(f)][k] = within(points[k]);
    }
  }

  // Marks (sets to 1) the vertices of every bound `moved` breaks; returns how many bounds broke.
  int broken(const Eigen::MatrixX3d& moved, std::vector<char>& marks) const {
    int count = 0;
    for (Eigen::Index v = 0; v < moved.rows(); ++v) {
      if (vertex_within_[static_cast<std::size_t>(v)] && !within(moved.row(v))) {
        marks[static_cast<std::size_t>(v)] = 1;
        ++count;
      }
    }
    for (Eigen::Index f = 0; f < start_.tris.rows(); ++f) {
      const auto points = face_points(moved, f);
      bool ok = !turned(moved, f);
      for (std::size_t k = 0; ok && k < points.size(); ++k)
        ok = !face_within_[static_cast<std::size_t>(f)][k] || within(points[k]);
      if (ok) continue;
      for (int k = 0; k < 3; ++k) marks[static_cast<std::size_t>(start_.tris(f, k))] = 1;
      ++count;
    }
    return count;
  }

 private:
  bool within(const Eigen::Vector3d& p) const { return boundary_.within(p, d_); }

  // A triangle's centroid and its edges' midpoints.
  std::array<Eigen::Vector3d, 4> face_points(const Eigen::MatrixX3d& x, Eigen::Index f) const {
    const Eigen::Vector3d a = x.row(start_.tris(f, 0)), b = x.row(start_.tris(f, 1)), c = x.row(start_.tris(f, 2));
    return {(a + b + c) / 3.0, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)};
  }

  bool turned(const Eigen::MatrixX3d& moved, Eigen::Index f) const {
    auto normal = [this, f](const Eigen::MatrixX3d& x) -> Eigen::Vector3d {
      const Eigen::Vector3d a = x.row(start_.tris(f, 0)), b = x.row(start_.tris(f, 1)), c = x.row(start_.tris(f, 2));
      return (b - a).cross(c - a);
    };
    const Eigen::Vector3d n_old = normal(start_.vertices), n_new = normal(moved);
    return n_old.norm() > 0.0 && n_new.dot(n_old) <= cos_turn_ * n_new.norm() * n_old.norm();
  }

  const TriSurface& start_;
  const VoxelBoundaryDistance& boundary_;
  double d_, cos_turn_;
  std::vector<char> vertex_within_;
  std::vector<std::array<char, 4>> face_within_;
};

}  // namespace

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

VolumeRestoreReport restore_volume(TriSurface& mesh, const VoxelBoundaryDistance& boundary,
                                   const VolumeRestoreOptions& options) {
  if (!(options.target_volume > 0.0)) throw_error("volume restoration: the target volume must be positive");
  if (!(options.max_distance > 0.0)) throw_error("volume restoration: the maximum distance must be positive");
  if (!(options.max_normal_turn_deg > 0.0 && options.max_normal_turn_deg < 90.0))
    throw_error("volume restoration: the normal turn limit must be in (0, 90) degrees");
  if (options.rounds < 1) throw_error("volume restoration: rounds must be >= 1, got ", options.rounds);
  VolumeRestoreReport report;
  report.volume_before = tri_surface_volume(mesh);
  const TriSurface start = mesh;
  const Eigen::MatrixX3d normals = vertex_normals(start);
  const VolumeBounds bounds(start, boundary, options.max_distance, std::cos(options.max_normal_turn_deg * kPi / 180.0));
  const Eigen::Index n = start.vertices.rows();
  // Each vertex moves by the offset clamped to its own cap; a cap shrinks when the vertex breaks a bound. No vertex
  // moves farther than twice the distance bound: it would leave the bound.
  const double reach = 2.0 * options.max_distance;
  std::vector<double> cap(static_cast<std::size_t>(n), reach);
  auto place = [&](double offset) {
    for (Eigen::Index v = 0; v < n; ++v)
      mesh.vertices.row(v) =
          start.vertices.row(v) +
          std::clamp(offset, -cap[static_cast<std::size_t>(v)], cap[static_cast<std::size_t>(v)]) * normals.row(v);
  };
  // The enclosed volume grows with the offset (its derivative at 0 is the area): bisection on [-reach, reach],
  // ending at an end when the target lies beyond what the caps allow.
  auto solve = [&] {
    double lo = -reach, hi = reach;
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi);
      place(mid);
      (tri_surface_volume(mesh) < options.target_volume ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
  };
  std::vector<char> marks(static_cast<std::size_t>(n), 0);
  for (int round = 0; round < options.rounds; ++round) {
    report.offset = solve();
    place(report.offset);
    std::fill(marks.begin(), marks.end(), 0);
    if (bounds.broken(mesh.vertices, marks) == 0) break;
    for (Eigen::Index v = 0; v < n; ++v) {
      auto& c = cap[static_cast<std::size_t>(v)];
      if (marks[static_cast<std::size_t>(v)] != 0) c = 0.5 * std::min(c, std::fabs(report.offset));
    }
  }
  // What still breaks a bound after the last solve stays where it was (at the start every bound that held holds).
  while (true) {
    place(report.offset);
    std::fill(marks.begin(), marks.end(), 0);
    if (bounds.broken(mesh.vertices, marks) == 0) break;
    for (Eigen::Index v = 0; v < n; ++v)
      if (marks[static_cast<std::size_t>(v)] != 0) cap[static_cast<std::size_t>(v)] = 0.0;
  }
  for (Eigen::Index v = 0; v < n; ++v)
    if (cap[static_cast<std::size_t>(v)] < std::fabs(report.offset) && normals.row(v).squaredNorm() > 0.0)
      ++report.held;
  report.volume_after = tri_surface_volume(mesh);
  return report;
}

}  // namespace surgsim::imaging
