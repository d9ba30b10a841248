#include "intestine/intestine_model.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <limits>

#include "support/alloc_counter.h"
#include "core/error.h"
#include "support/intestine_test_util.h"

using namespace surgsim::core;
using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

// A probe of radius 5 mm `depth` (m) inside the intestine's surface at the middle of rest segment `segment`, from
// outside the cylinder; `out` is the radial direction there, away from the vessel.
Probe pressing(const IntestineModel& model, int segment, double depth, Eigen::Vector3d& out) {
  const IntestineParams& p = model.params();
  const Eigen::Vector3d mid = 0.5 * (model.rest().col(segment) + model.rest().col(segment + 1));
  const Eigen::Vector3d axis = p.axis_direction.normalized();
  out = mid - p.axis_origin;
  out = (out - out.dot(axis) * axis).normalized();
  Probe probe;
  probe.active = true;
  probe.radius = 0.005;
  probe.center = mid + out * (p.intestine_radius + probe.radius - depth);
  return probe;
}

// No gravity, no self-collisions: the body moves only where a probe pushes it.
IntestineParams still_params() {
  IntestineParams p;
  p.gravity.setZero();
  p.self_collisions = false;
  return p;
}

bool same_state(const IntestineState& a, const IntestineState& b) {
  const auto bytes = sizeof(double) * static_cast<std::size_t>(a.x.size());
  return std::memcmp(a.x.data(), b.x.data(), bytes) == 0 && std::memcmp(a.v.data(), b.v.data(), bytes) == 0;
}

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

// Paper section 7: the mesentery narrows to the vessel at both ends of the intestine. With a 10 % taper the end masses
// lie at 7.5 % of the full width from the vessel (the width reaches zero half a segment further), the middle at the
// full width, every row scaled alike; the rest shape still has no collision: the curve's ends lie apart along the
// vessel, carried beyond the folds' range [-A, A] (where every crest's sheet meets the vessel: without that extension
// the end segments touch the crests' sheets near the vessel, 32 contacts), and the tube lying on its own narrowed
// mesentery is not a contact (without the exclusion of the tapered columns' deeper rows: 44 contacts).
TEST(IntestineModelTest, TaperedMesenteryNarrowsToTheVesselAtBothEndsWithoutCollision) {
  IntestineParams p;
  p.mesentery_taper = 0.1;
  const IntestineModel model(p);
  const Eigen::Matrix3Xd& x = model.rest();
  const Eigen::Vector3d axis = p.axis_direction.normalized();
  auto radius = [&](const Eigen::Vector3d& q) {
    const Eigen::Vector3d d = q - p.axis_origin;
    return (d - d.dot(axis) * axis).norm();
  };
  const int last = model.columns() - 1;
  for (int c : {0, last}) {
    EXPECT_LT(radius(x.col(model.node(0, c))), 0.08 * p.cylinder_radius) << "column " << c;
    EXPECT_NEAR(radius(x.col(model.node(0, c))), mesentery_width_factor(p, c) * p.cylinder_radius, 1e-12);
    EXPECT_NEAR(radius(x.col(model.node(1, c))), 2.0 / 3.0 * radius(x.col(model.node(0, c))), 1e-12);
  }
  EXPECT_NEAR(radius(x.col(model.node(0, last / 2))), p.cylinder_radius, 1e-12);
  for (int c = 1; c <= 9; ++c)
    EXPECT_GT(mesentery_width_factor(p, c), mesentery_width_factor(p, c - 1)) << "the width grows from the end";
  EXPECT_EQ(mesentery_width_factor(p, 10), 1.0);
  EXPECT_EQ(model.topology().taper_columns, 10);
  // The two ends lie apart along the vessel (4.5 periods: one end at +amplitude, the other at -amplitude).
  const double s0 = (x.col(model.node(0, 0)) - p.axis_origin).dot(axis);
  const double s1 = (x.col(model.node(0, last)) - p.axis_origin).dot(axis);
  EXPECT_GT(std::abs(s0 - s1), 10 * p.intestine_radius);
  // ... beyond the folds' range, where no crest's sheet meets the vessel.
  EXPECT_GT(std::abs(s0), model.fold_amplitude() + 3 * p.intestine_radius);
  EXPECT_GT(std::abs(s1), model.fold_amplitude() + 3 * p.intestine_radius);
  EXPECT_LT(s0 * s1, 0.0);
  // The rest positions stay smooth (the extension grows with 1 - w, no jump): the columns are spaced on the folded
  // curve before narrowing and extension, so the tapered segments are up to 37 % longer than the mean (0.055 against
  // 0.040 m), consecutive ones within 30 % of the mean of each other.
  for (int c = 0; c + 1 < model.columns(); ++c) {
    const double l = (x.col(model.node(0, c + 1)) - x.col(model.node(0, c))).norm();
    EXPECT_NEAR(l, model.segment_length(), 0.4 * model.segment_length()) << "segment " << c;
    if (c + 2 < model.columns()) {
      const double next = (x.col(model.node(0, c + 2)) - x.col(model.node(0, c + 1))).norm();
      EXPECT_NEAR(next, l, 0.3 * model.segment_length()) << "segment " << c;
    }
  }
  ContactList contacts(10000);
  detect_brute_force(model.topology(), model.rest(), contacts);
  EXPECT_EQ(contacts.size(), 0);
  // The same shape without the tapered columns' exclusion: the tube lies on its own narrowed mesentery.
  CollisionTopology plain = model.topology();
  plain.taper_columns = 0;
  ContactList naive(10000);
  detect_brute_force(plain, model.rest(), naive);
  EXPECT_GT(naive.size(), 10);
  // Out of range is refused.
  p.mesentery_taper = 0.5;
  EXPECT_THROW(IntestineModel{p}, Error);
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

TEST(IntestineModelTest, StepWithFourProbesAllocatesNothing) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 2);
  StepReport report;
  auto probes_at = [](double t, Probe* probes) {
    for (int i = 0; i < kMaxProbes; ++i) probes[i] = test::scripted_probe(t + 0.35 * i);  // four places on the path
  };
  Probe probes[kMaxProbes];
  for (int s = 0; s < 500; ++s) {
    probes_at(s * 1e-3, probes);
    step(model, state, probes, kMaxProbes, 1e-3, report);
  }
  surgsim::test::AllocationCounter counter;
  int touching[kMaxProbes] = {0, 0, 0, 0};
  for (int s = 500; s < 1500; ++s) {
    probes_at(s * 1e-3, probes);
    step(model, state, probes, kMaxProbes, 1e-3, report);
    for (int i = 0; i < kMaxProbes; ++i) touching[i] += report.probes[static_cast<std::size_t>(i)].contacts > 0;
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_EQ(report.probe_count, kMaxProbes);
  for (int i = 0; i < kMaxProbes; ++i) EXPECT_GT(touching[i], 0) << "probe " << i << " never touched the body";
  EXPECT_EQ(state.faults, 0u);
}

