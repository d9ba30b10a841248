// The force stage (haptic_node/force_stage.h): the passivity observer counts the force the device held over each
// interval, so it sees the energy a sample-and-hold makes (a one-tick-delayed stiff wall) as well as a delayed
// environment's, and the controller takes it out until the device comes to rest; the contact damper adds no drag while
// sliding, never pulls the tool in, starts from zero at contact onset and, when a scripted tool stops dead, fades
// within 5 % of the force a tick; the force sent stays finite and within the device limit, with no allocation; and the
// shipped liver, closed through a simulated device in this process (deterministic, no DDS), comes to rest with the
// hand's force at the corners of the mass / damping / hand-force grid.
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

// A 1-D device along -z (x = depth, positive into the organ): a mass m with its own damping b, pushed by a constant
// hand force, holding over each tick the force the stage sent last tick (a sample-and-hold, as a device's amplifier
// holds its command) and moving CONTINUOUSLY under it: m x'' = hand - b x' + F_held, integrated exactly over the tick
// (an integrator at the tick, such as semi-implicit Euler, would take out by itself much of the energy the hold makes).
// The environment: a wall at depth 0 whose spring reads the depth `delay` ticks late (0: the current one, so the force
// reaches the device one tick after the pose it answers, through the hold alone; more: a lagging contact model, or a
// contact re-anchored behind the tool). The stage sees the device's current tip and the wall's force.
struct WallRun {
  double energy_min = 0;  // J, the observer's lowest energy
  double energy_final = 0;
  double pc_dissipated = 0;
  std::uint64_t pc_ticks = 0;
  double amplitude_early = 0;  // m, largest |x - x_rest| over [1 s, 2 s)
  double amplitude_late = 0;   // m, the same over the last second
  bool finite = true;
  double force_max = 0;
};

WallRun run_wall(const HapticSpec& h, int delay, double k_wall, double seconds) {
  const double dt = 1e-3, m = 0.05, b = 0.1, hand = 2.0, limit = 8.0;
  const double x_rest = hand / k_wall;  // within the device limit: the wall holds the hand
  ForceStage stage(h, limit);
  std::vector<double> history(static_cast<std::size_t>(delay) + 1, -0.005);
  double x = -0.005, v = 0;  // start 5 mm above the wall, at rest
  Eigen::Vector3d held = Eigen::Vector3d::Zero();
  WallRun r;
  const double decay = std::exp(-b / m * dt);
  const int steps = static_cast<int>(std::lround(seconds / dt));
  for (int k = 0; k < steps; ++k) {
    // Device: the exact motion over the tick under the force held (constant over it), from v' = (F - b v) / m.
    const double force = hand - held.z();  // the axis is -z
    const double v_end = force / b;        // the velocity this force and damping tend to
    x += v_end * dt + (v - v_end) * (1 - decay) * m / b;
    v = v_end + (v - v_end) * decay;
    // Environment: a spring on the delayed depth, pushing the tool out (+z).
    std::rotate(history.begin(), history.begin() + 1, history.end());
    history.back() = x;
    ContactTick out;
    out.force = Eigen::Vector3d(0, 0, k_wall * std::max(0.0, history.front()));
    out.device_force = out.force;
    if (out.device_force.norm() > limit) out.device_force *= limit / out.device_force.norm();
    stage.apply(tip_at(Eigen::Vector3d(0, 0, -x)), dt, out);
    held = out.device_force;
    r.finite = r.finite && held.allFinite();
    r.force_max = std::max(r.force_max, held.norm());
    const double t = k * dt;
    if (t >= 1.0 && t < 2.0) r.amplitude_early = std::max(r.amplitude_early, std::abs(x - x_rest));
    if (t >= seconds - 1.0) r.amplitude_late = std::max(r.amplitude_late, std::abs(x - x_rest));
  }
  r.energy_min = stage.energy_min();
  r.energy_final = stage.energy();
  r.pc_dissipated = stage.pc_dissipated();
  r.pc_ticks = stage.pc_ticks();
  return r;
}

