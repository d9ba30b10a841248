// Another body resting on the organ (the field's bowel on the liver) solved in the organ's own contact system
// (ToolContacts::set_bodies): spheres of a body on the top of a bottom-fixed slab, alone and beside an instrument
// pressing into it. The reference is the test's own: the nearest rest point found by brute force over the slab's top
// triangles, and the organ's displacement under the pushes the solve reports from a direct solve of K u = f with the
// stiffness assembled in support/direct_solve.h (not the tensors, not CHOLMOD). Checked: the dent equals the direct
// solve with the same forces (<= 1e-9 relative), every touching sphere's push is its penalty on the dented surface
// (k times its overlap), a released one does not overlap it, and the instrument's force leaves the body's loads out.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <utility>
#include <vector>

#include "contact/tool_contacts.h"
#include "fem/fixed_set.h"
#include "support/alloc_counter.h"
#include "support/direct_solve.h"
#include "support/slab_util.h"

using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::contact;

namespace surgsim {
namespace {

constexpr double kTop = 0.03;        // m, the slab's top face
constexpr double kStiffness = 2000;  // N/m, the bowel's obstacle_stiffness
constexpr double kRadius = 0.006;    // m, a sphere of the body

class ToolContactsBodiesTest : public ::testing::Test {
 public:
  static void SetUpTestSuite() {
    slab_ = new test::Slab(10, 10, 3, {0.1, 0.1, kTop});
    std::vector<int> bottom;  // the reference sees the geometry only: the bottom face is fixed
    for (Eigen::Index n = 0; n < slab_->mesh.nodes.rows(); ++n)
      if (slab_->mesh.nodes(n, 2) == 0.0) bottom.push_back(static_cast<int>(n));
    direct_ = new test::DirectReference(slab_->mesh.nodes, slab_->mesh.tets, 3000.0, 0.45, bottom);
    ASSERT_TRUE(direct_->ok());
  }
  static void TearDownTestSuite() {
    delete direct_;
    delete slab_;
  }
  void SetUp() override {
    spec_.shaft_points = 1;
    spec_.force_limit = 100.0;
    spec_.contact_capacity = 32;
  }

  /// A sphere of the body with its centre at (x, y, top + radius + gap): its point found by brute force over the
  /// top's triangles (the test's own barycentric coordinates), normal +z.
  static BodyPoint sphere(double x, double y, double gap) {
    BodyPoint b;
    b.gap = gap;
    b.stiffness = kStiffness;
    b.normal = Eigen::Vector3d::UnitZ();
    const Eigen::MatrixX3d& v = slab_->mesh.nodes;
    const Eigen::MatrixX3i& tris = slab_->surface.tris;
    for (Eigen::Index f = 0; f < tris.rows(); ++f) {
      const Eigen::Vector3d a = v.row(tris(f, 0)), c1 = v.row(tris(f, 1)), c2 = v.row(tris(f, 2));
      if (std::abs(a.z() - kTop) > 1e-12 || std::abs(c1.z() - kTop) > 1e-12 || std::abs(c2.z() - kTop) > 1e-12)
        continue;
      const double det = (c1.x() - a.x()) * (c2.y() - a.y()) - (c2.x() - a.x()) * (c1.y() - a.y());
      const double l1 = ((x - a.x()) * (c2.y() - a.y()) - (c2.x() - a.x()) * (y - a.y())) / det;
      const double l2 = ((c1.x() - a.x()) * (y - a.y()) - (x - a.x()) * (c1.y() - a.y())) / det;
      if (l1 < -1e-12 || l2 < -1e-12 || l1 + l2 > 1 + 1e-12) continue;
      b.nodes = {tris(f, 0), tris(f, 1), tris(f, 2)};
      b.bary = Eigen::Vector3d(1 - l1 - l2, l1, l2);
      return b;
    }
    ADD_FAILURE() << "no top triangle under (" << x << ", " << y << ")";
    return b;
  }

