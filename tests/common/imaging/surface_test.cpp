// Tests for the surface stages of common/imaging: distances (surface_distance.cpp, voxel_boundary.cpp), the
// constrained smoothing (surface_smoothing.cpp) and the adaptive reduction and improvement (surface_decimation.cpp).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "mesh/tri_surface.h"
#include "imaging/marching_cubes.h"
#include "imaging/surface_decimation.h"
#include "imaging/surface_distance.h"
#include "imaging/surface_smoothing.h"
#include "imaging/voxel_boundary.h"

using namespace surgsim::mesh;
using namespace surgsim::imaging;

namespace surgsim {
namespace {

constexpr double kVoxel = 0.001;  // m

// A voxelized ellipsoid with semi-axes (a, b, c) voxels, centred in its grid.
VoxelMask ellipsoid(double a, double b, double c) {
  VoxelMask m;
  m.grid.size = Eigen::Vector3i(static_cast<int>(2 * a) + 6, static_cast<int>(2 * b) + 6, static_cast<int>(2 * c) + 6);
  m.grid.spacing = Eigen::Vector3d::Constant(kVoxel);
  m.inside.assign(static_cast<std::size_t>(m.grid.voxel_count()), 0);
  m.source = "ellipsoid";
  const Eigen::Vector3d centre = (m.grid.size.cast<double>() - Eigen::Vector3d::Ones()) / 2.0;
  for (int k = 0; k < m.grid.size.z(); ++k)
    for (int j = 0; j < m.grid.size.y(); ++j)
      for (int i = 0; i < m.grid.size.x(); ++i) {
        const double x = (i - centre.x()) / a, y = (j - centre.y()) / b, z = (k - centre.z()) / c;
        if (x * x + y * y + z * z <= 1.0) m.inside[static_cast<std::size_t>(m.grid.index(i, j, k))] = 1;
      }
  return m;
}

// Signed radial error of each vertex against the sphere of radius r (m) centred in the mask's grid.
double rms_sphere_error(const TriSurface& s, const VoxelMask& m, double r) {
  const Eigen::Vector3d centre = (m.grid.size.cast<double>() - Eigen::Vector3d::Ones()) / 2.0 * kVoxel;
  double sum = 0.0;
  for (Eigen::Index v = 0; v < s.vertices.rows(); ++v) {
    const double e = (s.vertices.row(v).transpose() - centre).norm() - r;
    sum += e * e;
  }
  return std::sqrt(sum / static_cast<double>(s.vertices.rows()));
}

TEST(SurfaceDistance, ClosestPointOnTriangleMatchesBruteForce) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0.2), c(0.3, 0.8, -0.1);
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::Vector3d p(2 * u(rng), 2 * u(rng), 2 * u(rng));
    const double d = (closest_point_on_triangle(p, a, b, c) - p).norm();
    double best = 1e9;
    for (int i = 0; i <= 200; ++i)
      for (int j = 0; i + j <= 200; ++j) best = std::min(best, (a + (b - a) * (i / 200.0) + (c - a) * (j / 200.0) - p).norm());
    EXPECT_LE(d, best + 1e-12);
    EXPECT_NEAR(d, best, 0.01);
  }
}

TEST(SurfaceDistance, TreeAndHausdorffOnSpheres) {
  VoxelMask m = ellipsoid(8, 8, 8);
  const TriSurface s = marching_cubes(m);
  const TriangleTree tree(s);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-0.02, 0.03);
  for (int trial = 0; trial < 100; ++trial) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    double best = 1e9;
    for (Eigen::Index f = 0; f < s.tris.rows(); ++f)
      best = std::min(best, (closest_point_on_triangle(p, s.vertices.row(s.tris(f, 0)), s.vertices.row(s.tris(f, 1)),
                                                       s.vertices.row(s.tris(f, 2))) - p).norm());
    EXPECT_NEAR(tree.distance(p), best, 1e-12);
  }
  // The same surface: 0. The surface moved by 1 mm: Hausdorff and mean 1 mm.
  EXPECT_NEAR(surface_distance(s, s, 0.0005).hausdorff, 0.0, 1e-12);
  TriSurface moved = s;
  moved.vertices.col(0).array() += 0.001;
  const SurfaceDistance d = surface_distance(s, moved, 0.0003);
  EXPECT_NEAR(d.hausdorff, 0.001, 1e-4);
  EXPECT_GT(d.mean, 0.0);
  EXPECT_LE(d.mean, 0.001 + 1e-12);
}