TEST(ForceStage, ObserverSeesTheEnergyOfTheSampleAndHold) {
  // A stiff wall (3000 N/m) at 1 kHz whose force reaches the light, lightly damped device one tick late, through the
  // hold alone: the hold hands out about K dx^2 / 2 a tick, more than the device's 0.1 N s/m takes (Colgate: b > K T
  // / 2 = 1.5 N s/m is needed), and the tool bounces on the wall for good. Without the controller (and without the
  // coupling damper), the observer must see that energy: it goes well below zero.
  const WallRun off = run_wall(spec(false, 0.0), 0, 3000, 6.0);
  std::cout << "[one-tick wall] without the controller: observer energy min " << off.energy_min << " J, amplitude "
            << 1e3 * off.amplitude_early << " mm at 1-2 s, " << 1e3 * off.amplitude_late << " mm at the end\n";
  EXPECT_LT(off.energy_min, -0.1) << "the hold made the wall active: the observer must see energy going negative";
  EXPECT_GT(off.amplitude_late, 5e-3) << "without the controller the tool keeps bouncing";
  EXPECT_GT(off.amplitude_late, 0.5 * off.amplitude_early) << "... and the bounce does not die out";
  EXPECT_EQ(off.pc_ticks, 0u);

  // With the controller at its default cap (30 N s/m): it acted, dissipated energy, and the tool comes to rest on the
  // wall; the observed energy dips below zero by at most a tick's worth (the deficit is seen after the interval).
  const WallRun on = run_wall(spec(true, 0.0, 30.0), 0, 3000, 6.0);
  std::cout << "[one-tick wall] with the controller: observer energy min " << on.energy_min << " J, amplitude "
            << 1e3 * on.amplitude_late << " mm at the end, " << on.pc_ticks << " ticks acted, " << on.pc_dissipated
            << " J dissipated\n";
  EXPECT_GT(on.pc_ticks, 0u);
  EXPECT_GT(on.pc_dissipated, 0.0);
  EXPECT_GT(on.energy_min, 1e-3 * off.energy_min);
  // The controller makes the port passive, it adds no damping of its own: the device's 0.1 N s/m brings it to rest.
  EXPECT_LT(on.amplitude_late, 0.01 * off.amplitude_late) << "with the controller the tool comes to rest";
  EXPECT_LT(on.amplitude_late, 0.5 * on.amplitude_early) << "... and the motion left dies out";
  EXPECT_TRUE(on.finite);
  EXPECT_LE(on.force_max, 8.0 + 1e-12);
}

TEST(ForceStage, CappedControllerTakesUpALongerDelayAndStaysWithinTheLimit) {
  // A wall 4 ticks late (plus the hold): far more active. The capped controller carries what it cannot dissipate in
  // one tick to the next ones; the tool still comes to rest and the force sent never leaves the device limit.
  const WallRun off = run_wall(spec(false, 0.0), 4, 800, 6.0);
  const WallRun on = run_wall(spec(true, 0.0, 30.0), 4, 800, 6.0);
  std::cout << "[4-tick wall] observer energy min " << off.energy_min << " J without the controller, " << on.energy_min
            << " J with it\n";
  EXPECT_LT(off.energy_min, -1.0);
  EXPECT_GT(off.amplitude_late, 5e-3);
  EXPECT_GT(on.energy_min, 0.01 * off.energy_min);
  EXPECT_GT(on.pc_ticks, 0u);
  EXPECT_LT(on.amplitude_late, 0.01 * off.amplitude_late);
  EXPECT_LT(on.amplitude_late, 0.5 * on.amplitude_early);
  EXPECT_TRUE(on.finite);
  EXPECT_LE(on.force_max, 8.0 + 1e-12);
}

TEST(ForceStage, ObserverCountsTheForceTheDeviceHeld) {
  // A spring K pressed and released along a scripted path (4 cycles of 1 cm at 2 Hz, ending where it started), the
  // force of tick k held over the motion to tick k + 1. The work the held force does on the tool is, summed by parts,
  //     sum_k K d_{k-1} (d_k - d_{k-1}) = K d_N^2 / 2 - K / 2 sum_k (d_k - d_{k-1})^2
  // (d_0 = 0): the spring's energy at the end less K dx^2 / 2 a tick, the energy the hold makes. The observer must
  // report exactly that (a continuous-time observer, pairing each force with the motion that follows the pose it was
  // computed from, reports the spring's energy PLUS K dx^2 / 2 a tick: it sees a passive element).
  const double dt = 1e-3, K = 300;
  const auto depth = [&](int k) { return 0.01 * (1.0 - std::cos(2 * M_PI * 2.0 * k * dt)); };
  const int ticks = 2000;
  ForceStage off(spec(false, 0.0), 8.0);
  ForceStage on(spec(true, 0.0), 8.0);
  double hold_energy = 0;  // K / 2 sum dx^2
  for (int k = 0; k <= ticks; ++k) {
    if (k > 0) hold_energy += 0.5 * K * (depth(k) - depth(k - 1)) * (depth(k) - depth(k - 1));
    ContactTick out;
    out.device_force = Eigen::Vector3d(0, 0, K * depth(k));
    const Eigen::Vector3d spring = out.device_force;
    off.apply(tip_at(Eigen::Vector3d(0, 0, -depth(k))), dt, out);
    ASSERT_EQ(out.device_force, spring) << "tick " << k << ": without the controller the force is the spring's";
    ContactTick same;
    same.device_force = spring;
    on.apply(tip_at(Eigen::Vector3d(0, 0, -depth(k))), dt, same);
  }
  const double expected = 0.5 * K * depth(ticks) * depth(ticks) - hold_energy;
  std::cout << "[sampled spring] observer " << off.energy() << " J, the hold's energy " << hold_energy << " J\n";
  EXPECT_GT(hold_energy, 1e-3);
  EXPECT_NEAR(off.energy(), expected, 1e-9 * hold_energy + 1e-15);
  EXPECT_LT(off.energy_min(), -0.5 * hold_energy);
  // With the controller the deficit is taken out as it comes: the controller acted, and the observed energy stays
  // within a small share of the hold's.
  EXPECT_GT(on.pc_ticks(), 0u);
  EXPECT_GT(on.pc_dissipated(), 0.0);
  EXPECT_GT(on.energy_min(), -0.05 * hold_energy);
}

