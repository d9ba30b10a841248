#include "intestine/collision_response.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "support/alloc_counter.h"
#include "intestine/stochastic_collision.h"

using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

// Two segments (nodes 0-1 and 2-3) crossing at right angles, `gap` m apart along z, approaching at `speed` m/s.
void crossing(double gap, double speed, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v) {
  x.resize(3, 4);
  v.setZero(3, 4);
  x.col(0) = Eigen::Vector3d(-0.03, 0, 0);
  x.col(1) = Eigen::Vector3d(0.01, 0, 0);  // the closest point at s = 0.75
  x.col(2) = Eigen::Vector3d(0, -0.02, -gap);
  x.col(3) = Eigen::Vector3d(0, 0.02, -gap);
  v.col(0) = v.col(1) = Eigen::Vector3d(0, 0, -0.5 * speed);
  v.col(2) = v.col(3) = Eigen::Vector3d(0, 0, 0.5 * speed);
}

CollisionContact contact_of(const Eigen::Matrix3Xd& x, double radius_sum) {
  double s = 0, t = 0;
  const double d = segment_segment(x.col(0), x.col(1), x.col(2), x.col(3), s, t);
  CollisionContact c;
  c.nodes = {0, 1, 2, 3, -1};
  c.weights = {1 - s, s, 1 - t, t, 0};
  c.normal = ((x.col(0) + s * (x.col(1) - x.col(0))) - (x.col(2) + t * (x.col(3) - x.col(2)))) / d;
  c.radius_sum = radius_sum;
  c.distance = d;
  return c;
}

TEST(CollisionResponseTest, CancelsApproachAndRestoresTheRadiiOnACrossing) {
  Eigen::Matrix3Xd x, v;
  crossing(0.01, 0.2, x, v);
  ContactList list(4);
  list.push(contact_of(x, 0.04));
  const std::vector<double> inv_mass(4, 1.0 / 0.012);
  const Eigen::Matrix3Xd x0 = x, v0 = v;
  ResponseReport rep;
  respond(list, inv_mass.data(), ResponseParams{}, x, v, rep);
  EXPECT_NEAR(rep.max_penetration_before, 0.03, 1e-12);
  EXPECT_NEAR(contact_gap(list[0], x), 0.0, 1e-12);
  EXPECT_LE(rep.max_penetration_after, 1e-12);
  EXPECT_EQ(rep.velocity_corrections, 1);
  // No approach left along n; the points now move together along n.
  const CollisionContact& c = list[0];
  const Eigen::Vector3d va = c.weights[0] * v.col(0) + c.weights[1] * v.col(1);
  const Eigen::Vector3d vb = c.weights[2] * v.col(2) + c.weights[3] * v.col(3);
  EXPECT_NEAR((va - vb).dot(c.normal), 0.0, 1e-12);
  // Equal masses: momentum and the centre of mass are unchanged (internal impulses, eqs. 2-9).
  EXPECT_LT((v.rowwise().sum() - v0.rowwise().sum()).norm(), 1e-12);
  EXPECT_LT((x.rowwise().sum() - x0.rowwise().sum()).norm(), 1e-12);
  // The closer node of each segment moves more (weights 0.75 / 0.25 on A, 0.5 / 0.5 on B).
  EXPECT_NEAR((x.col(1) - x0.col(1)).norm() / (x.col(0) - x0.col(0)).norm(), 3.0, 1e-9);
}

TEST(CollisionResponseTest, SeparatingContactsKeepTheirVelocity) {
  Eigen::Matrix3Xd x, v;
  crossing(0.03, -0.2, x, v);  // moving apart already
  ContactList list(1);
  list.push(contact_of(x, 0.04));
  const std::vector<double> inv_mass(4, 100.0);
  const Eigen::Matrix3Xd v0 = v;
  ResponseReport rep;
  respond(list, inv_mass.data(), ResponseParams{}, x, v, rep);
  EXPECT_EQ(v, v0);
  EXPECT_EQ(rep.velocity_corrections, 0);
  EXPECT_NEAR(contact_gap(list[0], x), 0.0, 1e-12);
}

TEST(CollisionResponseTest, FixedNodesDoNotMove) {
  Eigen::Matrix3Xd x, v;
  crossing(0.005, 0.1, x, v);
  ContactList list(1);
  list.push(contact_of(x, 0.025));
  const std::vector<double> inv_mass{100.0, 100.0, 0.0, 0.0};  // segment B fixed (the vessel)
  const Eigen::Matrix3Xd x0 = x;
  ResponseReport rep;
  respond(list, inv_mass.data(), ResponseParams{}, x, v, rep);
  EXPECT_EQ(x.col(2), x0.col(2));
  EXPECT_EQ(x.col(3), x0.col(3));
  EXPECT_NEAR(contact_gap(list[0], x), 0.0, 1e-12);
}

