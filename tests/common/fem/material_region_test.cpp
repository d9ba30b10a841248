// Material regions (heterogeneous tissue): which tets a region holds, and the stiffness assembled with each tet's own
// material against an assembly written here from the element stiffness alone.
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "core/error.h"
#include "core/hash.h"
#include "fem/fem.h"
#include "fem/hyperelastic.h"
#include "mesh/box_mesh.h"
#include "support/error_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;

namespace surgsim {
namespace {

const Eigen::Vector3d kSize(0.1, 0.08, 0.05);

Eigen::Vector3d centroid(const TetMesh& m, Eigen::Index t) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a) c += m.nodes.row(m.tets(t, a)).transpose();
  return c / 4;
}

// The base, a soft box (x >= 0.04) and, over it, a stiffer ellipsoid straddling its edge.
Material two_regions() {
  Material m;
  m.young_modulus = 4000;
  m.poisson_ratio = 0.4;
  MaterialRegion soft;
  soft.name = "soft";
  soft.young_modulus = 1000;
  soft.poisson_ratio = 0.3;
  soft.boxes.emplace_back(Eigen::Vector3d(0.04, -1, -1), Eigen::Vector3d(1, 1, 1));
  MaterialRegion stiff;
  stiff.name = "stiff";
  stiff.young_modulus = 9000;
  stiff.poisson_ratio = 0.45;
  stiff.ellipsoids.push_back(Ellipsoid{Eigen::Vector3d(0.045, 0.04, 0.025), Eigen::Vector3d(0.02, 0.03, 0.05)});
  m.regions = {soft, stiff};
  return m;
}

// Tet t's material as the regions above define it, decided here by its centroid.
Material expected_material(const TetMesh& m, Eigen::Index t) {
  const Eigen::Vector3d c = centroid(m, t);
  const Eigen::Vector3d e = (c - Eigen::Vector3d(0.045, 0.04, 0.025)).cwiseQuotient(Eigen::Vector3d(0.02, 0.03, 0.05));
  if (e.squaredNorm() <= 1) return Material{9000, 0.45};
  if (c.x() >= 0.04) return Material{1000, 0.3};
  return Material{4000, 0.4};
}

TEST(MaterialRegions, EachTetHasTheLastRegionHoldingItsCentroidElseTheBase) {
  const TetMesh m = make_box_mesh(5, 4, 3, kSize);
  const Material material = two_regions();
  const ElementMaterials em = element_materials(m, material);
  ASSERT_EQ(em.materials.size(), 3u);
  ASSERT_EQ(em.element.size(), static_cast<std::size_t>(m.tets.rows()));
  int count[3] = {0, 0, 0};
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
    const int i = em.element[static_cast<std::size_t>(t)];
    ++count[i];
    const Material want = expected_material(m, t);
    EXPECT_EQ(em.materials[static_cast<std::size_t>(i)].young_modulus, want.young_modulus) << t;
    EXPECT_EQ(em.materials[static_cast<std::size_t>(i)].poisson_ratio, want.poisson_ratio) << t;
  }
  // Every kind is there, so the comparison above is not vacuous.
  for (int i = 0; i < 3; ++i) EXPECT_GT(count[i], 0) << i;
}

TEST(MaterialRegions, StiffnessIsTheSumOfEachTetsOwnElementStiffness) {
  const TetMesh m = make_box_mesh(5, 4, 3, kSize);
  const Eigen::MatrixXd k = Eigen::MatrixXd(assemble_stiffness(m, two_regions()));
  Eigen::MatrixXd ref = Eigen::MatrixXd::Zero(k.rows(), k.cols());
  for (Eigen::Index t = 0; t < m.tets.rows(); ++t) {
    Eigen::Matrix<double, 4, 3> x;
    for (int a = 0; a < 4; ++a) x.row(a) = m.nodes.row(m.tets(t, a));
    const Eigen::Matrix<double, 12, 12> ke = tet_stiffness(x, expected_material(m, t));
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) ref.block<3, 3>(3 * m.tets(t, a), 3 * m.tets(t, b)) += ke.block<3, 3>(3 * a, 3 * b);
  }
  EXPECT_LT((k - ref).norm(), 1e-13 * ref.norm());
  // And it is not the one-material stiffness (the regions changed it).
  const Eigen::MatrixXd one = Eigen::MatrixXd(assemble_stiffness(m, two_regions().base()));
  EXPECT_GT((one - ref).norm(), 0.1 * ref.norm());
}

