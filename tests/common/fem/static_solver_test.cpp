#include "fem/static_solver.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mesh/box_mesh.h"
#include "core/error.h"
#include "support/liver_test_util.h"
#include "mesh/mesh.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;

namespace surgsim {
namespace {

// Patch test: u = A x with A upper triangular (any symmetric strain) imposed on every boundary node; the fixed dofs
// hold only the rigid modes (A x vanishes on them). The interior must reproduce u = A x to round-off.
void patch_test(const TetMesh& mesh, int n0, int n1, int n2) {
  const int n = static_cast<int>(mesh.nodes.rows());
  std::vector<std::uint8_t> masks(static_cast<std::size_t>(n), 0);
  masks[static_cast<std::size_t>(n0)] = 7;  // at the origin
  masks[static_cast<std::size_t>(n1)] = 6;  // on the +x axis: y, z
  masks[static_cast<std::size_t>(n2)] = 4;  // in the xy plane: z
  Eigen::Matrix3d a;
  a << 1e-3, 2e-3, -1e-3, 0, -2e-3, 1.5e-3, 0, 0, 3e-3;
  test::Organ organ(mesh, test::liver_material(), FixedSet(masks));
  std::vector<ImposedDisplacement> imposed;
  std::vector<char> on_boundary(static_cast<std::size_t>(n), 0);
  for (int i : boundary_surface(organ.mesh).nodes) {
    on_boundary[static_cast<std::size_t>(i)] = 1;
    const std::uint8_t free = static_cast<std::uint8_t>(7 & ~masks[static_cast<std::size_t>(i)]);
    if (free) imposed.push_back({i, a * organ.mesh.nodes.row(i).transpose(), free});
  }
  for (SolveMethod method : {SolveMethod::kDirect, SolveMethod::kCg}) {
    StaticSolverOptions opts;
    opts.method = method;
    opts.cg_tolerance = 1e-14;
    StaticSolver solver(organ.model, opts);
    const StaticSolution s = solver.solve(imposed);
    double worst = 0;
    int interior = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d exact = a * organ.mesh.nodes.row(i).transpose();
      worst = std::max(worst, (s.displacement.row(i).transpose() - exact).norm());
      interior += on_boundary[static_cast<std::size_t>(i)] ? 0 : 1;
    }
    const double scale = a.norm() * organ.mesh.nodes.cwiseAbs().maxCoeff();
    EXPECT_GT(interior, 0);
    EXPECT_LT(worst / scale, 1e-10) << to_string(method);
  }
}

TEST(StaticSolver, PatchTestSixTetBox) {
  patch_test(make_box_mesh(4, 4, 4, Eigen::Vector3d(0.1, 0.08, 0.06)), box_node(4, 4, 0, 0, 0), box_node(4, 4, 4, 0, 0),
             box_node(4, 4, 0, 4, 0));
}

TEST(StaticSolver, PatchTestFiveTetBox) {
  patch_test(make_box_mesh(3, 4, 3, Eigen::Vector3d(0.1, 0.08, 0.06), Eigen::Vector3d::Zero(), BoxSplit::kFive),
             box_node(3, 4, 0, 0, 0), box_node(3, 4, 3, 0, 0), box_node(3, 4, 0, 4, 0));
}

TEST(StaticSolver, PatchTestCylinder) {
  // Centre of the base (origin), the first outer node (+x axis), and a node off the x axis.
  const int rings = 3;
  patch_test(make_cylinder_mesh(0.025, 0.05, rings, 4), 0, 1 + 3 * rings * (rings - 1), 2);
}

// Cylinder (radius r, height h) compressed by x on its top face, lateral surface free, base held only axially:
// linear elasticity gives d_r = nu r x / h and f = s E x / h (s = cross-section area).
struct CompressionResult {
  double radial_error;   // max |d_r - nu r x / h| / (nu r x / h) over the lateral nodes
  double force_error;    // |f - pi r^2 E x / h| / (pi r^2 E x / h)
  double polygon_error;  // |f - s_h E x / h| / (...) with s_h the meshed (polygonal) cross-section
};

CompressionResult compress_cylinder(int rings, int layers) {
  const double r = 0.025, h = 0.1, x = 0.002;
  TetMesh mesh = make_cylinder_mesh(r, h, rings, layers);
  const int per = cylinder_layer_nodes(rings);
  const int n = static_cast<int>(mesh.nodes.rows());
  std::vector<std::uint8_t> masks(static_cast<std::size_t>(n), 0);
  for (int p = 0; p < per; ++p) masks[static_cast<std::size_t>(p)] = 4;  // base: axial only
  masks[0] = 7;                                                          // centre: also x, y
  masks[static_cast<std::size_t>(1 + 3 * rings * (rings - 1))] |= 2;     // on +x: y (no spin)
  test::Organ organ(std::move(mesh), test::liver_material(), FixedSet(masks));
  std::vector<ImposedDisplacement> top;
  for (int p = 0; p < per; ++p) top.push_back({layers * per + p, Eigen::Vector3d(0, 0, -x), 4});
  StaticSolver solver(organ.model);
  const StaticSolution s = solver.solve(top);

  const double nu = organ.material.poisson_ratio, e = organ.material.young_modulus;
  CompressionResult out{0, 0, 0};
  const double dr_exact = nu * r * x / h;
  for (int l = 0; l <= layers; ++l)
    for (int p = per - 6 * rings; p < per; ++p) {
      const int i = l * per + p;
      const Eigen::Vector2d radial = organ.mesh.nodes.row(i).head<2>().transpose().normalized();
      const double dr = s.displacement.row(i).head<2>().dot(radial.transpose());
      out.radial_error = std::max(out.radial_error, std::abs(dr - dr_exact) / dr_exact);
    }
  const double f = -s.total_reaction.z();  // the constraint pushes down on the organ
  const double f_exact = M_PI * r * r * e * x / h;
  const double polygon = 0.5 * 6 * rings * r * r * std::sin(2 * M_PI / (6 * rings));
  out.force_error = std::abs(f - f_exact) / f_exact;
  out.polygon_error = std::abs(f - polygon * e * x / h) / (polygon * e * x / h);
  return out;
}

TEST(StaticSolver, CylinderCompressionMatchesLinearRelations) {
  // The uniaxial field is linear, so P1 elements reproduce it: the radial displacement is exact and the force is
  // exact for the meshed (polygonal) section. The only discretization error is the section's area, which shrinks
  // as the circle is refined: 4.5 %, 1.1 %, 0.29 % for 12-, 24- and 48-gons.
  double previous = 1;
  for (int rings : {2, 4, 8}) {
    const CompressionResult c = compress_cylinder(rings, rings + 2);
    EXPECT_LT(c.radial_error, 1e-9) << rings;
    EXPECT_LT(c.polygon_error, 1e-9) << rings;
    EXPECT_LT(c.force_error, previous) << rings;
    previous = c.force_error;
  }
  EXPECT_LT(previous, 0.005);
}

// Plate (0.2 x 0.2 x 0.01 m) fixed at its four corner columns, two contacts on the top face (paper figs. 5 and 10).
struct Plate {
  std::unique_ptr<test::Organ> organ;
  std::vector<ImposedDisplacement> contacts;
};

Plate make_plate() {
  const int nx = 10, ny = 10, nz = 2;
  TetMesh mesh = make_box_mesh(nx, ny, nz, Eigen::Vector3d(0.2, 0.2, 0.01), Eigen::Vector3d(-0.1, -0.1, 0));
  std::vector<int> corners;
  for (int k = 0; k <= nz; ++k)
    for (int i : {0, nx})
      for (int j : {0, ny}) corners.push_back(box_node(nx, ny, i, j, k));
  const int n = static_cast<int>(mesh.nodes.rows());
  Plate p;
  p.organ = std::make_unique<test::Organ>(std::move(mesh), test::liver_material(), FixedSet(n, corners));
  p.contacts = {{box_node(nx, ny, 3, 4, nz), Eigen::Vector3d(0, 0, -0.005), 7},
                {box_node(nx, ny, 7, 6, nz), Eigen::Vector3d(0.001, 0, -0.003), 7}};
  return p;
}

TEST(StaticSolver, PlateContactsHoldExactly) {
  Plate p = make_plate();
  for (SolveMethod method : {SolveMethod::kDirect, SolveMethod::kCg}) {
    StaticSolverOptions opts;
    opts.method = method;
    StaticSolver solver(p.organ->model, opts);
    const StaticSolution s = solver.solve(p.contacts);
    for (const auto& c : p.contacts)
      EXPECT_LT((s.displacement.row(c.node).transpose() - c.value).norm(), 1e-12 * c.value.norm()) << to_string(method);
    ASSERT_EQ(s.imposed_nodes.size(), 2u);
    // Pushing down needs a downward force on the organ.
    EXPECT_LT(s.total_reaction.z(), 0);
    if (method == SolveMethod::kCg) {
      EXPECT_GT(s.iterations, 0);
      EXPECT_LE(s.residual, opts.cg_tolerance);
      EXPECT_TRUE(s.converged);
    }
  }
}

TEST(StaticSolver, ReactionsBalanceAtTheFixedNodes) {
  // With no other load, the forces at imposed dofs and at fixed dofs sum to zero: K u = r.
  Plate p = make_plate();
  StaticSolver solver(p.organ->model);
  const StaticSolution s = solver.solve(p.contacts);
  Eigen::VectorXd u(3 * s.displacement.rows());
  for (Eigen::Index i = 0; i < s.displacement.rows(); ++i) u.segment<3>(3 * i) = s.displacement.row(i).transpose();
  const Eigen::VectorXd ku = p.organ->model.k * u;
  Eigen::Vector3d fixed_sum = Eigen::Vector3d::Zero();
  for (int i : p.organ->fixed.fixed_nodes()) fixed_sum += ku.segment<3>(3 * i);
  EXPECT_LT((fixed_sum + s.total_reaction).norm(), 1e-9 * s.total_reaction.norm());
  for (std::size_t k = 0; k < s.imposed_nodes.size(); ++k)
    EXPECT_LT((ku.segment<3>(3 * s.imposed_nodes[k]) - s.reaction.row(static_cast<Eigen::Index>(k)).transpose()).norm(),
              1e-9 * s.total_reaction.norm());
}

TEST(StaticSolver, CgAgreesWithDirectWithinItsTolerance) {
  auto organ = test::box_organ(6, 5, 4);
  std::vector<ImposedDisplacement> imposed = {{box_node(6, 5, 2, 2, 4), Eigen::Vector3d(0.001, -0.002, -0.006), 7},
                                              {box_node(6, 5, 5, 3, 4), Eigen::Vector3d(0, 0, -0.004), 7},
                                              {box_node(6, 5, 6, 0, 2), Eigen::Vector3d(-0.003, 0.002, 0), 3}};
  StaticSolver direct(organ->model);
  const StaticSolution d = direct.solve(imposed);
  for (double tol : {1e-6, 1e-10}) {
    StaticSolverOptions opts;
    opts.method = SolveMethod::kCg;
    opts.cg_tolerance = tol;
    StaticSolver cg(organ->model, opts);
    const StaticSolution c = cg.solve(imposed);
    EXPECT_TRUE(c.converged);
    EXPECT_LE(c.residual, tol);
    // The error is bounded by cond(K) x residual; for this mesh cond ~ 1e3 suffices.
    EXPECT_LT(test::rel_error(c.displacement, d.displacement), 1e4 * tol) << tol;
    EXPECT_LT(test::rel_error(c.reaction, d.reaction), 1e4 * tol) << tol;
  }
}

TEST(StaticSolver, BadInputIsAClearError) {
  auto organ = test::box_organ(2, 2, 2);
  StaticSolver solver(organ->model);
  const int n = static_cast<int>(organ->mesh.nodes.rows());
  auto message = [&](const std::vector<ImposedDisplacement>& im) {
    try {
      solver.solve(im);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(message({{n, Eigen::Vector3d::Zero(), 7}}).find("out of range"), std::string::npos);
  EXPECT_NE(message({{0, Eigen::Vector3d::Zero(), 7}}).find("fixed"), std::string::npos);  // node 0 is on z = 0
  const int top = n - 1;
  EXPECT_NE(message({{top, Eigen::Vector3d(0, 0, 1e-3), 4}, {top, Eigen::Vector3d(0, 0, 2e-3), 4}}).find("twice"),
            std::string::npos);
  EXPECT_EQ(message({{top, Eigen::Vector3d(0, 0, 1e-3), 4}, {top, Eigen::Vector3d(0, 0, 1e-3), 4}}), "");
  EXPECT_NE(message({{top, Eigen::Vector3d(NAN, 0, 0), 7}}).find("non-finite"), std::string::npos);
  EXPECT_NE(message({{top, Eigen::Vector3d::Zero(), 0}}).find("no component"), std::string::npos);
  // No constraint: no deformation.
  const StaticSolution s = solver.solve({});
  EXPECT_EQ(s.displacement.norm(), 0);
}

}  // namespace
}  // namespace surgsim
