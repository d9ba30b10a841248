// Two instruments on one liver, on the flat 20 x 20 x 4 cm slab of 1 cm cells fixed on its bottom face:
// all contacts of both instruments are one constrained solve, so each instrument's force equals a direct solve of the
// elasticity with BOTH instruments' constraints and differs from what the same instrument feels alone; an instrument
// whose input is lost drops only its own contacts; a grasp is held by one instrument while the other presses. The
// direct solve (tests/support/direct_solve.h) is built from geometry alone: the slab's nodes and tets, its material and
// bottom face, each tip's position, radius and shaft; its patches, weights, offsets, near fields and stiffness are
// coded there, not read from ToolContacts nor from the project's FEM, so a wrong patch of either instrument fails
// here. The figures are printed: ctest -R common_contact_two_hands_test -V.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "fem/static_solver.h"
#include "contact/tool_contacts.h"
#include "support/direct_solve.h"
#include "support/slab_util.h"

using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::contact;

namespace surgsim {
namespace {

constexpr double kTop = 0.04;  // m, top face of the slab
constexpr double kDt = 1e-3;   // s

using test::ReferenceContact;
using test::ReferencePatch;

class LiverTwoHandsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    slab_ = new test::Slab(20, 20, 4, {0.2, 0.2, 0.04});
    FixedRegion region;
    region.has_plane = true;
    region.plane_point = {0, 0, 0.001};
    region.plane_normal = {0, 0, -1};
    fixed_ = new FixedSet(fixed_set_from_region(slab_->mesh, region));
    model_ = new ElasticModel(build_elastic_model(slab_->mesh, Material{3000.0, 0.45}, *fixed_));
    // The reference sees the geometry only: the bottom face (z = 0) is what is fixed.
    std::vector<int> bottom;
    for (Eigen::Index n = 0; n < slab_->mesh.nodes.rows(); ++n)
      if (slab_->mesh.nodes(n, 2) == 0.0) bottom.push_back(static_cast<int>(n));
    ASSERT_EQ(bottom.size(), 21u * 21u);
    direct_ = new test::DirectReference(slab_->mesh.nodes, slab_->mesh.tets, 3000.0, 0.45, bottom);
    ASSERT_TRUE(direct_->ok());
  }
  static void TearDownTestSuite() {
    delete direct_;
    delete model_;
    delete fixed_;
    delete slab_;
  }
  static ToolSpec spec(const char* name) {
    ToolSpec s;
    s.name = name;
    s.shaft_points = 1;
    s.force_limit = 100.0;
    s.contact_capacity = 32;
    return s;
  }
  static std::vector<ToolSpec> two(ContactModel model = ContactModel::kPatch) {
    std::vector<ToolSpec> t = {spec("left"), spec("right")};
    for (ToolSpec& s : t) s.contact_model = model;
    return t;
  }
  static ToolContacts contacts(const std::vector<ToolSpec>& tools) {
    return ToolContacts(slab_->mesh, slab_->surface, slab_->tensors, tools);
  }
  // One tick with instrument t's tip at tips[t] (a NaN x: that instrument's input is lost).
  static void step(ToolContacts& c, const std::vector<Eigen::Vector3d>& tips, std::vector<ContactTick>& out,
                   const std::vector<double>& jaws = {0.5, 0.5}) {
    std::vector<ToolGeometry> g(tips.size());
    std::vector<InstrumentInput> in(tips.size());
    for (std::size_t t = 0; t < tips.size(); ++t) {
      g[t] = test::vertical_tool(tips[t]);
      in[t] = InstrumentInput{std::isnan(tips[t].x()) ? nullptr : &g[t], jaws[t]};
    }
    out.assign(tips.size(), ContactTick{});
    c.step(in.data(), static_cast<int>(tips.size()), out.data(), kDt);
  }
  static Eigen::Vector3d at(double x, double y, double depth) { return {x, y, kTop - depth}; }

