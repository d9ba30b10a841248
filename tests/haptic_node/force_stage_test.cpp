// The force stage (haptic_node/force_stage.h): the passivity observer sees an environment that adds
// energy and the controller keeps the observed energy >= 0; the contact damper adds no drag while sliding, never pulls
// the tool in and starts from zero at contact onset; the force sent stays finite and within the device limit, with no
// allocation; and the shipped liver, closed through a simulated device in this process (deterministic, no DDS),
// comes to rest with the hand's force at the corners of the mass / damping / hand-force grid.
#include <gtest/gtest.h>

#include <iostream>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "force_stage.h"
#include "organ.h"
#include "scene/scene.h"
#include "support/alloc_counter.h"
#include "tool/tool.h"

using namespace surgsim::tool;
using namespace surgsim::contact;
using namespace surgsim::scene;

namespace surgsim {
namespace {

HapticSpec spec(bool passivity, double coupling_damping, double max_damping = 30.0) {
  HapticSpec h;
  h.passivity = passivity;
  h.coupling_damping = coupling_damping;
  h.passivity_max_damping = max_damping;
  return h;
}

ToolGeometry tip_at(const Eigen::Vector3d& p) {
  ToolGeometry g{};
  g.trocar = p + Eigen::Vector3d(0, 0, 0.2);
  g.direction = Eigen::Vector3d(0, 0, -1);
  g.tip = p;
  g.point_count = 1;
  g.points[0] = p;
  return g;
}

// A 1-D device along -z (x = depth, positive into the organ) pushed by a constant hand force, and an ACTIVE
// environment: a wall at depth 0 whose spring reads the position `delay` ticks late (what a lagging contact model, or
// a contact re-anchored behind the tool, does). The stage sees the device's current tip and the wall's force.
struct DelayedWallRun {
  double energy_min = 0;       // the observer's lowest energy (after the controller)
  double energy_final = 0;
  double pc_dissipated = 0;
  std::uint64_t pc_ticks = 0;
  double device_energy_max_late = 0;  // J, kinetic + wall and hand potential energy, largest over the last second
  double device_energy_start = 0;     // the same, largest over the first second
  bool finite = true;
  double force_max = 0;
};

DelayedWallRun run_delayed_wall(const HapticSpec& h, int delay, double seconds) {
  const double dt = 1e-3, m = 0.05, b = 0.1, k_wall = 800, hand = 2.0, limit = 8.0;
  ForceStage stage(h, limit);
  std::vector<double> history(static_cast<std::size_t>(delay) + 1, -0.005);
  double x = -0.005, v = 0;  // start 5 mm above the wall
  Eigen::Vector3d sent = Eigen::Vector3d::Zero();
  DelayedWallRun r;
  const int steps = static_cast<int>(std::lround(seconds / dt));
  for (int k = 0; k < steps; ++k) {
    // Device: the force sent last tick, semi-implicit Euler.
    const double f_axis = -sent.z();  // the axis is -z
    v += (hand - b * v + f_axis) / m * dt;
    x += v * dt;
    // Environment: a spring on the delayed depth, pushing the tool out (+z).
    std::rotate(history.begin(), history.begin() + 1, history.end());
    history.back() = x;
    const double depth_late = history.front();
    ContactTick out;
    out.force = Eigen::Vector3d(0, 0, k_wall * std::max(0.0, depth_late));
    out.device_force = out.force;
    if (out.device_force.norm() > limit) out.device_force *= limit / out.device_force.norm();
    stage.apply(tip_at(Eigen::Vector3d(0, 0, -x)), dt, out);
    sent = out.device_force;
    r.finite = r.finite && sent.allFinite();
    r.force_max = std::max(r.force_max, sent.norm());
    const double e_dev = 0.5 * m * v * v + 0.5 * k_wall * std::max(0.0, x) * std::max(0.0, x) - hand * x;
    if (k * dt < 1.0) r.device_energy_start = std::max(r.device_energy_start, e_dev);
    if (k * dt >= seconds - 1.0) r.device_energy_max_late = std::max(r.device_energy_max_late, e_dev);
  }
  r.energy_min = stage.energy_min();
  r.energy_final = stage.energy();
  r.pc_dissipated = stage.pc_dissipated();
  r.pc_ticks = stage.pc_ticks();
  return r;
}

TEST(ForceStage, ObserverSeesTheDelayedWallAddEnergyAndTheControllerRemovesIt) {
  // Without the controller (and without the coupling damper): the environment hands out energy, the observed energy
  // goes well below zero and the device's oscillation grows.
  const DelayedWallRun off = run_delayed_wall(spec(false, 0.0), 4, 6.0);
  EXPECT_LT(off.energy_min, -0.01) << "the delayed wall is active: the observer must see energy going negative";
  EXPECT_GT(off.device_energy_max_late, off.device_energy_start) << "without the controller the oscillation grows";
  EXPECT_EQ(off.pc_ticks, 0u);
  std::cout << "[delayed wall] observer energy min without the controller " << off.energy_min << " J\n";

  // With the controller: the observed energy never goes below zero (up to rounding), the controller did the work,
  // and what is left of the oscillation is a small fraction of the growth without it (the controller makes the port
  // passive; it does not add damping beyond the deficit, which is the coupling damper's job).
  const DelayedWallRun on = run_delayed_wall(spec(true, 0.0, 1000.0), 4, 6.0);
  EXPECT_GE(on.energy_min, -1e-9) << "the environment added energy through the controller";
  std::cout << "[delayed wall] observer energy min with the controller " << on.energy_min << " J\n";
  EXPECT_GT(on.pc_ticks, 0u);
  EXPECT_GT(on.pc_dissipated, 0.0);
  EXPECT_LT(on.device_energy_max_late, 0.1 * off.device_energy_max_late);
  EXPECT_TRUE(on.finite);
  EXPECT_LE(on.force_max, 8.0 + 1e-12);
}

TEST(ForceStage, CappedControllerCarriesTheDeficitAndStaysWithinTheLimit) {
  // A capped damping (the default 30 N s/m) may leave part of a deficit for the next ticks: the energy dips at most
  // briefly and the force sent never leaves the device limit.
  const DelayedWallRun on = run_delayed_wall(spec(true, 0.0, 30.0), 4, 6.0);
  const DelayedWallRun off = run_delayed_wall(spec(false, 0.0), 4, 6.0);
  EXPECT_GT(on.energy_min, 0.05 * off.energy_min);
  EXPECT_GE(on.energy_final, 0.0);
  EXPECT_TRUE(on.finite);
  EXPECT_LE(on.force_max, 8.0 + 1e-12);
}

TEST(ForceStage, PassiveSpringIsLeftAlone) {
  // A spring without delay is passive: the controller never acts and the force is the spring's.
  ForceStage stage(spec(true, 0.0), 8.0);
  const double dt = 1e-3;
  for (int k = 0; k < 2000; ++k) {
    const double depth = 0.01 * (1.0 - std::cos(2 * M_PI * 2.0 * k * dt));  // from rest at the surface
    ContactTick out;
    out.device_force = Eigen::Vector3d(0, 0, 300 * depth);
    const Eigen::Vector3d before = out.device_force;
    stage.apply(tip_at(Eigen::Vector3d(0, 0, -depth)), dt, out);
    ASSERT_EQ(out.device_force, before) << "tick " << k;
  }
  EXPECT_EQ(stage.pc_ticks(), 0u);
  EXPECT_GE(stage.energy_min(), 0.0);
}

TEST(ForceStage, CouplingDamperNoDragWhenSlidingNeverPullsAndStartsFromZero) {
  ForceStage stage(spec(true, 5.0), 8.0);
  const double dt = 1e-3;
  // Sliding at constant depth along x: v . n = 0, the force is unchanged (no tangential drag).
  ContactTick out;
  for (int k = 0; k < 100; ++k) {
    out = ContactTick{};
    out.device_force = Eigen::Vector3d(0, 0, 1.0);
    stage.apply(tip_at(Eigen::Vector3d(0.1 * k * dt, 0, -0.01)), dt, out);
    EXPECT_NEAR((out.device_force - Eigen::Vector3d(0, 0, 1.0)).norm(), 0.0, 1e-12) << "tick " << k;
  }
  // Pressing in (tip moving down at 0.2 m/s): the damper pushes out, by at most 35 % of the contact force (so that
  // a 0.1 m/s onset stays continuous).
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(0, 0, 0.1);
  stage.apply(tip_at(Eigen::Vector3d(0.01, 0, -0.0102)), dt, out);
  EXPECT_NEAR(out.device_force.z(), 0.135, 1e-12);
  // Pulling out fast: the damper lowers the push-back but never below zero (never pulls the tool in).
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(0, 0, 0.3);
  stage.apply(tip_at(Eigen::Vector3d(0.01, 0, -0.0002)), dt, out);
  EXPECT_GE(out.device_force.z(), 0.0);
  EXPECT_LE(out.device_force.z(), 0.3);
  // No contact force, no damper force, whatever the speed (contact onset starts from zero). A stage of its own: the
  // synthetic pull-out above gave energy back, which the controller would rightly dissipate on the next tick.
  ForceStage fresh(spec(false, 5.0), 8.0);
  out = ContactTick{};
  fresh.apply(tip_at(Eigen::Vector3d(0.01, 0, -0.01)), dt, out);
  out = ContactTick{};
  fresh.apply(tip_at(Eigen::Vector3d(0.01, 0, -0.05)), dt, out);
  EXPECT_TRUE(out.device_force.isZero(0));
}

TEST(ForceStage, FiniteWithinTheLimitAndNoJumpAfterLostInput) {
  ForceStage stage(spec(true, 3.0, 1000.0), 2.0);
  const double dt = 1e-3;
  ContactTick out;
  out.device_force = Eigen::Vector3d(0, 0, 1.9);
  stage.apply(tip_at(Eigen::Vector3d(0, 0, 0)), dt, out);
  // A large step into the organ: damper + limit.
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(0, 0, 1.9);
  stage.apply(tip_at(Eigen::Vector3d(0, 0, -0.05)), dt, out);
  EXPECT_LE(out.device_force.norm(), 2.0 + 1e-12);
  EXPECT_TRUE(out.saturated);
  // A non-finite force or pose in: a finite force out.
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 1);
  stage.apply(tip_at(Eigen::Vector3d(0, 0, -0.05)), dt, out);
  EXPECT_TRUE(out.device_force.allFinite());
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(0, 0, 1);
  stage.apply(tip_at(Eigen::Vector3d(std::numeric_limits<double>::infinity(), 0, 0)), dt, out);
  EXPECT_TRUE(out.device_force.allFinite());
  // Input lost, then back 10 cm away: the jump is not a velocity (no damper force on the first tick back).
  out = ContactTick{};
  stage.apply(nullptr, dt, out);
  EXPECT_TRUE(out.device_force.isZero(0));
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(0, 0, 0.5);
  stage.apply(tip_at(Eigen::Vector3d(0, 0, -0.15)), dt, out);
  EXPECT_EQ(out.device_force, Eigen::Vector3d(0, 0, 0.5));
}

TEST(ForceStage, ApplyAllocatesNothing) {
  ForceStage stage(spec(true, 3.0), 8.0);
  long allocations = 0;
  {
    test::AllocationCounter counter;
    for (int k = 0; k < 1000; ++k) {
      ContactTick out;
      out.device_force = Eigen::Vector3d(0, 0, 1.0 + 0.5 * std::sin(0.05 * k));
      stage.apply(tip_at(Eigen::Vector3d(0, 0, -0.01 - 0.005 * std::sin(0.03 * k))), 1e-3, out);
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
}

// The shipped liver closed through a simulated 1-D device along the shaft, in this process: m x'' = F_hand - b x' +
// F . axis at 1 kHz (semi-implicit Euler), the force one tick late (what the device gets over DDS: the previous
// tick's), the tool starting 5 mm above the top. Deterministic; the DDS run is tests/integration/
// device_physical_test.cpp.
struct LiverRun {
  double p2p_last = 0;       // m, position peak-to-peak over the last 0.5 s
  double force_final = 0;    // N, mean push-back over the last 0.5 s
  double energy_min = 0;     // J, the observer's lowest energy
};

LiverRun run_liver(const Scene& scene, double m, double b, double hand, double seconds) {
  const double dt = 1e-3;
  const auto organ = make_haptic_organ(scene, SURGSIM_TEST_CACHE_DIR, static_cast<std::uint64_t>(seconds / dt) + 2,
                                       nullptr);
  ForceStage stage(scene.haptic, scene.tools[0].force_limit);
  Pose5 pose;
  pose.insertion = 0.155;
  pose.jaw = 0.5;
  const Eigen::Vector3d axis = tool_geometry(scene.tools[0], pose).direction;
  double x = pose.insertion, v = 0;
  Eigen::Vector3d sent = Eigen::Vector3d::Zero();
  const int steps = static_cast<int>(std::lround(seconds / dt));
  double x_min = 1e9, x_max = -1e9, f_sum = 0;
  int n = 0;
  for (int k = 0; k < steps; ++k) {
    v += (hand - b * v + sent.dot(axis)) / m * dt;
    x += v * dt;
    pose.insertion = x;
    const ToolGeometry tool = tool_geometry(scene.tools[0], pose);
    ContactTick out;
    organ->step(&tool, pose.jaw, dt, out);
    stage.apply(tool, dt, out);
    sent = out.device_force;
    if (k * dt >= seconds - 0.5) {
      x_min = std::min(x_min, x);
      x_max = std::max(x_max, x);
      f_sum += -sent.dot(axis);
      ++n;
    }
  }
  return {x_max - x_min, f_sum / n, stage.energy_min()};
}

TEST(ForceStage, ShippedLiverClosedLoopComesToRestWithTheHandsForce) {
  Scene scene = load_scene(resolve_scene_path("liver"));
  scene.haptic.rate_hz = 1000;
  struct Case {
    double m, b, hand;
  };
  for (const Case c : {Case{0.05, 0.1, 3.0}, Case{0.2, 1.0, 0.5}, Case{0.05, 1.0, 0.5}, Case{0.2, 0.1, 3.0},
                       Case{0.1, 0.5, 1.5}}) {
    const LiverRun r = run_liver(scene, c.m, c.b, c.hand, 5.0);
    SCOPED_TRACE(::testing::Message() << "m " << c.m << " kg, b " << c.b << " N s/m, hand " << c.hand << " N");
    EXPECT_LT(r.p2p_last, 0.5e-3) << "still oscillating";
    EXPECT_NEAR(r.force_final, c.hand, 0.1 * c.hand);
    EXPECT_GE(r.energy_min, -1e-6);
  }
}

}  // namespace
}  // namespace surgsim