TEST(VoxelBoundary, DistanceMatchesTheVoxelFaces) {
  VoxelMask m = ellipsoid(4, 3, 3);
  const VoxelBoundaryDistance boundary(m);
  const TriSurface mc = marching_cubes(m);
  EXPECT_GT(boundary.face_count(), 0);
  // Brute force over every boundary face (faces between inside and outside voxels, outside the grid = outside).
  auto inside = [&m](int i, int j, int k) {
    return i >= 0 && j >= 0 && k >= 0 && i < m.grid.size.x() && j < m.grid.size.y() && k < m.grid.size.z() &&
           m.at(i, j, k);
  };
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Vector3d p = m.grid.size.cast<double>().cwiseProduct(Eigen::Vector3d(u(rng), u(rng), u(rng))) * kVoxel;
    double best = 1e9;
    for (int k = -1; k < m.grid.size.z(); ++k)
      for (int j = -1; j < m.grid.size.y(); ++j)
        for (int i = -1; i < m.grid.size.x(); ++i)
          for (int a = 0; a < 3; ++a) {
            const int di = a == 0, dj = a == 1, dk = a == 2;
            if (inside(i, j, k) == inside(i + di, j + dj, k + dk)) continue;
            Eigen::Vector3d q;
            const int v[3] = {i, j, k};
            for (int c = 0; c < 3; ++c)
              q[c] = c == a ? (v[c] + 0.5) * kVoxel : std::clamp(p[c], (v[c] - 0.5) * kVoxel, (v[c] + 0.5) * kVoxel);
            best = std::min(best, (q - p).norm());
          }
    EXPECT_NEAR(boundary.distance(p, 1.0), best, 1e-12);
    EXPECT_EQ(boundary.within(p, best * 1.001 + 1e-15), true);
    if (best > 1e-6) {
      EXPECT_FALSE(boundary.within(p, best * 0.999));
    }
    EXPECT_DOUBLE_EQ(boundary.distance(p, best * 0.5), best > 0 ? best * 0.5 : 0.0);
  }
}

TEST(SurfaceSmoothing, RemovesTheStaircaseWithinTheBound) {
  const double r = 10.0;
  VoxelMask m = ellipsoid(r, r, r);
  const VoxelBoundaryDistance boundary(m);
  TriSurface s = marching_cubes(m);
  const double before = rms_sphere_error(s, m, r * kVoxel);
  SmoothingOptions o;
  o.max_distance = 1.0 * kVoxel;
  const SmoothingReport rep = smooth_surface(s, boundary, o);
  EXPECT_EQ(rep.steps, 2 * o.iterations);
  EXPECT_LE(rep.max_distance, o.max_distance);
  EXPECT_LT(rms_sphere_error(s, m, r * kVoxel), 0.5 * before);
  EXPECT_TRUE(tri_surface_topology(s).closed_manifold());

  // A tighter bound than the smoothing wants (it moved vertices up to rep.max_distance): the clamp engages and
  // holds.
  TriSurface t = marching_cubes(m);
  o.max_distance = 0.5 * rep.max_distance;
  const SmoothingReport tight = smooth_surface(t, boundary, o);
  EXPECT_GT(tight.clamped, 0);
  EXPECT_LE(tight.max_distance, o.max_distance);
}

// A voxelized ellipsoid's surface as the pipeline leaves it before the volume is restored: marching cubes,
// smoothed, reduced to `vertices` (coarse: its chords cut inside), all within one voxel of the voxel boundary.
TriSurface reduced_surface(const VoxelMask& m, const VoxelBoundaryDistance& boundary, int vertices) {
  TriSurface s = marching_cubes(m);
  SmoothingOptions so;
  so.max_distance = kVoxel;
  smooth_surface(s, boundary, so);
  DecimationOptions o;
  o.max_distance = kVoxel;
  o.target_vertices = vertices;
  decimate_surface(s, &boundary, o);
  return s;
}