  struct Check {
    double dent_error = 0;    // max |u - u_direct| / max |u_direct| over the surface nodes with a column
    double law_error = 0;     // max |n . u(point) - push / k - gap| over touching spheres (m): push = k overlap
    double released_gap = 1;  // smallest gap - n . u(point) under a released sphere (m; < 0: it overlaps)
    int touching = 0, released = 0;
  };
  /// The solve's dent against the direct solve of the loads it reports: the bodies' pushes at their points and the
  /// instrument's node forces (the solution's lambda at the nodes no body loads).
  static Check check(const ToolContacts& c, const std::vector<BodyPoint>& bodies) {
    Check out;
    std::vector<std::pair<int, Eigen::Vector3d>> loads;
    for (std::size_t j = 0; j < bodies.size(); ++j) {
      const BodyForce& f = c.body_force(static_cast<int>(j));
      EXPECT_TRUE(f.solved) << "sphere " << j;
      for (int k = 0; k < 3; ++k)
        loads.emplace_back(bodies[j].nodes[k], -f.push * bodies[j].bary[k] * bodies[j].normal);
    }
    // The instrument's own node forces: the solution's lambda less the bodies' share at each node.
    const ContactSolution& s = c.solution();
    for (int l = 0; l < s.count; ++l) {
      Eigen::Vector3d tool = s.lambda[static_cast<std::size_t>(l)];
      for (const auto& [node, f] : loads)
        if (node == s.nodes[static_cast<std::size_t>(l)]) tool -= f;
      if (c.node_instrument(l) != ToolContacts::kBodyInstrument)
        loads.emplace_back(s.nodes[static_cast<std::size_t>(l)], tool);
    }
    const Eigen::MatrixX3d ref = direct_->displacements(loads);
    double worst = 0, scale = 0;
    for (int n : slab_->surface.nodes) {
      Eigen::Vector3d u;
      if (!c.solution_displacement(n, u)) continue;
      worst = std::max(worst, (u - ref.row(n).transpose()).cwiseAbs().maxCoeff());
      scale = std::max(scale, ref.row(n).cwiseAbs().maxCoeff());
    }
    out.dent_error = worst / scale;
    for (std::size_t j = 0; j < bodies.size(); ++j) {
      const BodyPoint& b = bodies[j];
      double un = 0;
      for (int k = 0; k < 3; ++k) un += b.bary[k] * b.normal.dot(ref.row(b.nodes[k]).transpose());
      const double push = c.body_force(static_cast<int>(j)).push;
      if (push > 0) {
        ++out.touching;
        out.law_error = std::max(out.law_error, std::abs(un - push / b.stiffness - b.gap));
      } else {
        ++out.released;
        out.released_gap = std::min(out.released_gap, b.gap - un);
      }
    }
    return out;
  }

