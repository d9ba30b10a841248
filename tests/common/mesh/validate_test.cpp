// Tests for common/mesh/validate.cpp: every refusal of validate_mesh names the file and the element at fault;
// inverted tets are flipped when allowed.
#include "mesh/mesh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <utility>

#include "core/error.h"
#include "mesh_test_util.h"

using namespace surgsim::mesh;

namespace surgsim {
namespace {

using namespace test;  // NOLINT(build/namespaces): the fixtures and helpers of mesh_test_util.h

// The cube as if read from "liver.msh" with ids 11..18 and element ids 101..105.
TetMesh named_cube() {
  TetMesh m = cube_mesh();
  m.source = "liver.msh";
  m.ids = {11, 12, 13, 14, 15, 16, 17, 18};
  m.tet_ids = {101, 102, 103, 104, 105};
  return m;
}

TEST(ValidateMesh, NonFiniteCoordinate) {
  TetMesh m = named_cube();
  m.nodes(6, 1) = std::nan("");
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "node 17", "non-finite"});
  TetMesh anon = cube_mesh();
  anon.nodes(2, 0) = INFINITY;
  expect_error([&] { validate_mesh(anon); }, {"<in-memory mesh>", "node index 2", "non-finite"});
}

TEST(ValidateMesh, IndexOutOfRange) {
  TetMesh m = named_cube();
  m.tets(3, 2) = 8;
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "element 104", "node index 8", "8 nodes"});
}

TEST(ValidateMesh, RepeatedNode) {
  TetMesh m = named_cube();
  m.tets(1, 3) = m.tets(1, 0);
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "element 102", "node 13 twice"});
}

TEST(ValidateMesh, ZeroVolume) {
  TetMesh m = named_cube();
  m.nodes.row(6) << 0.25, 0.25, 0.5;  // the far corner onto the plane of nodes 12, 14, 15: the central tet is flat
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "element 105", "(nodes 12 14 15 17)", "zero volume"});
  TetMesh tiny = named_cube();
  tiny.nodes.row(4) << 0, 0, 1e-14;  // element 101 becomes a sliver next to unit-size tets
  MeshValidation opts;
  opts.min_volume_ratio = 1e-9;
  expect_error([&] { validate_mesh(tiny, opts); }, {"liver.msh", "element 101", "zero volume"});
}

TEST(ValidateMesh, InvertedIsRefusedOrFlipped) {
  TetMesh m = named_cube();
  std::swap(m.tets(2, 0), m.tets(2, 1));
  const Eigen::MatrixX4i original = m.tets;
  MeshValidation strict;
  strict.fix_orientation = false;
  expect_error([&] { validate_mesh(m, strict); }, {"liver.msh", "element 103", "inverted", "fix_orientation"});
  EXPECT_TRUE(m.tets == original);  // a refused mesh is left as it was

  validate_mesh(m);
  for (int t = 0; t < m.tets.rows(); ++t) EXPECT_GT(tet_volume(m, t), 0.0) << "tet " << t;
  EXPECT_NEAR(total_volume(m), 1.0, 1e-15);
}

TEST(ValidateMesh, UnreferencedNode) {
  TetMesh m = named_cube();
  m.nodes.conservativeResize(9, 3);
  m.nodes.row(8) << 2, 2, 2;
  m.ids.push_back(99);
  expect_error([&] { validate_mesh(m); }, {"liver.msh", "node 99", "not used by any tetrahedron"});
}

// Two tets meeting along one edge only (nodes 0-1): that edge has 4 boundary faces.
TEST(ValidateMesh, NonManifoldEdge) {
  TetMesh m;
  m.source = "bowtie.msh";
  m.nodes.resize(6, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, -1, 0, 0, 0, -1;
  m.tets.resize(2, 4);
  m.tets << 0, 1, 2, 3, 0, 1, 4, 5;
  m.ids = {7, 8, 9, 10, 11, 12};
  m.tet_ids = {1, 2};
  expect_error([&] { validate_mesh(m); },
               {"bowtie.msh", "boundary edge (node 7, node 8)", "4 boundary faces", "element 1", "non-manifold"});
}

TEST(ValidateMesh, FaceSharedByThreeTets) {
  TetMesh m;
  m.nodes.resize(6, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0.2, 0.2, 0.5;
  m.tets.resize(3, 4);
  m.tets << 0, 1, 2, 3, 0, 2, 1, 4, 0, 1, 2, 5;
  expect_error([&] { validate_mesh(m); }, {"<in-memory mesh>", "shared by 3 tets", "tet 0 (0-based)"});
}

TEST(ValidateMesh, NoTets) {
  TetMesh m = cube_mesh();
  m.tets.resize(0, 4);
  expect_error([&] { validate_mesh(m); }, {"<in-memory mesh>", "no tetrahedra"});
}

}  // namespace
}  // namespace surgsim