// Which of a surface's vertices, triangle centroids and edge midpoints are within d of the voxel boundary.
std::vector<bool> points_within(const TriSurface& s, const VoxelBoundaryDistance& boundary, double d) {
  std::vector<bool> out;
  for (Eigen::Index v = 0; v < s.vertices.rows(); ++v) out.push_back(boundary.within(s.vertices.row(v).transpose(), d));
  for (Eigen::Index f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = s.vertices.row(s.tris(f, 0)), b = s.vertices.row(s.tris(f, 1)),
                          c = s.vertices.row(s.tris(f, 2));
    for (const Eigen::Vector3d& p : {Eigen::Vector3d((a + b + c) / 3.0), Eigen::Vector3d(0.5 * (a + b)),
                                     Eigen::Vector3d(0.5 * (b + c)), Eigen::Vector3d(0.5 * (c + a))})
      out.push_back(boundary.within(p, d));
  }
  return out;
}

TEST(SurfaceVolume, RestoresTheVoxelVolumeWithinTheBound) {
  VoxelMask m = ellipsoid(12, 8, 6);
  const VoxelBoundaryDistance boundary(m);
  TriSurface s = reduced_surface(m, boundary, 150);
  const double voxels = static_cast<double>(m.count()) * kVoxel * kVoxel * kVoxel;
  const double before = tri_surface_volume(s);
  EXPECT_LT(before, 0.98 * voxels);  // what there is to restore: the corners and chords cut off
  const Eigen::MatrixX3i tris = s.tris;
  VolumeRestoreOptions o;
  o.target_volume = voxels;
  o.max_distance = kVoxel;
  const VolumeRestoreReport rep = restore_volume(s, boundary, o);
  EXPECT_NEAR(tri_surface_volume(s) / voxels, 1.0, 1e-9);
  EXPECT_DOUBLE_EQ(rep.volume_before, before);
  EXPECT_DOUBLE_EQ(rep.volume_after, tri_surface_volume(s));
  // Outward by a fraction of a voxel, the same for every vertex; the triangles and the bound kept.
  EXPECT_GT(rep.offset, 0.0);
  EXPECT_LT(rep.offset, 0.5 * kVoxel);
  EXPECT_EQ(rep.held, 0);
  EXPECT_EQ(s.tris, tris);
  for (bool within : points_within(s, boundary, kVoxel)) EXPECT_TRUE(within);

  // And inward when the surface holds too much.
  o.target_volume = 0.98 * voxels;
  const VolumeRestoreReport in = restore_volume(s, boundary, o);
  EXPECT_LT(in.offset, 0.0);
  EXPECT_NEAR(tri_surface_volume(s) / o.target_volume, 1.0, 1e-9);
}

TEST(SurfaceVolume, HoldsBackWhatWouldLeaveTheBound) {
  VoxelMask m = ellipsoid(12, 8, 6);
  const VoxelBoundaryDistance boundary(m);
  TriSurface s = reduced_surface(m, boundary, 150);
  const double voxels = static_cast<double>(m.count()) * kVoxel * kVoxel * kVoxel;
  const std::vector<bool> within_before = points_within(s, boundary, kVoxel);
  // Half as much again as the voxels: a surface within a voxel of them cannot enclose that.
  VolumeRestoreOptions o;
  o.target_volume = 1.5 * voxels;
  o.max_distance = kVoxel;
  const VolumeRestoreReport rep = restore_volume(s, boundary, o);
  EXPECT_GT(rep.held, 0);
  EXPECT_GT(rep.volume_after, voxels);
  EXPECT_LT(rep.volume_after, o.target_volume);
  const std::vector<bool> within_after = points_within(s, boundary, kVoxel);
  for (std::size_t i = 0; i < within_before.size(); ++i) {
    if (within_before[i]) {
      EXPECT_TRUE(within_after[i]) << "point " << i;
    }
  }
  EXPECT_TRUE(tri_surface_topology(s).closed_manifold());

  // Bad options are refused.
  for (const VolumeRestoreOptions& bad :
       {VolumeRestoreOptions{0.0, kVoxel}, VolumeRestoreOptions{voxels, 0.0},
        VolumeRestoreOptions{voxels, kVoxel, 90.0}, VolumeRestoreOptions{voxels, kVoxel, 30.0, 0}}) {
    TriSurface copy = s;
    EXPECT_THROW(restore_volume(copy, boundary, bad), std::exception);
  }
}