  static test::Slab* slab_;
  static test::DirectReference* direct_;
  ToolSpec spec_;
};
test::Slab* ToolContactsBodiesTest::slab_ = nullptr;
test::DirectReference* ToolContactsBodiesTest::direct_ = nullptr;

// Spheres of a body over the top, some overlapping it by up to 2 mm, some 0.2 mm above it: the slab dents under the
// touching ones (each pushes the others' surface down, so some that overlapped the rest surface come free).
std::vector<BodyPoint> resting_body(std::mt19937& rng, int count) {
  std::uniform_real_distribution<double> xy(0.02, 0.08), gap(-0.002, 0.0002);
  std::vector<BodyPoint> out;
  for (int j = 0; j < count; ++j) out.push_back(ToolContactsBodiesTest::sphere(xy(rng), xy(rng), gap(rng)));
  return out;
}

TEST_F(ToolContactsBodiesTest, ABodyAloneDentsTheOrganAsTheDirectSolveWithItsPushes) {
  std::mt19937 rng(7);
  const std::vector<BodyPoint> bodies = resting_body(rng, 12);
  ToolContacts c(slab_->mesh, slab_->surface, slab_->tensors, spec_);
  c.set_bodies(bodies.data(), static_cast<int>(bodies.size()));
  ContactTick t;
  const InstrumentInput none{nullptr, 0.0};
  c.step(&none, 1, &t);
  ASSERT_EQ(c.body_count(), 12);
  const Check k = check(c, bodies);
  std::cout << "bodies alone: dent vs direct " << k.dent_error << ", law " << k.law_error << " m, " << k.touching
            << " touching, " << k.released << " released (smallest gap left " << k.released_gap << " m)\n";
  EXPECT_GT(k.touching, 4);
  EXPECT_LT(k.dent_error, 1e-9);
  EXPECT_LT(k.law_error, 1e-12);
  if (k.released > 0) {
    EXPECT_GT(k.released_gap, -1e-4) << "a released sphere deep in the dented surface";
  }
  EXPECT_TRUE(t.force.isZero(0)) << "no instrument: no force";
  // Its load on the organ: the pushes, down.
  double sum = 0;
  for (int j = 0; j < c.body_count(); ++j) sum += c.body_force(j).push;
  EXPECT_NEAR(-c.body_load().z(), sum, 1e-12);
  // Given for one step only: the next step without set_bodies has none.
  c.step(&none, 1, &t);
  EXPECT_EQ(c.body_count(), 0);
  EXPECT_EQ(c.solution().count, 0);
}

TEST_F(ToolContactsBodiesTest, ABodyBesideAnInstrumentIsSolvedWithItInOneSystem) {
  std::mt19937 rng(11);
  const std::vector<BodyPoint> bodies = resting_body(rng, 10);
  ToolContacts with(slab_->mesh, slab_->surface, slab_->tensors, spec_);
  ToolContacts without(slab_->mesh, slab_->surface, slab_->tensors, spec_);
  const Eigen::Vector3d tip(0.052, 0.047, kTop - 0.004);  // 4 mm deep among the spheres
  ContactTick tw, to;
  for (int k = 0; k <= 40; ++k) {  // pressed in over 40 ticks (past the onset ramp)
    const ToolGeometry g = test::vertical_tool(tip + Eigen::Vector3d(0, 0, 0.004 * (1 - k / 40.0)));
    with.set_bodies(bodies.data(), static_cast<int>(bodies.size()));
    with.step(g, 0.5, tw);
    without.step(g, 0.5, to);
  }
  const Check k = check(with, bodies);
  std::cout << "bodies beside an instrument: dent vs direct " << k.dent_error << ", law " << k.law_error << " m, "
            << k.touching << " touching; tool force " << tw.force.z() << " N (alone " << to.force.z() << " N)\n";
  EXPECT_GT(k.touching, 3);
  EXPECT_LT(k.dent_error, 1e-9);
  EXPECT_LT(k.law_error, 1e-12);
  // The instrument pushes the same imposed depth; the body's loads already pushed the surface down, so it feels less
  // (and never the body's weight itself).
  EXPECT_GT(tw.force.z(), 0.05);
  EXPECT_LT(tw.force.z(), to.force.z());
  EXPECT_GT(to.force.z() - tw.force.z(), 1e-4) << "the body's dent must change the instrument's force";
  // Its force is its own rows' only: -sum lambda over every node, less what the bodies put there.
  Eigen::Vector3d all = Eigen::Vector3d::Zero();
  for (int l = 0; l < with.solution().count; ++l) all -= with.solution().lambda[static_cast<std::size_t>(l)];
  EXPECT_LT((all + with.body_load() - tw.force).norm(), 1e-9 * tw.force.norm() + 1e-12);
}

TEST_F(ToolContactsBodiesTest, PointsOnTheFixedSetOrPastTheCapacityAreLeftToTheirOwner) {
  ToolSpec small = spec_;
  ToolContacts c(slab_->mesh, slab_->surface, slab_->tensors, small);
  std::vector<BodyPoint> bodies;
  // A sphere over the fixed bottom face, seen from below: every corner fixed.
  BodyPoint under;
  const Eigen::MatrixX3i& tris = slab_->surface.tris;
  for (Eigen::Index f = 0; f < tris.rows(); ++f) {
    if (slab_->mesh.nodes(tris(f, 0), 2) == 0.0 && slab_->mesh.nodes(tris(f, 1), 2) == 0.0 &&
        slab_->mesh.nodes(tris(f, 2), 2) == 0.0) {
      under.nodes = {tris(f, 0), tris(f, 1), tris(f, 2)};
      break;
    }
  }
  under.bary = Eigen::Vector3d::Constant(1.0 / 3);
  under.normal = -Eigen::Vector3d::UnitZ();
  under.gap = -0.001;
  under.stiffness = kStiffness;
  bodies.push_back(under);
  // Then more spheres than the union of 64 nodes can take, on distinct triangles.
  for (int i = 0; i < 9; ++i)
    for (int j = 0; j < 9; ++j) bodies.push_back(sphere(0.0055 + 0.0111 * i, 0.0045 + 0.0111 * j, -0.001));
  c.set_bodies(bodies.data(), static_cast<int>(bodies.size()));
  ContactTick t;
  const InstrumentInput none{nullptr, 0.0};
  c.step(&none, 1, &t);
  ASSERT_EQ(c.body_count(), static_cast<int>(bodies.size()));
  EXPECT_FALSE(c.body_force(0).solved) << "every corner fixed: the support holds it";
  int solved = 0;
  for (int j = 1; j < c.body_count(); ++j) solved += c.body_force(j).solved ? 1 : 0;
  EXPECT_GT(solved, 10);
  EXPECT_LT(solved, c.body_count() - 1) << "past the union's capacity the rest is left out";
  EXPECT_GT(c.body_overflow(), 0);
  EXPECT_LE(c.solution().count, kMaxContacts);
}

TEST_F(ToolContactsBodiesTest, StepWithBodiesAllocatesNothing) {
  std::mt19937 rng(3);
  const std::vector<BodyPoint> bodies = resting_body(rng, 20);
  ToolContacts c(slab_->mesh, slab_->surface, slab_->tensors, spec_);
  ContactTick t;
  const auto tick = [&](int k) {
    c.set_bodies(bodies.data(), static_cast<int>(bodies.size()));
    c.step(test::vertical_tool(Eigen::Vector3d(0.05, 0.05, kTop - 0.003 * std::sin(0.05 * k))), 0.5, t);
  };
  tick(0);
  long allocations = 0;
  {
    test::AllocationCounter counter;
    for (int k = 1; k < 100; ++k) tick(k);
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

}  // namespace
}  // namespace surgsim
