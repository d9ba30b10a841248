// Tests for common/mesh/mesh.cpp: read_mesh (every format loads the same cube; garbage, binary files, unknown
// extensions), boundary extraction and orientation, tet volume and quality, hashing.
#include "mesh/mesh.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "mesh_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

using namespace test;  // NOLINT(build/namespaces): the fixtures and helpers of mesh_test_util.h

// Divergence theorem with F = x / 3 (div F = 1): sum over faces of centroid . n * area / 3 is the enclosed volume
// when every normal points outward.
double divergence_volume(const TetMesh& m, const SurfaceMesh& s) {
  double v = 0;
  for (int f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = m.nodes.row(s.tris(f, 0)).transpose();
    const Eigen::Vector3d b = m.nodes.row(s.tris(f, 1)).transpose();
    const Eigen::Vector3d c = m.nodes.row(s.tris(f, 2)).transpose();
    const Eigen::Vector3d area_normal = 0.5 * (b - a).cross(c - a);  // |.| = area
    v += ((a + b + c) / 3.0).dot(area_normal) / 3.0;
  }
  return v;
}

TEST(ReadMesh, AllFormatsLoadTheSameCube) {
  const TetMesh expected = cube_mesh();
  const TetMesh v1 = read_mesh(write_file("cube_v1.msh", kCubeV1));
  const TetMesh v2 = read_mesh(write_file("cube_v2.msh", kCubeV2));
  const TetMesh v41 = read_mesh(write_file("cube_v41.msh", kCubeV41));
  const TetMesh v40 = read_mesh(write_file("cube_v40.msh", kCubeV40));
  const TetMesh vtk = read_mesh(write_file("cube.vtk", kCubeVtk));
  const TetMesh vtk51 = read_mesh(write_file("cube51.VTK", kCubeVtk51));
  for (const TetMesh* m : {&v1, &v2, &v41, &v40, &vtk, &vtk51}) {
    SCOPED_TRACE(m->source);
    expect_same_geometry(*m, expected);
    EXPECT_NEAR(total_volume(*m), 1.0, 1e-15);
  }
  // File ids are kept for messages, gaps compacted away in the indices.
  EXPECT_EQ(v1.ids, (std::vector<std::int64_t>{2, 5, 9, 17, 22, 23, 40, 41}));
  EXPECT_EQ(v1.tet_ids, (std::vector<std::int64_t>{4, 5, 6, 7, 8}));
  EXPECT_EQ(v2.ids, (std::vector<std::int64_t>{1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(v2.tet_ids, (std::vector<std::int64_t>{3, 4, 5, 6, 7}));
  EXPECT_EQ(v41.ids, (std::vector<std::int64_t>{100, 101, 102, 103, 104, 105, 106, 200}));
  EXPECT_EQ(v41.tet_ids, (std::vector<std::int64_t>{3, 4, 5, 6, 7}));
  EXPECT_EQ(vtk.ids, (std::vector<std::int64_t>{0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_EQ(vtk.tet_ids, (std::vector<std::int64_t>{2, 3, 4, 5, 6}));
  EXPECT_NE(v1.source.find("cube_v1.msh"), std::string::npos);
}

TEST(ReadMesh, ValidatesAndHashesDeterministically) {
  TetMesh a = read_mesh(write_file("a.msh", kCubeV2));
  TetMesh b = read_mesh(write_file("b.msh", kCubeV2));
  validate_mesh(a);
  validate_mesh(b);
  EXPECT_EQ(mesh_hash(a), mesh_hash(b));
  b.nodes(3, 1) += 1e-12;
  EXPECT_NE(mesh_hash(a), mesh_hash(b));
  TetMesh c = a;
  std::swap(c.tets(0, 1), c.tets(0, 2));
  EXPECT_NE(mesh_hash(a), mesh_hash(c));
}

// ---- Boundary

TEST(BoundarySurface, CubeHasTwelveOutwardFaces) {
  const TetMesh m = cube_mesh();
  const SurfaceMesh s = boundary_surface(m);
  EXPECT_EQ(s.tris.rows(), 12);
  EXPECT_EQ(s.nodes, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7}));
  EXPECT_NEAR(divergence_volume(m, s), 1.0, 1e-14);
  // Each normal points away from the cube's centre.
  const Eigen::Vector3d centre(0.5, 0.5, 0.5);
  for (int f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = m.nodes.row(s.tris(f, 0)).transpose();
    const Eigen::Vector3d b = m.nodes.row(s.tris(f, 1)).transpose();
    const Eigen::Vector3d c = m.nodes.row(s.tris(f, 2)).transpose();
    EXPECT_GT((b - a).cross(c - a).dot((a + b + c) / 3.0 - centre), 0.0) << "face " << f;
  }
}

TEST(BoundarySurface, GridCountsAndOrientationEvenWithInvertedTets) {
  TetMesh m = grid_mesh(3, 0.01);  // 3 cm cube of 1 cm cells
  // Outward orientation comes from geometry, not from the tets' node order.
  const SurfaceMesh before = boundary_surface(m);
  EXPECT_EQ(before.tris.rows(), 6 * 3 * 3 * 2);
  EXPECT_EQ(static_cast<int>(before.nodes.size()), 4 * 4 * 4 - 2 * 2 * 2);
  EXPECT_NEAR(divergence_volume(m, before), 27e-6, 1e-18);

  validate_mesh(m);
  for (int t = 0; t < m.tets.rows(); ++t) EXPECT_GT(tet_volume(m, t), 0.0);
  EXPECT_NEAR(total_volume(m), 27e-6, 1e-18);
  const SurfaceMesh after = boundary_surface(m);
  EXPECT_NEAR(divergence_volume(m, after), 27e-6, 1e-18);
}

TEST(TetVolume, SignFollowsNodeOrder) {
  TetMesh m = cube_mesh();
  EXPECT_NEAR(tet_volume(m, 0), 1.0 / 6.0, 1e-15);
  std::swap(m.tets(0, 2), m.tets(0, 3));
  EXPECT_NEAR(tet_volume(m, 0), -1.0 / 6.0, 1e-15);
}

// Garbage: random byte edits of the fixtures and random bytes give surgsim::core::Error or a mesh, never a crash.
TEST(ReadErrors, GarbageNeverCrashes) {
  std::mt19937 rng(12345);
  const std::string alphabet = std::string("0123456789$-+.e \n\r\tEN", 21) + std::string(1, '\0') + "\xff";
  int refused = 0;
  for (const char* fixture : {kCubeV1, kCubeV2, kCubeV41, kCubeV40, kCubeVtk, kCubeVtk51}) {
    const bool vtk = fixture == kCubeVtk || fixture == kCubeVtk51;
    for (int trial = 0; trial < 300; ++trial) {
      std::string text = fixture;
      const int edits = 1 + static_cast<int>(rng() % 3);
      for (int e = 0; e < edits; ++e) text[rng() % text.size()] = alphabet[rng() % alphabet.size()];
      const std::string path = write_file("fuzz" + std::to_string(trial) + (vtk ? ".vtk" : ".msh"), text);
      try {
        const TetMesh m = read_mesh(path);
        EXPECT_GT(m.tets.rows(), 0);
        EXPECT_EQ(m.nodes.rows(), static_cast<Eigen::Index>(m.ids.size()));
        for (int t = 0; t < m.tets.rows(); ++t) {
          for (int k = 0; k < 4; ++k) ASSERT_TRUE(m.tets(t, k) >= 0 && m.tets(t, k) < m.nodes.rows());
        }
      } catch (const Error& err) {
        ++refused;
        EXPECT_NE(std::string(err.what()).find(path), std::string::npos) << err.what();
      }
    }
    std::filesystem::remove_all(test_dir());
  }
  EXPECT_GT(refused, 0);
  for (int trial = 0; trial < 50; ++trial) {
    std::string text(1 + rng() % 2000, '\0');
    for (char& c : text) c = static_cast<char>(rng() % 256);
    if (trial % 2) text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" + text;
    EXPECT_THROW(read_mesh(write_file("random" + std::to_string(trial) + ".msh", text)), Error);
    EXPECT_THROW(read_mesh(write_file("random" + std::to_string(trial) + ".vtk", text)), Error);
  }
  std::filesystem::remove_all(test_dir());
}

TEST(ReadErrors, BinaryFilesAreRefused) {
  const std::string bin = std::string("$MeshFormat\n2.2 1 8\n") + std::string("\x01\0\0\0", 4) + "\n$EndMeshFormat\n";
  expect_error([&] { read_mesh(write_file("bin.msh", bin)); }, {"bin.msh:2:", "binary .msh not supported", "ASCII"});
  expect_error([&] { read_mesh(write_file("bin41.msh", "$MeshFormat\n4.1 1 8\n")); }, {"bin41.msh:2:", "binary"});
  const std::string vtk = replace(kCubeVtk, "ASCII", "BINARY");
  expect_error([&] { read_mesh(write_file("bin.vtk", vtk)); }, {"bin.vtk:3:", "binary VTK not supported"});
}

TEST(ReadErrors, ExtensionEmptyAndMissingFiles) {
  expect_error([] { read_mesh("organ.obj"); }, {"organ.obj", ".obj", ".msh", ".vtk"});
  expect_error([] { read_mesh("organ"); }, {"organ:", ".msh", ".vtk"});
  expect_error([] { read_mesh(test_dir() + "/missing.msh"); }, {"missing.msh", "cannot open"});
  expect_error([] { read_mesh(write_file("empty.msh", "")); }, {"empty.msh", "empty"});
  expect_error([] { read_mesh(write_file("blank.vtk", "\n \n")); }, {"blank.vtk", "empty"});
}

// By hand only (the project must not depend on shared data): gtest --gtest_also_run_disabled_tests.
TEST(SharedMeshes, DISABLED_SofaMeshes) {
  for (const char* path : {"/work/shared/data/sofa/liver2.msh", "/work/shared/data/sofa/liver.msh",
                           "/work/shared/data/sofa/cylinder.msh"}) {
    if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " is not here";
    TetMesh m = read_mesh(path);
    const std::size_t nodes = m.nodes.rows(), tets = m.tets.rows();
    std::string verdict = "valid";
    try {
      validate_mesh(m);
    } catch (const Error& e) {
      verdict = e.what();
    }
    const SurfaceMesh s = boundary_surface(m);
    std::printf("%s: %zu nodes, %zu tets, %ld boundary faces, %zu surface nodes, volume %.6g, divergence %.6g: %s\n",
                path, nodes, tets, static_cast<long>(s.tris.rows()), s.nodes.size(), total_volume(m),
                divergence_volume(m, s), verdict.c_str());
  }
}

TEST(MeshTest, TetQualityIsOneForTheRegularTetAndZeroForAFlatOne) {
  TetMesh m;
  m.nodes.resize(4, 3);
  m.nodes << 1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1;  // regular, edge 2 sqrt(2)
  m.tets.resize(1, 4);
  m.tets << 0, 1, 2, 3;
  EXPECT_NEAR(tet_quality(m, 0), 1.0, 1e-12);
  m.nodes *= 1e-3;  // scale invariant
  EXPECT_NEAR(tet_quality(m, 0), 1.0, 1e-12);
  m.nodes.row(3) = (m.nodes.row(0) + m.nodes.row(1) + m.nodes.row(2)) / 3;  // flat
  EXPECT_NEAR(tet_quality(m, 0), 0.0, 1e-12);
}

}  // namespace
}  // namespace surgsim