TEST(SurfaceDecimation, ReducesAdaptivelyWithinTheBound) {
  // An elongated ellipsoid: strongly curved at its tips, flat-ish along its middle.
  VoxelMask m = ellipsoid(24, 7, 7);
  const VoxelBoundaryDistance boundary(m);
  TriSurface s = marching_cubes(m);
  const int mc = static_cast<int>(s.tris.rows());
  SmoothingOptions so;
  so.max_distance = kVoxel;
  smooth_surface(s, boundary, so);
  DecimationOptions o;
  o.max_distance = kVoxel;
  o.max_error = 0.25 * kVoxel;
  const DecimationReport rep = decimate_surface(s, &boundary, o);
  EXPECT_EQ(rep.triangles, s.tris.rows());
  EXPECT_LT(rep.triangles, mc / 4) << mc << " -> " << rep.triangles;
  const TriSurfaceTopology t = tri_surface_topology(s);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.euler, 2);
  for (Eigen::Index v = 0; v < s.vertices.rows(); ++v) EXPECT_TRUE(boundary.within(s.vertices.row(v).transpose(), kVoxel));
  // Adaptive: vertices per unit area near the tips (|x| > 80 % of the half-length) against the middle (|x| < 40 %),
  // compared with the same reduction under a uniform curvature (a floor far above the ellipsoid's curvatures).
  const double cx = (m.grid.size.x() - 1) / 2.0 * kVoxel, half = 24 * kVoxel;
  auto tip_over_middle = [&](const TriSurface& r) {
    double tip_area = 0, mid_area = 0;
    int tip_vertices = 0, mid_vertices = 0;
    for (Eigen::Index f = 0; f < r.tris.rows(); ++f) {
      const Eigen::Vector3d a = r.vertices.row(r.tris(f, 0)), b = r.vertices.row(r.tris(f, 1)),
                            c = r.vertices.row(r.tris(f, 2));
      const double x = std::fabs((a.x() + b.x() + c.x()) / 3.0 - cx) / half;
      const double area = 0.5 * (b - a).cross(c - a).norm();
      if (x > 0.8) tip_area += area;
      if (x < 0.4) mid_area += area;
    }
    for (Eigen::Index v = 0; v < r.vertices.rows(); ++v) {
      const double x = std::fabs(r.vertices(v, 0) - cx) / half;
      if (x > 0.8) ++tip_vertices;
      if (x < 0.4) ++mid_vertices;
    }
    return (tip_vertices / tip_area) / (mid_vertices / mid_area);
  };
  TriSurface uniform = marching_cubes(m);
  smooth_surface(uniform, boundary, so);
  DecimationOptions flat = o;
  flat.min_curvature = 1e4;  // 1/m
  decimate_surface(uniform, &boundary, flat);
  const double adaptive_ratio = tip_over_middle(s), uniform_ratio = tip_over_middle(uniform);
  EXPECT_GT(adaptive_ratio, 1.4);
  EXPECT_GT(adaptive_ratio, 1.25 * uniform_ratio) << adaptive_ratio << " vs " << uniform_ratio;

  // Count-driven: down to a target.
  TriSurface c = s;
  DecimationOptions count;
  count.max_distance = kVoxel;
  count.target_vertices = 150;
  const DecimationReport cr = decimate_surface(c, &boundary, count);
  EXPECT_EQ(cr.vertices, 150);
  EXPECT_TRUE(tri_surface_topology(c).closed_manifold());

  // Improvement keeps the surface closed and does not lower its worst triangle.
  ImprovementOptions io;
  io.max_distance = kVoxel;
  const double q0 = tri_surface_min_quality(c);
  const ImprovementReport ir = improve_surface(c, &boundary, io);
  EXPECT_GE(ir.min_quality_after, q0 - 1e-12);
  EXPECT_TRUE(tri_surface_topology(c).closed_manifold());
  EXPECT_EQ(tri_surface_topology(c).euler, 2);
}

TEST(SurfaceDecimation, IsDeterministic) {
  VoxelMask m = ellipsoid(9, 6, 5);
  const VoxelBoundaryDistance boundary(m);
  DecimationOptions o;
  o.max_distance = kVoxel;
  o.max_error = 0.3 * kVoxel;
  TriSurface a = marching_cubes(m), b = marching_cubes(m);
  decimate_surface(a, &boundary, o);
  decimate_surface(b, &boundary, o);
  EXPECT_EQ(a.tris, b.tris);
  EXPECT_EQ(a.vertices, b.vertices);
}

}  // namespace
}  // namespace surgsim
