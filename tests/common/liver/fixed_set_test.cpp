#include "liver/fixed_set.h"

#include <gtest/gtest.h>

#include "mesh/box_mesh.h"
#include "core/error.h"
#include "liver/fem.h"
#include "support/liver_test_util.h"

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

}  // namespace
}  // namespace surgsim
