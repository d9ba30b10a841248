// Tests for common/mesh/validate.cpp: every refusal of validate_mesh names the file and the element at fault;
// inverted tets are flipped when allowed; tets folded over a shared face are refused.
#include "mesh/mesh.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "mesh/box_mesh.h"
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

// Two tets on the face (0, 1, 2) of the plane z = 0, the first with its apex (node 3) above it, the second with
// `apex`, listed as `order`; ids 7..11, element ids 1 and 2, as if read from "fold.msh".
TetMesh two_tets(const Eigen::RowVector3d& apex, const Eigen::RowVector4i& order) {
  TetMesh m;
  m.source = "fold.msh";
  m.nodes.resize(5, 3);
  m.nodes << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0;
  m.nodes.row(4) = apex;
  m.tets.resize(2, 4);
  m.tets.row(0) << 0, 1, 2, 3;
  m.tets.row(1) = order;
  m.ids = {7, 8, 9, 10, 11};
  m.tet_ids = {1, 2};
  return m;
}

// Both apexes above the shared face: each tet has positive volume, yet they overlap.
TEST(ValidateMesh, FoldedPairIsRefusedNamingBothElementsAndTheFace) {
  TetMesh m = two_tets({0.5, 0.5, 0.5}, {0, 1, 2, 4});
  ASSERT_GT(tet_volume(m, 0), 0.0);
  ASSERT_GT(tet_volume(m, 1), 0.0);
  const Eigen::MatrixX4i original = m.tets;
  MeshValidation strict;
  strict.fix_orientation = false;
  for (const MeshValidation& opts : {MeshValidation{}, strict}) {
    expect_error([&] { validate_mesh(m, opts); },
                 {"fold.msh", "element 1 (nodes 7 8 9 10)", "element 2 (nodes 7 8 9 11)",
                  "face (node 7, node 8, node 9)", "node 10", "node 11", "same side", "overlap", "re-mesh"});
    EXPECT_TRUE(m.tets == original);
  }
}

// The same pair with the second apex below the face is a valid mesh, whichever way the file orders its nodes.
TEST(ValidateMesh, UnfoldedPairIsAccepted) {
  TetMesh m = two_tets({0.3, 0.3, -0.5}, {0, 2, 1, 4});
  ASSERT_GT(tet_volume(m, 1), 0.0);
  EXPECT_NO_THROW(validate_mesh(m));
  TetMesh inverted = two_tets({0.3, 0.3, -0.5}, {0, 1, 2, 4});
  ASSERT_LT(tet_volume(inverted, 1), 0.0);
  EXPECT_NO_THROW(validate_mesh(inverted));  // flipped, then consistent with its neighbour
  EXPECT_GT(tet_volume(inverted, 1), 0.0);
}

// The same element twice: every face is shared by the two copies, with the same apex.
TEST(ValidateMesh, DuplicatedElementIsRefused) {
  TetMesh m = two_tets({0, 0, 1}, {0, 1, 2, 3});
  m.nodes.conservativeResize(4, 3);
  m.ids.pop_back();
  expect_error([&] { validate_mesh(m); }, {"fold.msh", "element 1", "element 2", "the same element twice", "re-mesh"});
}

// Every tet of a box mesh that holds `node`, in index order.
std::vector<int> tets_of_node(const TetMesh& m, int node) {
  std::vector<int> out;
  for (int t = 0; t < m.tets.rows(); ++t) {
    if ((m.tets.row(t).array() == node).any()) out.push_back(t);
  }
  return out;
}

// An interior node of a box mesh pushed through the face opposite it in one of its tets (to 1.5 times its distance):
// that tet turns inside out and overlaps its neighbour across the face. fix_orientation flips it to a positive
// volume, and a program that "repaired" the order before writing leaves every volume positive: both are refused.
TEST(ValidateMesh, NodeMovedThroughAFaceOfABoxMeshIsRefused) {
  const int n = 4;
  TetMesh m = make_box_mesh(n, n, n, Eigen::Vector3d::Constant(0.04));
  m.source = "box.msh";
  const int moved = box_node(n, n, 2, 2, 2);
  const int through = tets_of_node(m, moved).front();
  int face[3], k = 0;
  for (int a = 0; a < 4; ++a) {
    if (m.tets(through, a) != moved) face[k++] = m.tets(through, a);
  }
  const Eigen::Vector3d a = m.nodes.row(face[0]), b = m.nodes.row(face[1]), c = m.nodes.row(face[2]);
  const Eigen::Vector3d normal = (b - a).cross(c - a).normalized();
  const Eigen::Vector3d p = m.nodes.row(moved);
  m.nodes.row(moved) = (p - 1.5 * (p - a).dot(normal) * normal).transpose();

  // The construction: some tets inverted, none near zero volume (that would be another refusal).
  const double mean = total_volume(make_box_mesh(n, n, n, Eigen::Vector3d::Constant(0.04))) / m.tets.rows();
  std::vector<std::string> inverted;
  for (int t = 0; t < m.tets.rows(); ++t) {
    const double v = tet_volume(m, t);
    ASSERT_GT(std::abs(v), 1e-3 * mean) << "tet " << t;
    if (v < 0) inverted.push_back("tet " + std::to_string(t) + " (0-based)");
  }
  ASSERT_FALSE(inverted.empty());
  const auto names_an_inverted_tet = [&](const std::string& msg) {
    for (const std::string& name : inverted) {
      if (msg.find(name) != std::string::npos) return true;
    }
    return false;
  };

  TetMesh flipped = m;
  const std::string msg = expect_error([&] { validate_mesh(flipped); }, {"box.msh", "overlap", "flipped"});
  EXPECT_TRUE(names_an_inverted_tet(msg)) << msg;

  TetMesh repaired = m;
  for (int t = 0; t < repaired.tets.rows(); ++t) {
    if (tet_volume(repaired, t) < 0) std::swap(repaired.tets(t, 1), repaired.tets(t, 2));
  }
  MeshValidation strict;
  strict.fix_orientation = false;
  const std::string msg2 = expect_error([&] { validate_mesh(repaired, strict); }, {"box.msh", "overlap"});
  EXPECT_TRUE(names_an_inverted_tet(msg2)) << msg2;
  EXPECT_EQ(msg2.find("flipped"), std::string::npos) << msg2;
}

TEST(ValidateMesh, NoTets) {
  TetMesh m = cube_mesh();
  m.tets.resize(0, 4);
  expect_error([&] { validate_mesh(m); }, {"<in-memory mesh>", "no tetrahedra"});
}

}  // namespace
}  // namespace surgsim