TEST(ForceStage, DeadStopStepsTheForceByAtMostFivePercentATick) {
  // A scripted tool (no mass) comes down at 0.1 m/s onto a 300 N/m spring, 3 mm in, and stops dead. The coupling
  // damper (3 N s/m, the default) pushes back 0.3 N on top of the spring's 0.9 N while it moves; a damper of B v
  // would vanish in the tick the tool stops (a 33 % step). Each tick's force step must stay within 5 % of the force
  // held at rest, once stopped as on the way in (haptic_signal_bench's "slab approach stops dead" on the slab).
  ForceStage stage(spec(true, 3.0), 8.0);
  const double dt = 1e-3, K = 300, rest = K * 0.003;
  double prev = 0, step_moving = 0, step_stopped = 0, damper_at_stop = 0;
  for (int k = 0; k <= 150; ++k) {
    const double d = std::min(0.003, -0.002 + 1e-4 * k);  // 0.1 mm a tick from 2 mm above; tick 51 is the first at rest
    ContactTick out;
    out.device_force = Eigen::Vector3d(0, 0, K * std::max(0.0, d));
    stage.apply(tip_at(Eigen::Vector3d(0, 0, -d)), dt, out);
    const double held = out.device_force.norm();
    if (k == 50) damper_at_stop = held - K * d;
    double& worst = k <= 50 ? step_moving : step_stopped;
    worst = std::max(worst, std::abs(held - prev) / rest);
    prev = held;
  }
  std::cout << "[dead stop] damper at the stop " << damper_at_stop << " N, largest step " << 100 * step_moving
            << " % moving, " << 100 * step_stopped << " % stopped (of the force at rest)\n";
  EXPECT_GT(damper_at_stop, 0.25) << "the damper pushed back while the tool moved in";
  EXPECT_LE(step_stopped, 0.05);
  EXPECT_LE(step_moving, 0.05);
  EXPECT_NEAR(prev, rest, 1e-12) << "at rest the damper is gone";
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
  // a 0.1 m/s onset stays continuous), and it gets there by at most 4 % of the contact force a tick.
  for (int k = 1; k <= 10; ++k) {
    out = ContactTick{};
    out.device_force = Eigen::Vector3d(0, 0, 1.0);
    stage.apply(tip_at(Eigen::Vector3d(0.01, 0, -0.01 - 0.0002 * k)), dt, out);
    EXPECT_NEAR(out.device_force.z(), 1.0 + std::min(0.04 * k, 0.35), 1e-12) << "tick " << k;
  }
  // Pulling out fast (1 m/s, without the controller, whose own damper would rightly resist the energy handed back):
  // the damper lowers the push-back, to 65 % of the contact force at most, never below zero (never pulls the tool in).
  ForceStage pull(spec(false, 5.0), 8.0);
  for (int k = 0; k <= 12; ++k) {
    out = ContactTick{};
    out.device_force = Eigen::Vector3d(0, 0, 0.3);
    pull.apply(tip_at(Eigen::Vector3d(0.01, 0, -0.02 + 0.001 * k)), dt, out);
    EXPECT_NEAR(out.device_force.z(), 0.3 * (1 - std::min(0.04 * k, 0.35)), 1e-12) << "tick " << k;
  }
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
  out.device_force = Eigen::Vector3d(0, 0, 1.95);
  stage.apply(tip_at(Eigen::Vector3d(0, 0, 0)), dt, out);
  // A large step into the organ: damper (its first tick's 4 %) + limit.
  out = ContactTick{};
  out.device_force = Eigen::Vector3d(0, 0, 1.95);
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