// A second probe that is inactive (at the same place as the first: it would touch the same elements) or active but
// away from the body changes nothing: the state and the first probe's force are bit-identical to the one-probe step,
// whichever slot the first probe takes; the other probe reports nothing.
TEST(IntestineModelTest, AnIdleSecondProbeLeavesTheStepBitIdentical) {
  const IntestineModel model(IntestineParams{});
  IntestineState one(model, 7), idle_second(model, 7), away_first(model, 7);
  StepReport r1, r2, r3;
  int touching = 0;
  for (int s = 0; s < 800; ++s) {
    const Probe probe = test::scripted_probe(0.2 + s * 1e-3);
    Probe idle = probe;
    idle.active = false;
    Probe away = probe;
    away.active = true;
    away.center = Eigen::Vector3d(0, 0, 5);
    const Probe pair_idle[2] = {probe, idle};
    const Probe pair_away[2] = {away, probe};
    step(model, one, probe, 1e-3, r1);
    step(model, idle_second, pair_idle, 2, 1e-3, r2);
    step(model, away_first, pair_away, 2, 1e-3, r3);
    ASSERT_EQ(r2.probes[0].force, r1.probe_force) << "step " << s;
    ASSERT_EQ(r2.probe_force, r1.probe_force) << "step " << s;
    ASSERT_EQ(r3.probes[1].force, r1.probe_force) << "step " << s;
    ASSERT_EQ(r3.probes[1].contacts, r1.probe_contacts) << "step " << s;
    ASSERT_EQ(r2.probes[1].contacts, 0) << "step " << s;
    ASSERT_EQ(r2.probes[1].force, Eigen::Vector3d::Zero()) << "step " << s;
    ASSERT_EQ(r3.probes[0].contacts, 0) << "step " << s;
    ASSERT_EQ(r3.probe_force, Eigen::Vector3d::Zero()) << "step " << s;  // probe 0's, the one away
    touching += r1.probe_contacts > 0;
  }
  EXPECT_GT(touching, 100);  // the run did press the body
  EXPECT_EQ(r2.probe_count, 2);
  EXPECT_TRUE(same_state(one, idle_second));
  EXPECT_TRUE(same_state(one, away_first));
}

