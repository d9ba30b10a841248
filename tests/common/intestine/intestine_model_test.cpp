#include "intestine/intestine_model.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <limits>

#include "support/alloc_counter.h"
#include "core/error.h"
#include "support/intestine_test_util.h"

namespace surgsim::intestine {
namespace {

TEST(IntestineModelTest, RestShapeIsTheFoldedCurveOnTheCylinder) {
  const IntestineParams p;
  const IntestineModel model(p);
  ASSERT_EQ(model.rows(), 4);
  ASSERT_EQ(model.columns(), 100);
  ASSERT_EQ(model.node_count(), 400);
  const Eigen::Matrix3Xd& x = model.rest();
  const Eigen::Vector3d axis = p.axis_direction.normalized();
  auto radius = [&](const Eigen::Vector3d& q) {
    const Eigen::Vector3d d = q - p.axis_origin;
    return (d - d.dot(axis) * axis).norm();
  };
  double length = 0;
  for (int c = 0; c < model.columns(); ++c) {
    // The intestine on the cylinder, the vessel row on the axis and fixed, the mesentery rows between.
    EXPECT_NEAR(radius(x.col(model.node(0, c))), p.cylinder_radius, 1e-12);
    EXPECT_NEAR(radius(x.col(model.node(3, c))), 0.0, 1e-12);
    EXPECT_NEAR(radius(x.col(model.node(1, c))), p.cylinder_radius * 2 / 3, 1e-12);
    EXPECT_TRUE(model.mass_spring().fixed(model.node(3, c)));
    EXPECT_FALSE(model.mass_spring().fixed(model.node(0, c)));
    if (c > 0) length += (x.col(c) - x.col(c - 1)).norm();
  }
  // 4 m along the curve, nodes equally spaced along it: the chords are at most the arc between two nodes, a little
  // shorter across the crests.
  EXPECT_NEAR(model.segment_length(), p.length / 99, 1e-9);
  EXPECT_LE(length, p.length);
  EXPECT_GT(length, 0.97 * p.length);
  for (int c = 1; c < model.columns(); ++c) {
    const double chord = (x.col(c) - x.col(c - 1)).norm();
    EXPECT_LE(chord, model.segment_length() * (1 + 1e-6));
    EXPECT_GT(chord, 0.8 * model.segment_length());
  }
  // Folded: the curve goes back and forth along the vessel `folds` times.
  int turns = 0;
  for (int c = 2; c < model.columns(); ++c) {
    const double a = (x.col(c - 1) - x.col(c - 2)).dot(axis), b = (x.col(c) - x.col(c - 1)).dot(axis);
    turns += (a > 0) != (b > 0);
  }
  EXPECT_GE(turns, 2 * p.folds - 1);
  EXPECT_GT(model.fold_amplitude(), 0.1);
  // Intestine masses, springs of each kind.
  int kinds[3] = {0, 0, 0};
  for (const Spring& s : model.mass_spring().springs()) ++kinds[static_cast<int>(s.kind)];
  EXPECT_EQ(kinds[static_cast<int>(SpringKind::kBending)], 98);
  EXPECT_EQ(kinds[static_cast<int>(SpringKind::kShear)], 2 * 3 * 99);
  EXPECT_EQ(kinds[static_cast<int>(SpringKind::kStructural)], 3 * 99 + 3 * 100);  // the vessel row's own are fixed
  // The flat buffer: the intestine's points first.
  IntestineState state(model);
  EXPECT_EQ(state.point_count(), 400);
  EXPECT_EQ(state.positions()[3 * 7 + 2], x(2, 7));
}

TEST(IntestineModelTest, RestShapeHasNoCollision) {
  const IntestineModel model(IntestineParams{});
  ContactList contacts(10000);
  detect_brute_force(model.topology(), model.rest(), contacts);
  EXPECT_EQ(contacts.size(), 0);
}

TEST(IntestineModelTest, RejectsBadParameters) {
  auto bad = [](auto change) {
    IntestineParams p;
    change(p);
    return p;
  };
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.columns = 3; })), Error);
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.rows = 30; })), Error);  // > kMaxIntestineNodes
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.length = 0.5; })), Error);  // shorter than the arc
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.intestine_radius = 0; })), Error);
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.axis_direction.setZero(); })), Error);
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.structural_stiffness = -1; })), Error);
  EXPECT_THROW(IntestineModel(bad([](IntestineParams& p) { p.gravity.x() = std::nan(""); })), Error);
  EXPECT_NO_THROW(IntestineModel(bad([](IntestineParams& p) { p.axis_direction = Eigen::Vector3d(0, 0, 2); })));
}

TEST(IntestineModelTest, StepAllocatesNothing) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 2);
  StepReport report;
  for (int s = 0; s < 500; ++s) step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
  surgsim::test::AllocationCounter counter;
  int contacts = 0, probe = 0;
  for (int s = 500; s < 1000; ++s) {
    step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
    contacts += report.contacts;
    probe += report.probe_contacts;
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_GT(contacts, 0);  // the run did collide and touch
  EXPECT_GT(probe, 0);
  EXPECT_EQ(state.faults, 0u);
  EXPECT_EQ(state.steps, 1000u);
}

