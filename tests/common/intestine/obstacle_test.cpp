// The bowel resting on another organ (intestine_model.h, Obstacle): each node whose sphere overlaps an obstacle gets a
// frictionless penalty contact. The references are the test's own: a plane obstacle written here, the weight from the
// masses, and the mesentery root's reaction from the springs that hold the free nodes to the fixed ones, computed from
// the positions with the spring law of mass_spring.h.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "intestine/intestine_model.h"
#include "support/alloc_counter.h"
#include "support/intestine_test_util.h"

namespace surgsim::intestine {
namespace {

// The half-space z >= height: free side up.
class Floor final : public Obstacle {
 public:
  explicit Floor(double height) : height_(height) {}
  bool nearest(const Eigen::Vector3d& p, double max_distance, ObstacleHit& hit) const noexcept override {
    const double d = p.z() - height_;
    if (std::abs(d) > max_distance && d > 0) return false;
    hit.distance = d;
    hit.normal = Eigen::Vector3d::UnitZ();
    return true;
  }

 private:
  double height_;
};

// A stretch of bowel as in the shipped field (config/abdomen.yaml), its vessel along x through the origin.
IntestineParams field_bowel() {
  IntestineParams p;
  p.length = 1.2;
  p.cylinder_radius = 0.05;
  p.folds = 4;
  p.columns = 50;
  p.rows = 4;
  p.intestine_radius = 0.012;
  p.mesentery_thickness = 0.008;
  p.intestine_node_mass = 0.008;
  p.mesentery_node_mass = 0.003;
  p.self_collisions = false;  // the balance below counts forces only (the response moves positions)
  return p;
}

// The force (N) the fixed nodes (the mesentery's root) exert on the free ones through the springs, from positions
// and velocities.
// Runs `seconds` at 1 kHz on the obstacles.
void settle(const IntestineModel& model, IntestineState& state, const Obstacle* const* obstacles, int count,
            double seconds, StepReport& report) {
  for (int s = 0; s < static_cast<int>(seconds * 1000); ++s) {
    step(model, state, nullptr, 0, 1e-3, report, obstacles, count);
    ASSERT_EQ(report.status, StepStatus::kOk) << "step " << s;
  }
}

TEST(IntestineObstacle, RestsOnAFloorWithTheFloorAndTheRootCarryingItsWeight) {
  const IntestineModel model(field_bowel());
  // Where the bowel hangs from its root alone: the floor goes halfway between that and the body as built (the sag
  // is 4 mm), so that the body settles onto it.
  IntestineState hanging(model);
  StepReport report;
  settle(model, hanging, nullptr, 0, 6.0, report);
  const double sag_low = test::lowest_sphere(model, hanging.x), rest_low = test::lowest_sphere(model, model.rest());
  const double height = 0.5 * (sag_low + rest_low);
  ASSERT_LT(height, rest_low) << "the floor must not cut the body as built";
  const Floor floor(height);
  const Obstacle* obstacles[] = {&floor};

  IntestineState state(model);
  settle(model, state, obstacles, 1, 8.0, report);
  ASSERT_EQ(report.obstacle_count, 1);
  const ObstacleReport& on_floor = report.obstacles[0];
  EXPECT_GT(on_floor.contacts, 3);
  EXPECT_LT(state.v.cwiseAbs().maxCoeff(), 1e-4) << "not at rest";
  // Nothing sinks: a node's weight on 2000 N/m is 0.04 mm.
  EXPECT_LT(on_floor.max_depth, 1e-3);
  EXPECT_GT(test::lowest_sphere(model, state.x), height - 1e-3);
  // The balance: what the floor and the root carry is the weight, within 1 % of it.
  const Eigen::Vector3d w = test::weight(model), root = test::root_reaction(model, state);
  const Eigen::Vector3d residual = on_floor.force + root + w;
  EXPECT_LT(residual.norm(), 0.01 * w.norm()) << "floor " << on_floor.force.transpose() << " N, root "
                                              << root.transpose() << " N, weight " << w.transpose() << " N";
  // ... and the floor carries a real share of it, straight up (frictionless).
  EXPECT_GT(on_floor.force.z(), 0.1 * w.norm());
  EXPECT_LT(std::hypot(on_floor.force.x(), on_floor.force.y()), 1e-9 * w.norm() + 1e-12);
  RecordProperty("floor_share", std::to_string(on_floor.force.z() / w.norm()));
  RecordProperty("balance_residual_fraction", std::to_string(residual.norm() / w.norm()));
}

TEST(IntestineObstacle, WithoutTheObstacleTheBodySinksThroughIt) {
  // The negative control of the floor above: the same body without it hangs lower than the floor.
  const IntestineModel model(field_bowel());
  IntestineState a(model), b(model);
  StepReport report;
  settle(model, a, nullptr, 0, 6.0, report);
  const double height = 0.5 * (test::lowest_sphere(model, a.x) + test::lowest_sphere(model, model.rest()));
  const Floor floor(height);
  const Obstacle* obstacles[] = {&floor};
  settle(model, b, obstacles, 1, 6.0, report);
  EXPECT_LT(test::lowest_sphere(model, a.x), height - 1.5e-3);
  EXPECT_GT(test::lowest_sphere(model, b.x), height - 0.5e-3);
}

TEST(IntestineObstacle, ZeroStiffnessPassesThroughAndCountsNoForce) {
  IntestineParams p = field_bowel();
  p.obstacle_stiffness = 0;
  const IntestineModel model(p);
  const Floor floor(test::lowest_sphere(model, model.rest()) + 0.01);  // cuts the body as built
  const Obstacle* obstacles[] = {&floor};
  IntestineState state(model);
  StepReport report;
  step(model, state, nullptr, 0, 1e-3, report, obstacles, 1);
  ASSERT_EQ(report.status, StepStatus::kOk);
  EXPECT_EQ(report.obstacles[0].contacts, 0);
  EXPECT_EQ(report.obstacles[0].force, Eigen::Vector3d::Zero());
}

TEST(IntestineObstacle, BadObstacleListsAreRefused) {
  const IntestineModel model(field_bowel());
  IntestineState state(model);
  StepReport report;
  const Floor floor(-1.0);
  const Obstacle* one[] = {&floor};
  step(model, state, nullptr, 0, 1e-3, report, nullptr, 1);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  const Obstacle* null_one[] = {nullptr};
  step(model, state, nullptr, 0, 1e-3, report, null_one, 1);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  step(model, state, nullptr, 0, 1e-3, report, one, kMaxObstacles + 1);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  EXPECT_EQ(state.steps, 0u);
  step(model, state, nullptr, 0, 1e-3, report, one, 1);
  EXPECT_EQ(report.status, StepStatus::kOk);
}

TEST(IntestineObstacle, OverflowIsCountedAndTheStepAllocatesNothing) {
  IntestineParams p = field_bowel();
  p.obstacle_capacity = 2;
  const IntestineModel model(p);
  const Floor floor(test::lowest_sphere(model, model.rest()) + 0.01);  // several nodes overlap it
  const Obstacle* obstacles[] = {&floor};
  IntestineState state(model);
  StepReport report;
  surgsim::test::AllocationCounter counter;
  step(model, state, nullptr, 0, 1e-3, report, obstacles, 1);
  EXPECT_EQ(counter.count(), 0);
  ASSERT_EQ(report.status, StepStatus::kOk);
  EXPECT_GT(report.obstacles[0].contacts, 2);
  EXPECT_EQ(report.obstacle_overflow, report.obstacles[0].contacts - 2);
}

}  // namespace
}  // namespace surgsim::intestine