TEST(MaterialRegions, ElasticModelAssemblesWithTheRegions) {
  const TetMesh m = make_box_mesh(5, 4, 3, kSize);
  std::vector<int> clamped;
  for (int j = 0; j <= 4; ++j)
    for (int k = 0; k <= 3; ++k) clamped.push_back(box_node(5, 4, 0, j, k));
  const FixedSet fixed(static_cast<int>(m.nodes.rows()), clamped);
  const ElasticModel model = build_elastic_model(m, two_regions(), fixed);
  EXPECT_EQ(model.elements.element, element_materials(m, two_regions()).element);
  const Eigen::SparseMatrix<double> k = assemble_stiffness(m, two_regions());
  EXPECT_EQ(Eigen::MatrixXd(model.k), Eigen::MatrixXd(k));
  // The neo-Hookean tangent at rest is the linear elasticity of each tet's own material.
  const HyperelasticSolver solver(model);
  Eigen::SparseMatrix<double> tangent;
  ASSERT_TRUE(solver.tangent_stiffness(Eigen::VectorXd::Zero(k.rows()), tangent));
  EXPECT_LT(Eigen::MatrixXd(tangent - k).norm(), 1e-10 * Eigen::MatrixXd(k).norm());
}

TEST(MaterialRegions, OneMaterialStiffnessIsBitForBitAsBeforeRegions) {
  // The checksum of this K (values, then row indices) from the assembly before regions existed (6ea914f): a
  // homogeneous organ's K, and so its tensors and caches, are unchanged.
  const TetMesh m = make_box_mesh(3, 2, 2, kSize);
  const Material material{4000, 0.4};
  const Eigen::SparseMatrix<double> k = assemble_stiffness(m, material);
  Hasher h;
  h.bytes(k.valuePtr(), sizeof(double) * static_cast<std::size_t>(k.nonZeros()));
  h.bytes(k.innerIndexPtr(), sizeof(int) * static_cast<std::size_t>(k.nonZeros()));
  EXPECT_EQ(k.nonZeros(), 2826);
  EXPECT_EQ(h.digest(), 0xc2a4f38b474054e0ULL);
  // A region of the base's own material changes no bit either.
  Material same = material;
  MaterialRegion r;
  r.name = "same";
  r.young_modulus = 4000;
  r.poisson_ratio = 0.4;
  r.boxes.emplace_back(Eigen::Vector3d(0.05, -1, -1), Eigen::Vector3d(1, 1, 1));
  same.regions = {r};
  const Eigen::SparseMatrix<double> k2 = assemble_stiffness(m, same);
  ASSERT_EQ(k2.nonZeros(), k.nonZeros());
  EXPECT_EQ(0, std::memcmp(k.valuePtr(), k2.valuePtr(), sizeof(double) * static_cast<std::size_t>(k.nonZeros())));
}

TEST(MaterialRegions, RegionsAreWrittenInTheOrgansFrame) {
  const TetMesh organ = make_box_mesh(5, 4, 3, kSize);
  TetMesh placed = organ;
  const Placement p = Placement::from_euler_deg(Eigen::Vector3d(0.3, -0.1, 0.05), Eigen::Vector3d(10, -20, 75));
  for (Eigen::Index i = 0; i < placed.nodes.rows(); ++i)
    placed.nodes.row(i) = p.to_world(organ.nodes.row(i).transpose()).transpose();
  Material material = two_regions();
  const std::vector<int> at_origin = element_materials(organ, material).element;
  material.frame = p;
  EXPECT_EQ(element_materials(placed, material).element, at_origin);
  // Without the frame the same regions miss the placed mesh.
  material.frame = Placement();
  EXPECT_THROW(element_materials(placed, material), Error);
}

TEST(MaterialRegions, ARegionHoldingNoTetIsAnErrorNamingIt) {
  const TetMesh m = make_box_mesh(5, 4, 3, kSize);
  Material material = two_regions();
  material.regions[1].ellipsoids[0].center = Eigen::Vector3d(1, 1, 1);  // far outside
  material.regions[1].where = "scene.yaml:7: key 'material.regions[1]'";
  const std::string outside = test::error_of([&] { element_materials(m, material); });
  EXPECT_NE(outside.find("scene.yaml:7: key 'material.regions[1]'"), std::string::npos) << outside;
  EXPECT_NE(outside.find("'stiff' holds no element"), std::string::npos) << outside;
  // A region every tet of which a later one takes holds none either.
  material = two_regions();
  material.regions[1].boxes.emplace_back(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1));
  const std::string overridden = test::error_of([&] { element_materials(m, material, "liver.yaml"); });
  EXPECT_EQ(overridden.rfind("liver.yaml: material region 'soft' holds no element", 0), 0u) << overridden;
  EXPECT_NE(overridden.find("a later region takes every one"), std::string::npos) << overridden;
}

TEST(MaterialRegions, ARegionsMaterialIsChecked) {
  const TetMesh m = make_box_mesh(2, 2, 2, kSize);
  Material material = two_regions();
  material.regions[0].poisson_ratio = 0.5;
  material.regions[0].where = "s.yaml:3: key 'material.regions[0]'";
  const std::string what = test::error_of([&] { assemble_stiffness(m, material); });
  EXPECT_NE(what.find("s.yaml:3: key 'material.regions[0]': material region 'soft': Poisson ratio"), std::string::npos)
      << what;
}

}  // namespace
}  // namespace surgsim