TEST(IntestineModelTest, SameSeedGivesBitIdenticalStates) {
  const IntestineModel model(IntestineParams{});
  IntestineState a(model, 7), b(model, 7);
  StepReport ra, rb;
  for (int s = 0; s < 800; ++s) {
    const Probe probe = test::scripted_probe(0.2 + s * 1e-3);
    step(model, a, probe, 1e-3, ra);
    step(model, b, probe, 1e-3, rb);
  }
  EXPECT_EQ(std::memcmp(a.x.data(), b.x.data(), sizeof(double) * static_cast<std::size_t>(a.x.size())), 0);
  EXPECT_EQ(std::memcmp(a.v.data(), b.v.data(), sizeof(double) * static_cast<std::size_t>(a.v.size())), 0);
  EXPECT_EQ(ra.probe_force, rb.probe_force);
  // reset() brings back the initial state: the same run again is identical too.
  b.reset(model, 7);
  for (int s = 0; s < 800; ++s) step(model, b, test::scripted_probe(0.2 + s * 1e-3), 1e-3, rb);
  EXPECT_EQ(std::memcmp(a.x.data(), b.x.data(), sizeof(double) * static_cast<std::size_t>(a.x.size())), 0);
}

TEST(IntestineModelTest, ProbeForcePushesTheToolOutAndIsClamped) {
  IntestineParams p;
  p.gravity.setZero();
  p.self_collisions = false;
  const IntestineModel model(p);
  IntestineState state(model);
  StepReport report;
  // The probe 1 cm inside the intestine's surface at the middle of segment 40, from outside the cylinder.
  const Eigen::Vector3d a = model.rest().col(40), b = model.rest().col(41), mid = 0.5 * (a + b);
  const Eigen::Vector3d axis = p.axis_direction.normalized();
  Eigen::Vector3d out = mid - p.axis_origin;
  out = (out - out.dot(axis) * axis).normalized();  // radial, away from the vessel
  Probe probe;
  probe.active = true;
  probe.radius = 0.005;
  probe.center = mid + out * (p.intestine_radius + probe.radius - 0.01);
  step(model, state, probe, 1e-3, report);
  ASSERT_EQ(report.status, StepStatus::kOk);
  EXPECT_GE(report.probe_contacts, 1);
  // On the tool: away from the intestine (outwards), about k x depth.
  EXPECT_GT(report.probe_force.dot(out), 0.9 * report.probe_force.norm());
  EXPECT_NEAR(report.probe_force.norm(), p.probe_stiffness * 0.01, 0.35 * p.probe_stiffness * 0.01);
  EXPECT_FALSE(report.probe_saturated);
  // Deep inside (2 mm off the axis): clamped to the limit, flagged.
  probe.center = mid + 0.002 * out;
  state.reset(model);
  step(model, state, probe, 1e-3, report);
  EXPECT_TRUE(report.probe_saturated);
  EXPECT_NEAR(report.probe_force.norm(), p.probe_force_limit, 1e-9);
  EXPECT_GT(report.probe_force_raw, p.probe_force_limit);
  // The intestine moves away from the probe.
  EXPECT_GT((state.x.col(40) - model.rest().col(40)).dot(-out), 0);
}

TEST(IntestineModelTest, NonFiniteInputsAreRefusedAndNeverReachTheState) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model);
  StepReport report;
  Probe probe;
  probe.active = true;
  probe.center = Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 0);
  step(model, state, probe, 1e-3, report);
  EXPECT_EQ(report.status, StepStatus::kOk);  // the probe is ignored, the body still steps
  EXPECT_TRUE(report.probe_rejected);
  EXPECT_EQ(report.probe_force, Eigen::Vector3d::Zero());
  EXPECT_TRUE(state.x.allFinite());
  const Eigen::Matrix3Xd before = state.x;
  step(model, state, Probe{}, std::numeric_limits<double>::quiet_NaN(), report);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  EXPECT_EQ(state.x, before);
  step(model, state, Probe{}, -1e-3, report);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  EXPECT_EQ(state.faults, 2u);
  // An explicit step far beyond its stability limit overflows: every such step is refused and the state stays
  // finite (the last good one).
  IntestineParams p;
  p.integrator = Integrator::kSymplecticEuler;
  p.structural_stiffness = 1e12;
  const IntestineModel wild(p);
  IntestineState ws(wild);
  int refused = 0;
  for (int s = 0; s < 300; ++s) {
    step(wild, ws, Probe{}, 1e-2, report);
    refused += report.status == StepStatus::kNonFinite;
    ASSERT_TRUE(ws.x.allFinite());
    ASSERT_TRUE(ws.v.allFinite());
    ASSERT_TRUE(report.probe_force.allFinite());
  }
  EXPECT_GT(refused, 0);
  EXPECT_EQ(ws.faults, static_cast<std::uint64_t>(refused));
}

TEST(IntestineModelTest, StiffModelWithCollisionsStaysFiniteAndBounded) {
  for (double k : {1e2, 1e4, 1e6}) {
    IntestineParams p;
    p.structural_stiffness = p.shear_stiffness = k;
    p.bending_stiffness = 0.1 * k;
    const IntestineModel model(p);
    IntestineState state(model, 3);
    StepReport report;
    const double e0 = energy(model, state);
    double emax = e0;
    for (int s = 0; s < 400; ++s) {
      step(model, state, test::scripted_probe(0.4 + s * 1e-3), 1e-3, report);
      ASSERT_EQ(report.status, StepStatus::kOk) << "k = " << k << " step " << s;
      emax = std::max(emax, energy(model, state));
    }
    // Gravity only lowers the energy; the probe adds a little work.
    EXPECT_LT(emax - e0, 0.5) << "k = " << k;
  }
}

}  // namespace
}  // namespace surgsim::intestine