// Two probes pressing the intestine at two places (different depths): each gets the force of its own contacts, the
// one-probe force of the same press (1e-12: the contacts are found at the positions on entry), pointing away from the
// body; both push the body at once, and go on being pushed back while they hold (the body bounces and slides under
// them: within 45 degrees of the outward radial).
TEST(IntestineModelTest, TwoProbesPressingApartEachGetTheirOwnForce) {
  IntestineParams p = still_params();
  const IntestineModel model(p);
  Eigen::Vector3d out_a, out_b;
  const Probe a = pressing(model, 20, 0.008, out_a);
  const Probe b = pressing(model, 70, 0.004, out_b);
  StepReport ra, rb, r;
  IntestineState alone_a(model), alone_b(model), both(model);
  step(model, alone_a, a, 1e-3, ra);
  step(model, alone_b, b, 1e-3, rb);
  const Probe probes[2] = {a, b};
  step(model, both, probes, 2, 1e-3, r);
  ASSERT_EQ(r.status, StepStatus::kOk);
  ASSERT_GE(ra.probe_contacts, 1);
  ASSERT_GE(rb.probe_contacts, 1);
  EXPECT_EQ(r.probes[0].contacts, ra.probe_contacts);
  EXPECT_EQ(r.probes[1].contacts, rb.probe_contacts);
  EXPECT_LE((r.probes[0].force - ra.probe_force).norm(), 1e-12);
  EXPECT_LE((r.probes[1].force - rb.probe_force).norm(), 1e-12);
  EXPECT_GT(r.probes[0].force.norm(), 1.5 * r.probes[1].force.norm());  // deeper, more force: not one shared value
  // The body moved at both places, as far as each alone moved it there.
  const double moved_a = (both.x.col(20) - model.rest().col(20)).dot(-out_a);
  const double moved_b = (both.x.col(70) - model.rest().col(70)).dot(-out_b);
  EXPECT_GT(moved_a, 0);
  EXPECT_GT(moved_b, 0);
  EXPECT_NEAR(moved_a, (alone_a.x.col(20) - model.rest().col(20)).dot(-out_a), 1e-3 * moved_a);
  EXPECT_NEAR(moved_b, (alone_b.x.col(70) - model.rest().col(70)).dot(-out_b), 1e-3 * moved_b);
  // Held for 0.2 s: each probe keeps (nearly always) touching and its force points outwards (away from the body at
  // its place).
  int touching[2] = {0, 0};
  for (int s = 0; s < 200; ++s) {
    step(model, both, probes, 2, 1e-3, r);
    ASSERT_EQ(r.status, StepStatus::kOk);
    for (int i = 0; i < 2; ++i) {
      const ProbeReport& pr = r.probes[static_cast<std::size_t>(i)];
      const Eigen::Vector3d& out = i == 0 ? out_a : out_b;
      if (pr.contacts == 0) continue;
      ++touching[i];
      ASSERT_GT(pr.force.dot(out), 0.7 * pr.force.norm()) << "probe " << i << " step " << s;
    }
  }
  EXPECT_GE(touching[0], 180);
  EXPECT_GE(touching[1], 180);
}

// Deep presses: each probe's force is clamped to its own limit (a limit not > 0 takes params().probe_force_limit).
TEST(IntestineModelTest, EachProbeIsClampedToItsOwnLimit) {
  IntestineParams p = still_params();
  const IntestineModel model(p);
  IntestineState state(model);
  Eigen::Vector3d out;
  const double deep = p.intestine_radius + 0.005 - 0.002;  // the centre 2 mm off the intestine's axis
  Probe probes[3] = {pressing(model, 20, deep, out), pressing(model, 45, deep, out), pressing(model, 70, deep, out)};
  probes[0].force_limit = 2.0;
  probes[1].force_limit = 5.0;
  probes[2].force_limit = 0;  // the model's 8 N
  StepReport r;
  step(model, state, probes, 3, 1e-3, r);
  ASSERT_EQ(r.status, StepStatus::kOk);
  const double limits[3] = {2.0, 5.0, p.probe_force_limit};
  for (int i = 0; i < 3; ++i) {
    const ProbeReport& pr = r.probes[static_cast<std::size_t>(i)];
    ASSERT_GT(pr.force_raw, limits[i]) << "probe " << i << " presses too little to test its clamp";
    EXPECT_TRUE(pr.saturated) << "probe " << i;
    EXPECT_NEAR(pr.force.norm(), limits[i], 1e-9) << "probe " << i;
  }
  EXPECT_EQ(r.probe_force, r.probes[0].force);
  EXPECT_EQ(r.probe_saturated, true);
  EXPECT_EQ(r.probe_force_raw, r.probes[0].force_raw);
}