  // A vertical tool point of instrument t at `tip` (radius: the instruments' default tip), sliding or grasping what
  // it held at `grasp_tip`.
  static ReferenceContact probe(int t, const Eigen::Vector3d& tip) {
    ReferenceContact r;
    r.instrument = t;
    r.tip = tip;
    r.axis = {0, 0, -1};
    r.radius = ToolSpec{}.tip_radius;
    return r;
  }
  static ReferenceContact grasp(int t, const Eigen::Vector3d& tip, const Eigen::Vector3d& grasp_tip) {
    ReferenceContact r = probe(t, tip);
    r.grasp = true;
    r.grasp_tip = grasp_tip;
    return r;
  }
  static std::vector<Eigen::Vector3d> direct(const std::vector<ReferenceContact>& contacts, int instruments) {
    return direct_->forces(contacts, instruments);
  }
  // Instrument t's patch in ToolContacts against the reference's: the same nodes and weights, normal, offset and near
  // field.
  static void expect_same_patch(const ToolContacts& c, int t, const ReferencePatch& ref) {
    const PointPatch& p = c.patch(0, t);
    std::map<int, double> got;
    for (int e = 0; e < p.count; ++e)
      got[p.nodes[static_cast<std::size_t>(e)]] = p.weights[static_cast<std::size_t>(e)];
    ASSERT_EQ(got.size(), ref.nodes.size()) << "instrument " << t << ": patch nodes";
    for (std::size_t e = 0; e < ref.nodes.size(); ++e) {
      ASSERT_EQ(got.count(ref.nodes[e]), 1u) << "instrument " << t << ": node " << ref.nodes[e] << " not in its patch";
      EXPECT_NEAR(got[ref.nodes[e]], ref.weights[e], 1e-12)
          << "instrument " << t << ": weight of node " << ref.nodes[e];
    }
    EXPECT_LE((p.normal - ref.normal).norm(), 1e-12) << "instrument " << t;
    EXPECT_LE((c.point(0, t).offset - ref.offset).norm(), 1e-12) << "instrument " << t << ": offset";
    EXPECT_NEAR(p.near_normal, ref.near_normal, 1e-9 * ref.near_normal) << "instrument " << t << ": near field";
  }

  static test::Slab* slab_;
  static FixedSet* fixed_;
  static ElasticModel* model_;
  static test::DirectReference* direct_;
};
test::Slab* LiverTwoHandsTest::slab_ = nullptr;
FixedSet* LiverTwoHandsTest::fixed_ = nullptr;
ElasticModel* LiverTwoHandsTest::model_ = nullptr;
test::DirectReference* LiverTwoHandsTest::direct_ = nullptr;

double rel(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return (a - b).norm() / b.norm(); }

// Two tips 3 cm apart pressing 5 mm (patch model): each force is the direct solve with both constraints, and not
// the force of the same tip alone (the tissue couples them).
TEST_F(LiverTwoHandsTest, EachForceIsTheDirectSolveWithBothConstraintsAndNotTheForceAlone) {
  ToolContacts c = contacts(two());
  ToolContacts alone = contacts({spec("left")});
  std::vector<ContactTick> out, out_alone;
  const double xa = 0.085, xb = 0.115, y = 0.1;
  for (int k = 0; k <= 60; ++k) {
    const double depth = 0.005 * std::min(1.0, k / 40.0);
    step(c, {at(xa, y, depth), at(xb, y, depth)}, out);
    step(alone, {at(xa, y, depth)}, out_alone);
  }
  ASSERT_EQ(out[0].points_in_contact, 1);
  ASSERT_EQ(out[1].points_in_contact, 1);
  // The reference from the tips alone.
  const std::vector<Eigen::Vector3d> d = direct({probe(0, at(xa, y, 0.005)), probe(1, at(xb, y, 0.005))}, 2);
  std::cout << "[two hands] left " << out[0].force.transpose() << " N (direct " << d[0].transpose() << ", alone "
            << out_alone[0].force.transpose() << "), right " << out[1].force.transpose() << " N; coupling: left "
            << 100 * (out[0].force.z() - out_alone[0].force.z()) / out_alone[0].force.z() << " % vs alone\n";
  EXPECT_LE(rel(out[0].force, d[0]), 1e-9);
  EXPECT_LE(rel(out[1].force, d[1]), 1e-9);
  // Pressing beside it relieves the left tip (the right one already pushed the tissue down under it).
  EXPECT_GT(rel(out[0].force, out_alone[0].force), 1e-2);
  EXPECT_LT(out[0].force.z(), out_alone[0].force.z());
  // Each solution node is credited to an instrument, and both instruments hold nodes.
  EXPECT_GT(c.instrument_nodes(0), 0);
  EXPECT_GT(c.instrument_nodes(1), 0);
  EXPECT_EQ(c.instrument_nodes(0) + c.instrument_nodes(1), c.solution().count);
}

