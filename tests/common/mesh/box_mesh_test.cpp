#include "mesh/box_mesh.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "mesh/mesh.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim {
namespace {

double total_volume(const TetMesh& m, double* min_volume) {
  double v = 0, vmin = HUGE_VAL;
  for (int t = 0; t < m.tets.rows(); ++t) {
    const double vt = tet_volume(m, t);
    v += vt;
    vmin = std::min(vmin, vt);
  }
  *min_volume = vmin;
  return v;
}

TEST(BoxMesh, SixTetSplitIsConformingAndPositive) {
  const TetMesh m = make_box_mesh(3, 4, 2, Eigen::Vector3d(0.3, 0.4, 0.1));
  EXPECT_EQ(m.nodes.rows(), 4 * 5 * 3);
  EXPECT_EQ(m.tets.rows(), 6 * 3 * 4 * 2);
  double vmin = 0;
  EXPECT_NEAR(total_volume(m, &vmin), 0.3 * 0.4 * 0.1, 1e-15);
  EXPECT_GT(vmin, 0);
  // A conforming mesh's boundary is exactly the box's 6 faces, 2 triangles per cell face.
  EXPECT_EQ(boundary_surface(m).tris.rows(), 2 * 2 * (3 * 4 + 4 * 2 + 3 * 2));
  EXPECT_EQ(m.nodes.row(box_node(3, 4, 3, 4, 2)), Eigen::RowVector3d(0.3, 0.4, 0.1));
}

TEST(BoxMesh, FiveTetSplitIsConformingAndPositive) {
  const TetMesh m = make_box_mesh(3, 3, 3, Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(-1, 0, 2), BoxSplit::kFive);
  EXPECT_EQ(m.tets.rows(), 5 * 27);
  double vmin = 0;
  EXPECT_NEAR(total_volume(m, &vmin), 1.0, 1e-12);
  EXPECT_GT(vmin, 0);
  EXPECT_EQ(boundary_surface(m).tris.rows(), 2 * 6 * 9);
  TetMesh copy = m;
  EXPECT_NO_THROW(validate_mesh(copy, MeshValidation{false, 1e-12}));
}

TEST(BoxMesh, NodeTargetIsApproached) {
  const TetMesh m = make_box_mesh_with_nodes(1500, Eigen::Vector3d(0.26, 0.16, 0.08));
  EXPECT_GT(m.nodes.rows(), 1100);
  EXPECT_LT(m.nodes.rows(), 1900);
}

TEST(BoxMesh, CylinderIsConformingWithNodesOnTheCircle) {
  const double r = 0.025, h = 0.1;
  const int rings = 4, layers = 5;
  const TetMesh m = make_cylinder_mesh(r, h, rings, layers);
  const int per = cylinder_layer_nodes(rings);
  EXPECT_EQ(m.nodes.rows(), per * (layers + 1));
  double vmin = 0;
  const double polygon = 0.5 * 6 * rings * r * r * std::sin(2 * M_PI / (6 * rings));
  EXPECT_NEAR(total_volume(m, &vmin), polygon * h, 1e-15);
  EXPECT_GT(vmin, 0);
  // Outer ring nodes on the circle; boundary closed and manifold.
  for (int p = per - 6 * rings; p < per; ++p) EXPECT_NEAR(m.nodes.row(p).head<2>().norm(), r, 1e-15);
  TetMesh copy = m;
  EXPECT_NO_THROW(validate_mesh(copy, MeshValidation{false, 1e-12}));
}

TEST(BoxMesh, BadArgumentsAreErrors) {
  EXPECT_THROW(make_box_mesh(0, 1, 1, Eigen::Vector3d::Ones()), Error);
  EXPECT_THROW(make_box_mesh(1, 1, 1, Eigen::Vector3d(1, -1, 1)), Error);
  EXPECT_THROW(make_cylinder_mesh(0.1, 0.1, 0, 1), Error);
}

}  // namespace
}  // namespace surgsim