TEST(CollisionResponseTest, PointTriangleContactMovesTheBarycentricPointByTheCorrection) {
  // Segment A (nodes 0, 1) above triangle B (nodes 2, 3, 4), 1 cm above the plane; contact distance 2.5 cm.
  Eigen::Matrix3Xd x(3, 5), v = Eigen::Matrix3Xd::Zero(3, 5);
  x.col(0) = Eigen::Vector3d(0.01, 0.01, 0.01);
  x.col(1) = Eigen::Vector3d(0.05, 0.01, 0.03);
  x.col(2) = Eigen::Vector3d(0, 0, 0);
  x.col(3) = Eigen::Vector3d(0.05, 0, 0);
  x.col(4) = Eigen::Vector3d(0, 0.05, 0);
  double s = 0;
  Eigen::Vector3d bary;
  const double d = segment_triangle(x.col(0), x.col(1), x.col(2), x.col(3), x.col(4), s, bary);
  ASSERT_NEAR(d, 0.01, 1e-12);
  CollisionContact c;
  c.kind = ContactKind::kSegmentTriangle;
  c.count_b = 3;
  c.nodes = {0, 1, 2, 3, 4};
  c.weights = {1 - s, s, bary[0], bary[1], bary[2]};
  c.normal = Eigen::Vector3d::UnitZ();
  c.radius_sum = 0.025;
  c.distance = d;
  ContactList list(1);
  list.push(c);
  const std::vector<double> inv_mass{1, 1, 2, 2, 2};
  ResponseReport rep;
  respond(list, inv_mass.data(), ResponseParams{}, x, v, rep);
  EXPECT_NEAR(contact_gap(c, x), 0.0, 1e-12);
  // Heavier side moves less: the mass-weighted split.
  const double move_a = ((1 - s) * x.col(0) + s * x.col(1)).z() - 0.01;
  EXPECT_GT(move_a, 0);
  EXPECT_NEAR(rep.max_penetration_before, 0.015, 1e-12);
}

// A chain of segments crafted into crossings: a parallel overlap (a flat valley of contacts, 2.5 cm deep) and a run
// crossing both. The brute-force detector finds every intestine-intestine contact, the response with its fixed
// iteration count must leave no interpenetration. (The grid's second row only completes the topology: its cells are
// walls to the far fixed row, so the mesentery contacts are left out here.)
TEST(CollisionResponseTest, NoInterpenetrationLeftOnCraftedCrossings) {
  const int cols = 40;
  CollisionTopology topo;
  topo.rows = 2;
  topo.cols = cols;
  for (int i = 0; i < 2 * cols; ++i) topo.grid.push_back(i);
  Eigen::Matrix3Xd x(3, 2 * cols);
  // Run 1 (segments 0..11) along x at z = 0; run 2 (13..24) back along x at z = 0.015 (overlapping, 1.5 cm apart:
  // 2.5 cm of penetration); run 3 (26..38) crosses both along y at z = 0.03.
  for (int c = 0; c < cols; ++c) {
    Eigen::Vector3d p;
    if (c <= 12) {
      p = Eigen::Vector3d(0.04 * c, 0, 0);
    } else if (c <= 25) {
      p = Eigen::Vector3d(0.04 * (25 - c), 0.0, 0.015) + Eigen::Vector3d(0, 0.003 * (c - 12), 0);
    } else {
      p = Eigen::Vector3d(0.2, -0.26 + 0.04 * (c - 26), 0.03);
    }
    x.col(c) = p;
    x.col(cols + c) = p + Eigen::Vector3d(0, 0, 10);  // far away fixed row
  }
  std::vector<double> inv_mass(static_cast<std::size_t>(2 * cols), 1.0 / 0.012);
  for (int c = 0; c < cols; ++c) inv_mass[static_cast<std::size_t>(cols + c)] = 0;
  Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, 2 * cols);

  auto segment_contacts = [&](ContactList& out) {
    ContactList all(8192);
    detect_brute_force(topo, x, all);
    out.clear();
    for (const auto& c : all) {
      if (c.kind == ContactKind::kSegmentSegment) out.push(c);
    }
  };
  ContactList before(4096);
  segment_contacts(before);
  ASSERT_GT(before.size(), 20);
  double worst = 0;
  for (const auto& c : before) worst = std::max(worst, c.radius_sum - c.distance);
  EXPECT_GT(worst, 0.02);

  // Detection and response alternate as in the loop (a few steps without dynamics).
  ResponseParams params;
  ContactList list(4096);
  for (int step = 0; step < 5; ++step) {
    segment_contacts(list);
    ResponseReport rep;
    respond(list, inv_mass.data(), params, x, v, rep);
  }
  ContactList after(4096);
  segment_contacts(after);
  double left = 0;
  for (const auto& c : after) left = std::max(left, c.radius_sum - c.distance);
  EXPECT_LT(left, 1e-4) << after.size() << " contacts left";
}

TEST(CollisionResponseTest, RespondAllocatesNothing) {
  Eigen::Matrix3Xd x, v;
  crossing(0.01, 0.2, x, v);
  ContactList list(8);
  for (int i = 0; i < 8; ++i) list.push(contact_of(x, 0.04));
  const std::vector<double> inv_mass(4, 1.0);
  ResponseReport rep;
  surgsim::test::AllocationCounter counter;
  respond(list, inv_mass.data(), ResponseParams{}, x, v, rep);
  list.clear();
  EXPECT_EQ(counter.count(), 0);
}

TEST(CollisionResponseTest, ContactListCountsOverflow) {
  ContactList list(2);
  CollisionContact c;
  EXPECT_TRUE(list.push(c));
  EXPECT_TRUE(list.push(c));
  EXPECT_FALSE(list.push(c));
  EXPECT_EQ(list.size(), 2);
  EXPECT_EQ(list.dropped(), 1);
  list.clear();
  EXPECT_EQ(list.size(), 0);
  EXPECT_EQ(list.dropped(), 0);
}

}  // namespace
}  // namespace surgsim::intestine