// The reference's own patch on the flat top of the slab, from the tip's position alone: its normal is the face's,
// its weights are positive and sum to 1, their first moment is the tip's centre (the footprint is a symmetric load
// and P1 shape functions reproduce linear fields), its offset is the depth below the top face; and the model's
// 4 x 12 quadrature integrates the punch's pressure against the shape functions (a 64 x 256 rule of the same
// integral agrees), so the rule it reproduces is the contact model's integral, not an arbitrary one.
TEST_F(LiverTwoHandsTest, TheReferencePatchOnTheSlabHasTheSlabsInvariants) {
  const double a = ToolSpec{}.tip_radius;
  for (const Eigen::Vector3d& tip :
       {at(0.085, 0.1, 0.005), at(0.115, 0.1, 0.005), at(0.0833, 0.1021, 0.0031), at(0.1171, 0.0968, 0.0007)}) {
    const ReferencePatch p = direct_->patch(probe(1, tip));
    ASSERT_FALSE(p.nodes.empty());
    EXPECT_LE((p.normal - Eigen::Vector3d::UnitZ()).norm(), 1e-12);
    EXPECT_LE((p.centre - Eigen::Vector3d(tip.x(), tip.y(), kTop)).norm(), 1e-12);
    double sum = 0;
    Eigen::Vector3d moment = Eigen::Vector3d::Zero();
    for (std::size_t e = 0; e < p.nodes.size(); ++e) {
      EXPECT_GT(p.weights[e], 0.0);
      EXPECT_NEAR(slab_->mesh.nodes(p.nodes[e], 2), kTop, 1e-15) << "a node off the top face";
      sum += p.weights[e];
      moment += p.weights[e] * slab_->mesh.nodes.row(p.nodes[e]).transpose();
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_LE((moment - p.centre).norm(), 1e-12);
    EXPECT_NEAR(p.depth, kTop - tip.z(), 1e-12);
    EXPECT_LE((p.offset - Eigen::Vector3d(0, 0, -(kTop - tip.z()))).norm(), 1e-12);
    EXPECT_GT(p.near_normal, 0.0);
    const auto fine = direct_->footprint(p.centre, p.normal, a, 64, 256);
    std::map<int, double> exact(fine.begin(), fine.end());
    double worst = 0;
    for (std::size_t e = 0; e < p.nodes.size(); ++e)
      worst = std::max(worst, std::abs(p.weights[e] - exact[p.nodes[e]]));
    for (const auto& [node, w] : exact)
      if (std::find(p.nodes.begin(), p.nodes.end(), node) == p.nodes.end()) worst = std::max(worst, w);
    std::cout << "[two hands, reference patch] tip " << tip.transpose() << ": " << p.nodes.size()
              << " nodes, largest weight difference from a 64 x 256 quadrature " << worst << "\n";
    EXPECT_LT(worst, 1e-3);
  }
}

// ToolContacts builds, for EACH instrument, the patch the reference derives from that instrument's tip: the same
// nodes and weights, normal, offset and near field (the two tips 3 cm apart of the first test, and two tips off the
// grid lines at other depths).
TEST_F(LiverTwoHandsTest, EachInstrumentsPatchIsTheReferencePatchOfItsTip) {
  const std::vector<std::vector<Eigen::Vector3d>> cases = {{at(0.085, 0.1, 0.005), at(0.115, 0.1, 0.005)},
                                                           {at(0.0833, 0.1021, 0.003), at(0.1171, 0.0968, 0.0045)}};
  for (const auto& tips : cases) {
    ToolContacts c = contacts(two());
    std::vector<ContactTick> out;
    for (int k = 0; k <= 60; ++k) {
      const double s = std::min(1.0, k / 40.0);
      step(c,
           {at(tips[0].x(), tips[0].y(), s * (kTop - tips[0].z())),
            at(tips[1].x(), tips[1].y(), s * (kTop - tips[1].z()))},
           out);
    }
    ASSERT_EQ(out[0].points_in_contact, 1);
    ASSERT_EQ(out[1].points_in_contact, 1);
    for (int t = 0; t < 2; ++t) {
      SCOPED_TRACE("tip " + std::to_string(t));
      expect_same_patch(c, t, direct_->patch(probe(t, tips[static_cast<std::size_t>(t)])));
    }
    const std::vector<Eigen::Vector3d> d = direct({probe(0, tips[0]), probe(1, tips[1])}, 2);
    EXPECT_LE(rel(out[0].force, d[0]), 1e-9);
    EXPECT_LE(rel(out[1].force, d[1]), 1e-9);
  }
}

// The paper's triangle model: node displacements imposed, so the direct solve is StaticSolver (CHOLMOD) with every
// node of both instruments imposed; each instrument's force is minus the reactions of its own nodes.
TEST_F(LiverTwoHandsTest, TriangleModelMatchesTheDirectSolveWithEveryNodeImposed) {
  ToolContacts c = contacts(two(ContactModel::kTriangle));
  std::vector<ContactTick> out;
  step(c, {at(0.083, 0.102, -0.002), at(0.117, 0.097, -0.002)}, out);
  for (int k = 1; k <= 20; ++k) step(c, {at(0.083, 0.102, 0.0003 * k), at(0.117, 0.097, 0.0003 * k)}, out);
  ASSERT_EQ(out[0].points_in_contact, 1);
  ASSERT_EQ(out[1].points_in_contact, 1);
  const ContactSolution& s = c.solution();
  std::vector<ImposedDisplacement> imposed;
  for (int l = 0; l < s.count; ++l)
    imposed.push_back({s.nodes[static_cast<std::size_t>(l)], s.displacement[static_cast<std::size_t>(l)], 7});
  StaticSolver solver(*model_);
  const StaticSolution direct = solver.solve(imposed);
  Eigen::Vector3d f[2] = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  for (std::size_t i = 0; i < direct.imposed_nodes.size(); ++i) {
    int owner = -1;
    for (int l = 0; l < s.count; ++l)
      if (s.nodes[static_cast<std::size_t>(l)] == direct.imposed_nodes[i]) owner = c.node_instrument(l);
    ASSERT_GE(owner, 0);
    f[owner] -= direct.reaction.row(static_cast<Eigen::Index>(i)).transpose();
  }
  std::cout << "[two hands, triangle] left " << out[0].force.transpose() << " N (direct " << f[0].transpose()
            << "), right " << out[1].force.transpose() << " N (direct " << f[1].transpose() << ")\n";
  EXPECT_LE(rel(out[0].force, f[0]), 1e-9);
  EXPECT_LE(rel(out[1].force, f[1]), 1e-9);
}

// Input lost on the left instrument: its force is zero and its contacts are gone; the right one goes on as if it
// had been alone from then on (the same force as a one-instrument contact driven along the same path).
TEST_F(LiverTwoHandsTest, OneInstrumentLostLeavesTheOtherUnaffected) {
  ToolContacts c = contacts(two());
  ToolContacts right_alone = contacts({spec("right")});
  std::vector<ContactTick> out, alone;
  const double nan = std::nan("");
  for (int k = 0; k <= 60; ++k) {
    const double depth = 0.005 * std::min(1.0, k / 40.0);
    step(c, {at(0.085, 0.1, depth), at(0.115, 0.1, depth)}, out);
    step(right_alone, {at(0.115, 0.1, depth)}, alone);
  }
  const Eigen::Vector3d coupled = out[1].force;
  step(c, {Eigen::Vector3d(nan, 0, 0), at(0.115, 0.1, 0.005)}, out);
  step(right_alone, {at(0.115, 0.1, 0.005)}, alone);
  EXPECT_EQ(out[0].device_force, Eigen::Vector3d::Zero());
  EXPECT_EQ(out[0].points_in_contact, 0);
  EXPECT_EQ(c.instrument_nodes(0), 0);
  EXPECT_FALSE(out[1].nonfinite);
  EXPECT_EQ(out[1].points_in_contact, 1);
  EXPECT_LE(rel(out[1].force, alone[0].force), 1e-9) << "the right instrument alone";
  EXPECT_GT(rel(coupled, alone[0].force), 1e-2) << "it was coupled before the loss";
  std::cout << "[two hands, lost] right: " << coupled.z() << " N coupled, " << out[1].force.z()
            << " N once the left input is lost (alone: " << alone[0].force.z() << " N)\n";
  // The left one comes back: found again inside the tissue in one tick (no onset ramp), coupled again.
  step(c, {at(0.085, 0.1, 0.005), at(0.115, 0.1, 0.005)}, out);
  EXPECT_EQ(out[0].points_in_contact, 1);
  EXPECT_LE(rel(out[1].force, coupled), 1e-9);
}

// The left instrument grasps (jaw closed) and lifts the tissue 4 mm; the right one then presses 2.5 cm away. The
// grasp holds throughout, and the grasper feels the press through the tissue: its force is the direct solve with its
// 3-D hold and the probe's normal constraint.
TEST_F(LiverTwoHandsTest, AGraspHeldByOneWhileTheOtherPresses) {
  ToolContacts c = contacts(two());
  std::vector<ContactTick> out;
  const Eigen::Vector3d away(0.125, 0.1, kTop + 0.01);
  const double xg = 0.1, y = 0.1;
  for (int k = 0; k <= 40; ++k) step(c, {at(xg, y, 0.002 * std::min(1.0, k / 20.0)), away}, out);  // press 2 mm
  for (int k = 0; k <= 10; ++k) step(c, {at(xg, y, 0.002), away}, out, {0.0, 0.5});                // close the jaw
  ASSERT_TRUE(out[0].grasp);
  for (int k = 0; k <= 60; ++k)  // lift to 4 mm up
    step(c, {at(xg, y, 0.002 - 0.006 * std::min(1.0, k / 40.0)), away}, out, {0.0, 0.5});
  ASSERT_TRUE(out[0].grasp);
  const Eigen::Vector3d holding = out[0].force;
  EXPECT_LT(holding.z(), 0.0) << "the lifted tissue pulls the grasper down";
  for (int k = 0; k <= 60; ++k)
    step(c, {at(xg, y, -0.004), at(0.125, y, 0.006 * std::min(1.0, k / 40.0))}, out, {0.0, 0.5});
  ASSERT_TRUE(out[0].grasp);
  ASSERT_EQ(out[1].points_in_contact, 1);
  // The reference from the tips alone: the grasper holds what it closed on at 2 mm depth, now 4 mm up.
  const std::vector<Eigen::Vector3d> d =
      direct({grasp(0, at(xg, y, -0.004), at(xg, y, 0.002)), probe(1, at(0.125, y, 0.006))}, 2);
  std::cout << "[two hands, grasp] grasper " << holding.transpose() << " N holding alone, " << out[0].force.transpose()
            << " N while the probe presses (direct " << d[0].transpose() << "); probe " << out[1].force.transpose()
            << " N\n";
  EXPECT_LE(rel(out[0].force, d[0]), 1e-9);
  EXPECT_LE(rel(out[1].force, d[1]), 1e-9);
  EXPECT_GT(rel(out[0].force, holding), 1e-2) << "the press changes what the grasper feels";
  expect_same_patch(c, 0, direct_->patch(grasp(0, at(xg, y, -0.004), at(xg, y, 0.002))));
  expect_same_patch(c, 1, direct_->patch(probe(1, at(0.125, y, 0.006))));
}

// Each instrument is clamped to its own device limit, and says so only for itself.
TEST_F(LiverTwoHandsTest, EachInstrumentIsClampedToItsOwnLimit) {
  std::vector<ToolSpec> tools = two();
  tools[0].force_limit = 0.05;
  ToolContacts c = contacts(tools);
  std::vector<ContactTick> out;
  for (int k = 0; k <= 60; ++k) {
    const double depth = 0.005 * std::min(1.0, k / 40.0);
    step(c, {at(0.085, 0.1, depth), at(0.115, 0.1, depth)}, out);
  }
  EXPECT_TRUE(out[0].saturated);
  EXPECT_NEAR(out[0].device_force.norm(), 0.05, 1e-12);
  EXPECT_FALSE(out[1].saturated);
  EXPECT_EQ(out[1].device_force, out[1].force);
}

}  // namespace
}  // namespace surgsim
