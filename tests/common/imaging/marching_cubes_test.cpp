// Tests for common/imaging/marching_cubes.cpp: the generated table, watertight and outward surfaces on every single
// cube configuration and on random volumes, vertices on the voxel boundary, the box and sphere volumes.
#include "imaging/marching_cubes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "mesh/tri_surface.h"
#include "imaging/voxel_boundary.h"

using namespace surgsim::mesh;
using namespace surgsim::imaging;

namespace surgsim {
namespace {

constexpr double kPi = 3.14159265358979323846;

VoxelMask mask_of(int nx, int ny, int nz, double spacing = 1.0) {
  VoxelMask m;
  m.grid.size = Eigen::Vector3i(nx, ny, nz);
  m.grid.spacing = Eigen::Vector3d::Constant(spacing);
  m.inside.assign(static_cast<std::size_t>(nx) * ny * nz, 0);
  m.source = "test";
  return m;
}

void set(VoxelMask& m, int i, int j, int k) { m.inside[static_cast<std::size_t>(m.grid.index(i, j, k))] = 1; }

TEST(MarchingCubes, TableHasTheClassicTriangleCountsForUnambiguousCases) {
  auto triangles = [](int config) {
    const std::int8_t* e = marching_cubes_case(config);
    int n = 0;
    while (n < 16 && e[n] >= 0) ++n;
    EXPECT_EQ(n % 3, 0) << "case " << config;
    return n / 3;
  };
  EXPECT_EQ(triangles(0), 0);
  EXPECT_EQ(triangles(255), 0);
  EXPECT_EQ(triangles(1), 1);      // one corner
  EXPECT_EQ(triangles(254), 1);    // all but one
  EXPECT_EQ(triangles(3), 2);      // an edge
  EXPECT_EQ(triangles(15), 2);     // a face
  EXPECT_EQ(triangles(0x81), 2);   // opposite corners (0 and 7): two separate triangles
  EXPECT_EQ(triangles(0x69), 4);   // corners 0, 3, 5, 6: four separate corners
  // Every cut edge of every case carries a vertex and no uncut edge does.
  for (int config = 0; config < 256; ++config) {
    const std::int8_t* e = marching_cubes_case(config);
    for (int n = 0; n < 16 && e[n] >= 0; ++n) {
      const int a = marching_cubes_edge_corner(e[n], 0), b = marching_cubes_edge_corner(e[n], 1);
      EXPECT_NE((config >> a) & 1, (config >> b) & 1) << "case " << config << " edge " << int(e[n]);
    }
  }
}

TEST(MarchingCubes, EveryCubeConfigurationGivesAClosedOutwardSurface) {
  for (int config = 1; config < 255; ++config) {
    VoxelMask m = mask_of(2, 2, 2);
    for (int c = 0; c < 8; ++c)
      if ((config >> c) & 1) set(m, c & 1, (c >> 1) & 1, (c >> 2) & 1);
    const TriSurface s = marching_cubes(m);
    const TriSurfaceTopology t = tri_surface_topology(s);
    ASSERT_TRUE(t.closed_manifold()) << "case " << config;
    EXPECT_GT(tri_surface_volume(s), 0.0) << "case " << config;
  }
}

TEST(MarchingCubes, RandomVolumesGiveClosedOutwardSurfacesOnTheVoxelBoundary) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 60; ++trial) {
    VoxelMask m = mask_of(7, 6, 5, 0.5);
    const double density = 0.2 + 0.6 * (trial % 7) / 6.0;
    std::bernoulli_distribution inside(density);
    for (auto& v : m.inside) v = inside(rng) ? 1 : 0;
    if (m.count() == 0) continue;
    const TriSurface s = marching_cubes(m);
    const TriSurfaceTopology t = tri_surface_topology(s);
    ASSERT_TRUE(t.closed_manifold()) << "trial " << trial << ": " << t.boundary_edges << " open, "
                                     << t.nonmanifold_edges << " non-manifold edges, " << t.nonmanifold_vertices
                                     << " pinched vertices";
    EXPECT_GT(tri_surface_volume(s), 0.0);
    // Binary input: every vertex is the centre of a boundary voxel face.
    const VoxelBoundaryDistance boundary(m);
    for (Eigen::Index v = 0; v < s.vertices.rows(); ++v)
      ASSERT_LT(boundary.distance(s.vertices.row(v).transpose(), 1.0), 1e-12);
  }
}

TEST(MarchingCubes, SingleVoxelIsAnOctahedronAndABoxLosesItsCorners) {
  VoxelMask one = mask_of(1, 1, 1, 2.0);
  set(one, 0, 0, 0);
  const TriSurface octa = marching_cubes(one);
  EXPECT_EQ(octa.tris.rows(), 8);
  EXPECT_EQ(octa.vertices.rows(), 6);
  EXPECT_NEAR(tri_surface_volume(octa), 8.0 / 6.0, 1e-12);  // (4/3) (s/2)^3 for s = 2

  VoxelMask box = mask_of(6, 5, 4);
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 6; ++i) set(box, i, j, k);
  const TriSurface s = marching_cubes(box);
  const TriSurfaceTopology t = tri_surface_topology(s);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.euler, 2);
  EXPECT_EQ(t.components, 1);
  // Faces at the voxel faces, edges and corners chamfered: between the centres' box and the voxels' box.
  const double v = tri_surface_volume(s);
  EXPECT_GT(v, 6.0 * 5.0 * 4.0 * 0.8);
  EXPECT_LT(v, 6.0 * 5.0 * 4.0);
}

TEST(MarchingCubes, SphereHasItsVolumeAndIsSphereLike) {
  const int n = 24;
  const double r = 9.0, c = (n - 1) / 2.0;
  VoxelMask m = mask_of(n, n, n, 0.001);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        if ((i - c) * (i - c) + (j - c) * (j - c) + (k - c) * (k - c) <= r * r) set(m, i, j, k);
  const TriSurface s = marching_cubes(m);
  const TriSurfaceTopology t = tri_surface_topology(s);
  EXPECT_TRUE(t.closed_manifold());
  EXPECT_EQ(t.euler, 2);
  const double exact = 4.0 / 3.0 * kPi * std::pow(r * 0.001, 3);
  EXPECT_NEAR(tri_surface_volume(s), exact, 0.05 * exact);
}

}  // namespace
}  // namespace surgsim
