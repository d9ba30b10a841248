#include "fem/fixed_set.h"

#include <gtest/gtest.h>

#include "mesh/box_mesh.h"
#include "core/error.h"
#include "fem/fem.h"
#include "liver/liver_setup.h"
#include "support/liver_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::liver;

namespace surgsim {
namespace {

std::string rigid_error(const TetMesh& m, const FixedSet& f) {
  try {
    check_rigid_modes_removed(m, f, "scene.yaml");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(FixedSet, NumbersFreeDofs) {
  std::vector<std::uint8_t> masks = {7, 0, 4, 3};
  const FixedSet f(masks);
  EXPECT_EQ(f.dof_count(), 12);
  EXPECT_EQ(f.free_dof_count(), 12 - 3 - 1 - 2);
  EXPECT_TRUE(f.dof_fixed(0));
  EXPECT_FALSE(f.dof_fixed(3));
  EXPECT_TRUE(f.dof_fixed(8));
  EXPECT_EQ(f.free_index()[3], 0);
  EXPECT_EQ(f.free_dofs()[0], 3);
  EXPECT_EQ(f.fixed_nodes(), (std::vector<int>{0, 2, 3}));
  EXPECT_NE(f.hash(), FixedSet(std::vector<std::uint8_t>{7, 0, 4, 1}).hash());
}

TEST(FixedSet, RegionUnionOfListBoxesAndPlane) {
  const TetMesh m = make_box_mesh(4, 4, 4, Eigen::Vector3d(1, 1, 1));
  FixedRegion r;
  r.nodes = {box_node(4, 4, 2, 2, 2)};
  r.boxes.emplace_back(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.25, 0.25, 0.25));  // 8 nodes
  r.has_plane = true;
  r.plane_point = Eigen::Vector3d(0, 0, 1);
  r.plane_normal = Eigen::Vector3d(0, 0, 2);  // z >= 1: top face, 25 nodes (normal need not be unit)
  const auto nodes = nodes_in_region(m, r);
  EXPECT_EQ(nodes.size(), 1u + 8u + 25u);
  EXPECT_TRUE(std::is_sorted(nodes.begin(), nodes.end()));
  FixedRegion bad;
  bad.nodes = {125};
  EXPECT_THROW(nodes_in_region(m, bad), Error);
  FixedRegion single_box;
  single_box.boxes.emplace_back(Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 1, 0));  // bottom face
  EXPECT_EQ(nodes_in_region(m, single_box).size(), 25u);
}

TEST(FixedSet, NothingFixedIsAClearError) {
  const TetMesh m = make_box_mesh(2, 2, 2, Eigen::Vector3d::Ones());
  const std::string e = rigid_error(m, FixedSet(static_cast<int>(m.nodes.rows()), {}));
  EXPECT_NE(e.find("scene.yaml: no node is fixed"), std::string::npos) << e;
  EXPECT_NE(e.find("3 non-collinear"), std::string::npos) << e;
  EXPECT_THROW(build_elastic_model(m, test::liver_material(), FixedSet(static_cast<int>(m.nodes.rows()), {})), Error);
}

TEST(FixedSet, CollinearNodesAreAClearError) {
  const TetMesh m = make_box_mesh(2, 2, 2, Eigen::Vector3d::Ones());
  const std::vector<int> edge = {box_node(2, 2, 0, 0, 0), box_node(2, 2, 1, 0, 0), box_node(2, 2, 2, 0, 0)};
  const std::string e = rigid_error(m, FixedSet(static_cast<int>(m.nodes.rows()), edge));
  EXPECT_NE(e.find("one line"), std::string::npos) << e;
  EXPECT_NE(e.find("3 node(s) fixed"), std::string::npos) << e;
  EXPECT_NE(e.find("rotation about the axis along (1 0 0)"), std::string::npos) << e;
  const std::string single = rigid_error(m, FixedSet(static_cast<int>(m.nodes.rows()), {4}));
  EXPECT_NE(single.find("single fixed node"), std::string::npos) << single;
}

TEST(FixedSet, ThreeNonCollinearNodesSuffice) {
  const TetMesh m = make_box_mesh(2, 2, 2, Eigen::Vector3d::Ones());
  const std::vector<int> tri = {box_node(2, 2, 0, 0, 0), box_node(2, 2, 2, 0, 0), box_node(2, 2, 0, 2, 0)};
  EXPECT_EQ(rigid_error(m, FixedSet(static_cast<int>(m.nodes.rows()), tri)), "");
  EXPECT_NO_THROW(build_elastic_model(m, test::liver_material(), FixedSet(static_cast<int>(m.nodes.rows()), tri)));
}

TEST(FixedSet, ComponentsMustHoldEveryRigidMode) {
  // Cylinder-like base: z fixed on the bottom face, x and y at one node, y at another -> no rigid mode.
  const TetMesh m = make_box_mesh(2, 2, 2, Eigen::Vector3d::Ones());
  std::vector<std::uint8_t> masks(static_cast<std::size_t>(m.nodes.rows()), 0);
  for (int j = 0; j <= 2; ++j)
    for (int i = 0; i <= 2; ++i) masks[static_cast<std::size_t>(box_node(2, 2, i, j, 0))] = 4;
  EXPECT_NE(rigid_error(m, FixedSet(masks)).find("rigid mode"), std::string::npos);  // slides in x, y; spins
  masks[static_cast<std::size_t>(box_node(2, 2, 1, 1, 0))] = 7;
  masks[static_cast<std::size_t>(box_node(2, 2, 2, 1, 0))] |= 2;
  EXPECT_EQ(rigid_error(m, FixedSet(masks)), "");
}

TEST(FixedSet, EveryConnectedPartNeedsFixedNodes) {
  TetMesh a = make_box_mesh(1, 1, 1, Eigen::Vector3d::Ones());
  const TetMesh b = make_box_mesh(1, 1, 1, Eigen::Vector3d::Ones(), Eigen::Vector3d(3, 0, 0));
  TetMesh m;
  m.nodes.resize(16, 3);
  m.nodes << a.nodes, b.nodes;
  m.tets.resize(a.tets.rows() + b.tets.rows(), 4);
  m.tets << a.tets, (b.tets.array() + 8).matrix();
  const std::string e = rigid_error(m, FixedSet(16, {0, 1, 2, 3}));
  EXPECT_NE(e.find("not connected"), std::string::npos) << e;
  EXPECT_NE(e.find("no fixed node"), std::string::npos) << e;
  EXPECT_EQ(rigid_error(m, FixedSet(16, {0, 1, 2, 3, 8, 9, 10})), "");
}

// Box a (unit cube at the origin, 8 nodes) and box b (unit cube at b_origin) in one mesh; b's nodes listed in
// `shared` (b node -> a node) are merged into a's, the others follow a's nodes in order.
TetMesh two_boxes(const Eigen::Vector3d& b_origin, const std::vector<std::pair<int, int>>& shared) {
  const TetMesh a = make_box_mesh(1, 1, 1, Eigen::Vector3d::Ones());
  const TetMesh b = make_box_mesh(1, 1, 1, Eigen::Vector3d::Ones(), b_origin);
  std::vector<int> map(8, -1);
  for (const auto& [bn, an] : shared) map[static_cast<std::size_t>(bn)] = an;
  int next = 8;
  for (int& m : map)
    if (m < 0) m = next++;
  TetMesh out;
  out.nodes.resize(next, 3);
  out.nodes.topRows(8) = a.nodes;
  for (int i = 0; i < 8; ++i) {
    if (map[static_cast<std::size_t>(i)] >= 8)
      out.nodes.row(map[static_cast<std::size_t>(i)]) = b.nodes.row(i);
    else
      EXPECT_TRUE(out.nodes.row(map[static_cast<std::size_t>(i)]).isApprox(b.nodes.row(i)));
  }
  out.tets.resize(a.tets.rows() + b.tets.rows(), 4);
  out.tets.topRows(a.tets.rows()) = a.tets;
  for (Eigen::Index t = 0; t < b.tets.rows(); ++t)
    for (int c = 0; c < 4; ++c) out.tets(a.tets.rows() + t, c) = map[static_cast<std::size_t>(b.tets(t, c))];
  return out;
}

// a's bottom face z = 0 (nodes 0..3): holds box a on its own.
const std::vector<int> kBottomOfA = {0, 1, 2, 3};

TEST(FixedSet, BodyHingedAtAVertexIsRefused) {
  // b's corner (0,0,0) is a's corner (1,1,1) = node 7: one shared node, no shared face.
  const TetMesh m = two_boxes(Eigen::Vector3d(1, 1, 1), {{0, 7}});
  ASSERT_EQ(m.nodes.rows(), 15);
  const std::string e = rigid_error(m, FixedSet(15, kBottomOfA));
  EXPECT_NE(e.find("scene.yaml: "), std::string::npos) << e;
  EXPECT_NE(e.find("part 2 of 2 of the mesh (8 of 15 nodes: 7, 8, 9"), std::string::npos) << e;
  EXPECT_NE(e.find("no fixed node"), std::string::npos) << e;
  EXPECT_NE(e.find("touches part 1 only at node 7 (a vertex hinge)"), std::string::npos) << e;
  EXPECT_NE(e.find("Either fix at least 3 non-collinear nodes of that part"), std::string::npos) << e;
  EXPECT_NE(e.find("share faces"), std::string::npos) << e;
  EXPECT_THROW(build_elastic_model(m, test::liver_material(), FixedSet(15, kBottomOfA)), Error);

  // Fixing the hinge node itself holds b at one point only: its rotations about node 7 stay free.
  std::vector<int> with_hinge = kBottomOfA;
  with_hinge.push_back(7);
  const std::string h = rigid_error(m, FixedSet(15, with_hinge));
  EXPECT_NE(h.find("3 rigid mode(s) of part 2 of 2"), std::string::npos) << h;
  EXPECT_NE(h.find("a single fixed node"), std::string::npos) << h;
  EXPECT_NE(h.find("(a vertex hinge)"), std::string::npos) << h;

  // Three non-collinear fixed nodes of b hold it.
  std::vector<int> both = kBottomOfA;
  for (int i : {8, 9, 10}) both.push_back(i);
  EXPECT_EQ(rigid_error(m, FixedSet(15, both)), "");
}

TEST(FixedSet, BodyHingedAlongAnEdgeIsRefused) {
  // b at (1,0,1): its nodes (0,0,0) and (0,1,0) (0 and 2) are a's (1,0,1) and (1,1,1) (5 and 7): a shared edge.
  const TetMesh m = two_boxes(Eigen::Vector3d(1, 0, 1), {{0, 5}, {2, 7}});
  ASSERT_EQ(m.nodes.rows(), 14);
  const std::string e = rigid_error(m, FixedSet(14, kBottomOfA));
  EXPECT_NE(e.find("part 2 of 2 of the mesh (8 of 14 nodes"), std::string::npos) << e;
  EXPECT_NE(e.find("touches part 1 along the edge 5-7 (an edge hinge)"), std::string::npos) << e;
  // Fixing both hinge nodes leaves the rotation about the edge (along y) free.
  const std::string h = rigid_error(m, FixedSet(14, {0, 1, 2, 3, 5, 7}));
  EXPECT_NE(h.find("1 rigid mode(s) of part 2 of 2"), std::string::npos) << h;
  EXPECT_NE(h.find("rotation about the axis along (0 1 0)"), std::string::npos) << h;
  EXPECT_NE(h.find("(an edge hinge)"), std::string::npos) << h;
}

TEST(FixedSet, BodiesSharingAFaceAreOne) {
  // b at (1,0,0): its face x = 0 is a's face x = 1 (nodes 1, 3, 5, 7), split alike: one body held by a's bottom.
  const TetMesh m = two_boxes(Eigen::Vector3d(1, 0, 0), {{0, 1}, {2, 3}, {4, 5}, {6, 7}});
  ASSERT_EQ(m.nodes.rows(), 12);
  EXPECT_EQ(rigid_error(m, FixedSet(12, kBottomOfA)), "");
  EXPECT_NO_THROW(build_elastic_model(m, test::liver_material(), FixedSet(12, kBottomOfA)));
}

TEST(FixedSet, FloatingBodyIsRefused) {
  const TetMesh m = two_boxes(Eigen::Vector3d(2, 0, 0), {});
  const std::string e = rigid_error(m, FixedSet(16, kBottomOfA));
  EXPECT_NE(e.find("part 2 of 2 of the mesh (8 of 16 nodes: 8, 9"), std::string::npos) << e;
  EXPECT_NE(e.find("is not attached to anything"), std::string::npos) << e;
  EXPECT_NE(e.find("remove the part"), std::string::npos) << e;
}

// Through a scene (load_liver_tensors, the nodes' path): the refusal comes before any factorization and names the
// scene and its mesh file.
TEST(FixedSet, SceneRefusalNamesTheSceneAndTheMeshFile) {
  TetMesh m = two_boxes(Eigen::Vector3d(1, 1, 1), {{0, 7}});
  m.source = "hinged.msh";
  FixedRegion region;
  region.nodes = kBottomOfA;
  const std::string dir = ::testing::TempDir();
  const LiverTensorSetup setup = liver_tensor_setup(test::liver_material(), region, m, dir, "scene.yaml");
  try {
    load_liver_tensors(setup, m, test::liver_material(), {"haptic"}, nullptr, nullptr, "scene.yaml");
    FAIL() << "expected a refusal";
  } catch (const Error& e) {
    const std::string w = e.what();
    EXPECT_EQ(w.rfind("scene.yaml (mesh hinged.msh): ", 0), 0u) << w;
    EXPECT_NE(w.find("(a vertex hinge)"), std::string::npos) << w;
    EXPECT_EQ(w.find("CHOLMOD"), std::string::npos) << w;  // refused before factoring
  }
}

}  // namespace
}  // namespace surgsim
