#include "fem/fem.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <limits>

#include "mesh/box_mesh.h"
#include "core/error.h"
#include "support/liver_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;

namespace surgsim {
namespace {

// The 6 rigid modes at the mesh nodes (3N x 6).
Eigen::MatrixXd rigid_modes(const TetMesh& m) {
  const Eigen::Index n = m.nodes.rows();
  Eigen::MatrixXd r = Eigen::MatrixXd::Zero(3 * n, 6);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d x = m.nodes.row(i).transpose();
    for (int a = 0; a < 3; ++a) {
      r(3 * i + a, a) = 1;
      r.block<3, 1>(3 * i, 3 + a) = Eigen::Vector3d::Unit(a).cross(x);
    }
  }
  return r;
}

TEST(Fem, ElementStiffnessIsSymmetricWithSixRigidModes) {
  Eigen::Matrix<double, 4, 3> x;
  x << 0, 0, 0, 0.01, 0, 0.001, 0.002, 0.012, 0, 0.001, 0.003, 0.009;
  const Eigen::Matrix<double, 12, 12> ke = tet_stiffness(x, test::liver_material());
  EXPECT_LT((ke - ke.transpose()).norm(), 1e-12 * ke.norm());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> eig(ke);
  const auto& ev = eig.eigenvalues();  // ascending
  for (int k = 0; k < 6; ++k) EXPECT_LT(std::abs(ev[k]), 1e-10 * ev[11]) << k;
  for (int k = 6; k < 12; ++k) EXPECT_GT(ev[k], 1e-6 * ev[11]) << k;
}

TEST(Fem, GlobalStiffnessIsSymmetricAndAnnihilatesRigidModes) {
  const TetMesh m = make_box_mesh(3, 2, 2, Eigen::Vector3d(0.1, 0.08, 0.05));
  const Eigen::SparseMatrix<double> k = assemble_stiffness(m, test::liver_material());
  EXPECT_EQ(k.rows(), 3 * m.nodes.rows());
  const Eigen::SparseMatrix<double> kt = k.transpose();
  EXPECT_LT((k - kt).norm(), 1e-12 * k.norm());
  const Eigen::MatrixXd kr = k * rigid_modes(m);
  EXPECT_LT(kr.norm(), 1e-10 * k.norm());
}

TEST(Fem, StrainEnergyOfAUniformStrainIsExact) {
  // u = A x gives a uniform strain; u^T K u = V eps^T D eps (Voigt, engineering shears).
  const Eigen::Vector3d size(0.1, 0.08, 0.05);
  const TetMesh m = make_box_mesh(2, 3, 2, size, Eigen::Vector3d::Zero(), BoxSplit::kFive);
  const Material mat = test::liver_material();
  const Eigen::SparseMatrix<double> k = assemble_stiffness(m, mat);
  Eigen::Matrix3d a;
  a << 1e-3, 2e-3, -5e-4, 4e-4, -2e-3, 1e-3, 0, 7e-4, 3e-3;
  Eigen::VectorXd u(3 * m.nodes.rows());
  for (Eigen::Index i = 0; i < m.nodes.rows(); ++i) u.segment<3>(3 * i) = a * m.nodes.row(i).transpose();
  const Eigen::Matrix3d e = 0.5 * (a + a.transpose());
  Eigen::Matrix<double, 6, 1> eps;
  eps << e(0, 0), e(1, 1), e(2, 2), 2 * e(0, 1), 2 * e(1, 2), 2 * e(0, 2);
  const double expected = size.prod() * eps.dot(elasticity_matrix(mat) * eps);
  EXPECT_NEAR(u.dot(k * u), expected, 1e-12 * expected);
}

TEST(Fem, MaterialIsChecked) {
  Material m = test::liver_material();
  m.poisson_ratio = 0.5;
  EXPECT_THROW(check_material(m), Error);
  m.poisson_ratio = -0.1;
  EXPECT_THROW(check_material(m), Error);
  m.poisson_ratio = 0.3;
  m.young_modulus = 0;
  EXPECT_THROW(check_material(m), Error);
  m.young_modulus = 1e3;
  EXPECT_NO_THROW(check_material(m));
  try {
    Material bad = test::liver_material();
    bad.poisson_ratio = 0.5;
    check_material(bad);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("0.5"), std::string::npos) << e.what();
  }
}

TEST(Fem, InvertedTetIsRefused) {
  TetMesh m = make_box_mesh(1, 1, 1, Eigen::Vector3d::Ones());
  std::swap(m.tets(0, 1), m.tets(0, 2));
  EXPECT_THROW(assemble_stiffness(m, test::liver_material()), Error);
}

TEST(Fem, AssemblyIsDeterministic) {
  const TetMesh m = make_box_mesh(3, 3, 2, Eigen::Vector3d(0.1, 0.1, 0.05));
  const auto k1 = assemble_stiffness(m, test::liver_material());
  const auto k2 = assemble_stiffness(m, test::liver_material());
  ASSERT_EQ(k1.nonZeros(), k2.nonZeros());
  EXPECT_EQ(0, std::memcmp(k1.valuePtr(), k2.valuePtr(), sizeof(double) * static_cast<std::size_t>(k1.nonZeros())));
}

TEST(Fem, FreeStiffnessDropsFixedDofs) {
  auto organ = test::box_organ(3, 2, 2);
  const auto& model = organ->model;
  EXPECT_EQ(model.k_ff.rows(), model.fixed.free_dof_count());
  const auto& dofs = model.fixed.free_dofs();
  for (int j = 0; j < model.k_ff.cols(); j += 7)
    for (int i = 0; i < model.k_ff.rows(); i += 5)
      EXPECT_EQ(model.k_ff.coeff(i, j),
                model.k.coeff(dofs[static_cast<std::size_t>(i)], dofs[static_cast<std::size_t>(j)]));
}

TEST(Fem, CountInvertedTetsFindsTetsTurnedInsideOut) {
  const TetMesh m = make_box_mesh(2, 2, 2, Eigen::Vector3d::Constant(0.02));
  Eigen::MatrixX3d u = Eigen::MatrixX3d::Zero(m.nodes.rows(), 3);
  TetInversion inv = count_inverted_tets(m, u);
  EXPECT_EQ(inv.inverted, 0);
  EXPECT_NEAR(inv.min_volume_ratio, 1.0, 1e-12);
  // A mirror image (z -> -z) turns every tet inside out.
  u.col(2) = -2 * m.nodes.col(2);
  inv = count_inverted_tets(m, u);
  EXPECT_EQ(inv.inverted, m.tets.rows());
  EXPECT_NEAR(inv.min_volume_ratio, -1.0, 1e-12);
  // The centre node pushed down by 3 edges: only tets around it, and a NaN counts as inverted.
  u.setZero();
  const int centre = box_node(2, 2, 1, 1, 1);
  u(centre, 2) = -0.03;
  inv = count_inverted_tets(m, u);
  EXPECT_GT(inv.inverted, 0);
  EXPECT_LT(inv.inverted, m.tets.rows());
  EXPECT_LT(inv.min_volume_ratio, 0.0);
  u.setZero();
  u(centre, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_GT(count_inverted_tets(m, u).inverted, 0);
  EXPECT_THROW(count_inverted_tets(m, Eigen::MatrixX3d::Zero(3, 3)), Error);
}

}  // namespace
}  // namespace surgsim