// probe_capacity is per probe: two deep probes each keep `capacity` contacts and count their own overflow.
TEST(IntestineModelTest, EachProbeHasItsOwnContactCapacity) {
  IntestineParams p = still_params();
  p.probe_capacity = 2;
  const IntestineModel model(p);
  Eigen::Vector3d out;
  const double deep = p.intestine_radius + 0.005 - 0.002;
  const Probe probes[2] = {pressing(model, 20, deep, out), pressing(model, 70, deep, out)};
  IntestineState alone(model), both(model);
  StepReport ra, r;
  step(model, alone, probes[1], 1e-3, ra);
  ASSERT_GT(ra.probe_overflow, 0) << "the probe touches too few elements to test the capacity";
  step(model, both, probes, 2, 1e-3, r);
  ASSERT_EQ(r.status, StepStatus::kOk);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(r.probes[static_cast<std::size_t>(i)].contacts, 2) << "probe " << i;
    EXPECT_GT(r.probes[static_cast<std::size_t>(i)].overflow, 0) << "probe " << i;
  }
  EXPECT_EQ(r.probes[1].overflow, ra.probe_overflow);
  EXPECT_EQ(r.probes[1].force, ra.probe_force);
}

// A step refused for a non-finite result (an absurdly long explicit step: the pressed nodes fly off to infinity)
// sends no probe any force, though every probe touched the body and had a finite force before the integration.
TEST(IntestineModelTest, ARefusedStepZeroesEveryProbeForce) {
  IntestineParams p = still_params();
  p.integrator = Integrator::kSymplecticEuler;
  const IntestineModel model(p);
  IntestineState state(model);
  Eigen::Vector3d out;
  const double deep = p.intestine_radius + 0.005 - 0.002;
  const Probe probes[2] = {pressing(model, 20, deep, out), pressing(model, 70, deep, out)};
  StepReport r;
  step(model, state, probes, 2, 1e300, r);
  ASSERT_EQ(r.status, StepStatus::kNonFinite);
  EXPECT_EQ(state.x, model.rest());
  for (int i = 0; i < 2; ++i) {
    const ProbeReport& pr = r.probes[static_cast<std::size_t>(i)];
    EXPECT_GT(pr.contacts, 0) << "probe " << i;
    EXPECT_TRUE(std::isfinite(pr.force_raw) && pr.force_raw > 0) << "probe " << i;
    EXPECT_EQ(pr.force, Eigen::Vector3d::Zero()) << "probe " << i;
  }
  EXPECT_EQ(r.probe_force, Eigen::Vector3d::Zero());
}

TEST(IntestineModelTest, ProbeCountOutOfRangeIsBadInput) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model);
  const Eigen::Matrix3Xd before = state.x;
  Probe probes[kMaxProbes + 1];
  StepReport report;
  step(model, state, probes, kMaxProbes + 1, 1e-3, report);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  step(model, state, probes, -1, 1e-3, report);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  step(model, state, nullptr, 1, 1e-3, report);
  EXPECT_EQ(report.status, StepStatus::kBadInput);
  EXPECT_EQ(state.x, before);
  EXPECT_EQ(state.faults, 3u);
  EXPECT_EQ(state.steps, 0u);
  // No probe at all: the body steps (gravity), nothing is reported for any probe.
  step(model, state, nullptr, 0, 1e-3, report);
  EXPECT_EQ(report.status, StepStatus::kOk);
  EXPECT_EQ(report.probe_count, 0);
  EXPECT_EQ(report.probe_force, Eigen::Vector3d::Zero());
  EXPECT_NE(state.x, before);
  EXPECT_EQ(state.steps, 1u);
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
  EXPECT_TRUE(same_state(a, b));
  EXPECT_EQ(ra.probe_force, rb.probe_force);
  // reset() brings back the initial state: the same run again is identical too.
  b.reset(model, 7);
  for (int s = 0; s < 800; ++s) step(model, b, test::scripted_probe(0.2 + s * 1e-3), 1e-3, rb);
  EXPECT_TRUE(same_state(a, b));
}

TEST(IntestineModelTest, ProbeForcePushesTheToolOutAndIsClamped) {
  IntestineParams p = still_params();
  const IntestineModel model(p);
  IntestineState state(model);
  StepReport report;
  // The probe 1 cm inside the intestine's surface at the middle of segment 40, from outside the cylinder.
  Eigen::Vector3d out;
  Probe probe = pressing(model, 40, 0.01, out);
  const Eigen::Vector3d mid = 0.5 * (model.rest().col(40) + model.rest().col(41));
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
