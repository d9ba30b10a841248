// The god-object proxy and its coupling: force = k depth on a plane, the proxy never on the far side, frictionless
// slides (a plane, a finely tessellated cylinder, the inside of a dome) without ripple or drag, concave corners and a
// convex edge against their exact offset surfaces, and the closed loop with a simulated device at 1 kHz (zero-order
// hold, with and without a tick of delay): no energy given out, settling, and the bare spring as negative control.
#include "rigid/proxy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <iomanip>
#include <iostream>
#include <random>
#include <vector>

#include "rigid/rigid_shapes.h"
#include "support/alloc_counter.h"
#include "support/error_test_util.h"

namespace surgsim::rigid {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDt = 0.001;  // s, the haptic tick

// Moves the device from `from` to `to` in `ticks` steps, then holds it for `hold` ticks; returns the last force.
Eigen::Vector3d move(Proxy& proxy, const Eigen::Vector3d from, const Eigen::Vector3d& to, int ticks, int hold) {
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  for (int i = 1; i <= ticks; ++i) f = proxy.step(from + (to - from) * i / ticks, kDt);
  for (int i = 0; i < hold; ++i) f = proxy.step(to, kDt);
  return f;
}

TEST(Proxy, PushOntoAPlaneGivesStiffnessTimesDepthAlongTheNormal) {
  const RigidSurface floor(plane_patch(0.2, 0.2, 10), false, "floor");
  const ProxyParams params;
  Proxy proxy(floor, params);
  const Eigen::Vector3d above(0.013, -0.021, 0.02);
  proxy.reset(above);
  EXPECT_FALSE(proxy.in_contact());
  for (double depth : {0.0005, 0.001, 0.0015}) {
    const Eigen::Vector3d device(0.013, -0.021, params.radius - depth);
    const Eigen::Vector3d f = move(proxy, above, device, 20, 3);
    EXPECT_NEAR(f.z(), params.stiffness * depth, 1e-5) << depth;
    EXPECT_NEAR(f.head<2>().norm(), 0, 1e-9);
    EXPECT_NEAR(proxy.penetration(), depth, 1e-8);
    EXPECT_NEAR(proxy.proxy_point().z(), params.radius, 1e-8);
    EXPECT_LT((proxy.proxy_point().head<2>() - device.head<2>()).norm(), 1e-12);
    EXPECT_TRUE(proxy.in_contact());
    EXPECT_EQ(proxy.active_constraints(), 1);
    move(proxy, device, above, 5, 1);
    EXPECT_FALSE(proxy.in_contact());
    EXPECT_EQ(proxy.penetration(), 0);
  }
}

// Random device motions through organs: the tip sphere never crosses the surface (signed distance >= radius).
void expect_never_crosses(const RigidSurface& surface, const Eigen::Vector3d& start, double spread, int seed) {
  ProxyParams params;
  Proxy proxy(surface, params);
  proxy.reset(start);
  std::mt19937 rng(seed);
  std::normal_distribution<double> jitter(0, spread);
  Eigen::Vector3d device = start;
  double worst = 1;
  for (int i = 0; i < 4000; ++i) {
    device += Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
    if (i % 500 == 0) device = start;  // back out now and then
    const Eigen::Vector3d f = proxy.step(device, kDt);
    ASSERT_TRUE(f.allFinite());
    const ClosestPoint cp = surface.closest_point(proxy.proxy_point(), 0.02);
    if (cp.found) worst = std::min(worst, cp.distance - params.radius);
  }
  EXPECT_GT(worst, -1e-12) << surface.where();
}

TEST(Proxy, NeverLeavesTheFreeSide) {
  expect_never_crosses(RigidSurface(box_surface(Eigen::Vector3d(0.02, 0.015, 0.01), 3), false, "box"),
                       Eigen::Vector3d(0.0, 0.0, 0.016), 0.002, 1);
  expect_never_crosses(RigidSurface(box_surface(Eigen::Vector3d(0.02, 0.015, 0.01), 3), true, "room"),
                       Eigen::Vector3d::Zero(), 0.003, 2);
  expect_never_crosses(RigidSurface(tube_surface(0.01, 0.06, 24, 6, true), false, "rib bar"),
                       Eigen::Vector3d(0.0, 0.0135, 0), 0.002, 3);
  RibsSpec spec;
  expect_never_crosses(RigidSurface(ribs(spec), false, "ribs"), Eigen::Vector3d(0.11, 0, 0.015), 0.002, 4);
}

// A slide of the device at constant depth along a path; the figures relative to the smooth surface's normal there.
struct Slide {
  double ripple = 0;       // (max - min) / mean of the normal force
  double tangential = 0;   // max |tangential force| / mean normal force
  double mean_normal = 0;  // N
  std::vector<double> forces;
};
template <typename Path, typename Normal>
Slide slide(const RigidSurface& surface, Path path, Normal normal, int ticks) {
  Proxy proxy(surface, ProxyParams{});
  proxy.reset(path(0.0) + 0.01 * normal(path(0.0)));
  move(proxy, proxy.proxy_point(), path(0.0), 50, 10);
  Slide s;
  double lo = 1e9, hi = -1e9, sum = 0, tangential = 0;
  for (int i = 0; i <= ticks; ++i) {
    const Eigen::Vector3d device = path(static_cast<double>(i) / ticks);
    const Eigen::Vector3d f = proxy.step(device, kDt);
    const Eigen::Vector3d n = normal(device);
    const double fn = f.dot(n);
    lo = std::min(lo, fn);
    hi = std::max(hi, fn);
    sum += fn;
    tangential = std::max(tangential, (f - fn * n).norm());
    s.forces.insert(s.forces.end(), f.data(), f.data() + 3);
  }
  s.mean_normal = sum / (ticks + 1);
  s.ripple = (hi - lo) / s.mean_normal;
  s.tangential = tangential / s.mean_normal;
  return s;
}
void report(const char* what, const Slide& s) {
  std::cout << std::setprecision(3) << what << ": normal force " << s.mean_normal << " N, ripple " << 100 * s.ripple
            << " %, tangential " << 100 * s.tangential << " % of the normal\n";
}

constexpr double kDepth = 0.001;  // m past the offset surface: 2 N at k = 2000 N/m

TEST(Proxy, SlidesAlongATiltedPlaneWithoutRippleOrDrag) {
  const mesh::Placement tilt =
      mesh::Placement::from_euler_deg(Eigen::Vector3d(0.01, 0.02, 0.03), Eigen::Vector3d(25, -15, 40));
  const RigidSurface wall(placed(plane_patch(0.2, 0.2, 24), tilt), false, "wall");
  const Eigen::Vector3d n = tilt.rotation.col(2);
  const double r = ProxyParams{}.radius;
  auto path = [&](double s) {
    return tilt.to_world(Eigen::Vector3d(-0.07 + 0.14 * s, 0.05 * std::sin(6 * s), r - kDepth));
  };
  const Slide s = slide(
      wall, path, [&](const Eigen::Vector3d&) { return n; }, 1500);  // 0.1 m/s
  report("plane slide", s);
  EXPECT_NEAR(s.mean_normal, 2000 * kDepth, 1e-4);
  EXPECT_LE(s.ripple, 0.05);
  EXPECT_LE(s.tangential, 0.02);
}

TEST(Proxy, SlidesAroundAFinelyTessellatedCylinder) {
  const double radius = 0.02, r = ProxyParams{}.radius;
  const RigidSurface bar(tube_surface(radius, 0.1, 256, 8, true), false, "rib bar");
  auto path = [&](double s) {
    const double a = 2 * kPi * s;
    return Eigen::Vector3d((radius + r - kDepth) * std::cos(a), (radius + r - kDepth) * std::sin(a), 0.01 * s);
  };
  auto normal = [](const Eigen::Vector3d& p) { return Eigen::Vector3d(p.x(), p.y(), 0).normalized().eval(); };
  const Slide s = slide(bar, path, normal, 2000);  // one turn in 2 s: 0.07 m/s
  report("cylinder slide (256 segments)", s);
  EXPECT_LE(s.ripple, 0.05);
  EXPECT_LE(s.tangential, 0.02);
}

TEST(Proxy, SlidesInsideTheAbdominalWallDome) {
  const double radius = 0.15, r = ProxyParams{}.radius;
  const RigidSurface wall(ellipsoid_shell(Eigen::Vector3d::Constant(radius), 256, 128, -0.3), true, "abdominal wall");
  const double polar = 60 * kPi / 180, rho = radius - r + kDepth;
  auto path = [&](double s) {
    const double a = 2 * kPi * s;
    return Eigen::Vector3d(rho * std::sin(polar) * std::cos(a), rho * std::sin(polar) * std::sin(a),
                           rho * std::cos(polar));
  };
  auto normal = [](const Eigen::Vector3d& p) { return Eigen::Vector3d(-p.normalized()); };  // towards the centre
  const Slide s = slide(wall, path, normal, 4000);  // 0.41 m around in 4 s: 0.1 m/s
  report("dome (cavity) slide", s);
  EXPECT_LE(s.ripple, 0.05);
  EXPECT_LE(s.tangential, 0.02);
}

TEST(Proxy, ConcaveCornersHoldTheProxyOnTwoAndThreeWalls) {
  const double h = 0.05, r = ProxyParams{}.radius, k = ProxyParams{}.stiffness;
  const RigidSurface room(box_surface(Eigen::Vector3d::Constant(h), 4), true, "room");
  Proxy proxy(room, ProxyParams{});
  proxy.reset(Eigen::Vector3d::Zero());
  const Eigen::Vector3d into_edge(h - r + 0.001, h - r + 0.0005, 0.01);
  Eigen::Vector3d f = move(proxy, Eigen::Vector3d::Zero(), into_edge, 100, 5);
  EXPECT_LT((proxy.proxy_point() - Eigen::Vector3d(h - r, h - r, 0.01)).norm(), 1e-8);
  EXPECT_LT((f - k * Eigen::Vector3d(-0.001, -0.0005, 0)).norm(), 1e-4);
  EXPECT_EQ(proxy.active_constraints(), 2);
  const Eigen::Vector3d into_corner(h - r + 0.001, h - r + 0.0005, h - r + 0.0002);
  f = move(proxy, into_edge, into_corner, 50, 5);
  EXPECT_LT((proxy.proxy_point() - Eigen::Vector3d::Constant(h - r)).norm(), 1e-8);
  EXPECT_LT((f - k * Eigen::Vector3d(-0.001, -0.0005, -0.0002)).norm(), 1e-4);
  EXPECT_EQ(proxy.active_constraints(), 3);
}

// Over a box's convex edge the exact offset surface is a quarter cylinder of the tip radius: the device moved on an
// arc inside it, from above one face to beside the other, meets the force of that offset surface all the way.
TEST(Proxy, RollsOverAConvexEdge) {
  const double h = 0.05, r = ProxyParams{}.radius, k = ProxyParams{}.stiffness;
  const RigidSurface block(box_surface(Eigen::Vector3d::Constant(h), 4), false, "block");
  const Eigen::Vector3d edge(h, h, 0.01);
  Proxy proxy(block, ProxyParams{});
  const double rho = r - 0.001;
  auto at = [&](double deg) {
    return (edge + rho * Eigen::Vector3d(std::cos(deg * kPi / 180), std::sin(deg * kPi / 180), 0)).eval();
  };
  proxy.reset(edge + Eigen::Vector3d(-0.01, 0.02, 0));
  move(proxy, proxy.proxy_point(), at(100), 50, 5);
  double worst_force = 0, worst_direction = 0;
  for (int i = 0; i <= 1200; ++i) {
    const double deg = 100 - 120.0 * i / 1200;  // 100 to -20 degrees
    const Eigen::Vector3d device = at(deg);
    const Eigen::Vector3d f = proxy.step(device, kDt);
    // The exact offset surface's nearest point to the device: the face planes beyond the quarter, the cylinder in it.
    const double a = deg * kPi / 180;
    Eigen::Vector3d expected;
    if (deg > 90)
      expected = k * Eigen::Vector3d(0, r - rho * std::sin(a), 0);
    else if (deg < 0)
      expected = k * Eigen::Vector3d(r - rho * std::cos(a), 0, 0);
    else
      expected = k * (r - rho) * Eigen::Vector3d(std::cos(a), std::sin(a), 0);
    worst_force = std::max(worst_force, std::abs(f.norm() - expected.norm()) / expected.norm());
    worst_direction = std::max(worst_direction, (f.normalized() - expected.normalized()).norm());
  }
  std::cout << "convex edge roll: force within " << 100 * worst_force << " %, direction within " << worst_direction
            << " rad of the exact offset surface\n";
  EXPECT_LT(worst_force, 0.02);
  EXPECT_LT(worst_direction, 0.02);
}

// The closed loop: a device of mass m (kg) and damping b (N s/m) pushed by a constant hand force F (N) along
// -normal onto a plane, from 1 mm above contact at rest, the haptic loop at 1 kHz. The force is held over the tick
// (zero-order hold), optionally a tick late; the device's motion over a tick is the exact solution of
// m v' = f - F - b v for the held force (no integration error). The environment's energy balance: W(t) = integral of
// f v dt (what it gave the device) plus the energy its spring holds at t, 1/2 k gap^2 of the force being applied:
// a passive environment keeps W + stored <= 0 at every instant (it can only give back what it was given).
struct Loop {
  double generated = 0;    // J, max over time of W + stored
  double work = 0;         // J, W at the end (the net energy the environment gave the device)
  double late_speed = 0;   // m/s, max |v| over the last 0.5 s
  double penetration = 0;  // m, at the end
};
Loop closed_loop(double m, double b, double push, int delay, const ProxyParams& params) {
  const RigidSurface floor(plane_patch(0.2, 0.2, 4), false, "floor");
  Proxy proxy(floor, params);
  double z = params.radius + 0.001, v = 0;
  proxy.reset(Eigen::Vector3d(0.01, 0.02, z));
  Loop out;
  double held_force = 0, held_gap = 0;  // the previous tick's, for the delay
  const int ticks = 3000;
  for (int i = 0; i < ticks; ++i) {
    const double f_new = proxy.step(Eigen::Vector3d(0.01, 0.02, z), kDt).z();
    const double gap_new = proxy.penetration();
    const double f = delay ? held_force : f_new, gap = delay ? held_gap : gap_new;
    held_force = f_new;
    held_gap = gap_new;
    const double total = f - push, a = b / m, v_inf = total / b, decay = std::exp(-a * kDt);
    const double z1 = z + v_inf * kDt + (v - v_inf) * (1 - decay) / a;
    v = v_inf + (v - v_inf) * decay;
    out.work += f * (z1 - z);
    z = z1;
    out.generated = std::max(out.generated, out.work + 0.5 * params.stiffness * gap * gap);
    if (i >= ticks - 500) out.late_speed = std::max(out.late_speed, std::abs(v));
  }
  out.penetration = params.radius - z;
  return out;
}

TEST(Proxy, ClosedLoopIsPassiveAndSettlesOverTheDeviceRange) {
  std::cout << "m kg, b N s/m, push N, delay ticks: generated J, net work J, late speed m/s, penetration mm\n";
  for (double m : {0.05, 0.1, 0.2})
    for (double b : {0.1, 0.5, 1.0})
      for (double push : {0.5, 1.0, 3.0})
        for (int delay : {0, 1}) {
          const Loop l = closed_loop(m, b, push, delay, ProxyParams{});
          std::cout << m << " " << b << " " << push << " " << delay << ": " << l.generated << " " << l.work << " "
                    << l.late_speed << " " << 1000 * l.penetration << "\n";
          EXPECT_LE(l.generated, 1e-9) << m << " " << b << " " << push << " " << delay;
          EXPECT_LE(l.work, 0);
          EXPECT_LT(l.late_speed, 1e-6);
          EXPECT_NEAR(l.penetration, push / 2000, 1e-6);  // 3 N at 2 N/mm: 1.5 mm
        }
}

// The negative control: the bare spring (no damper), sampled, gives energy out on a light lightly damped device.
TEST(Proxy, BareSpringWithoutTheDamperGivesEnergyOut) {
  ProxyParams bare;
  bare.damping = 0;
  for (int delay : {0, 1}) {
    const Loop l = closed_loop(0.05, 0.1, 3.0, delay, bare);
    std::cout << "bare spring, 0.05 kg, 0.1 N s/m, 3 N, delay " << delay << ": generated " << l.generated
              << " J, net work " << l.work << " J, late speed " << l.late_speed << " m/s\n";
    EXPECT_GT(l.generated, 1e-3);
    EXPECT_GT(l.late_speed, 0.01);
  }
}

TEST(Proxy, IdenticalRunsAreBitIdentical) {
  const RigidSurface bar(tube_surface(0.02, 0.1, 64, 4, true), false, "rib bar");
  auto path = [](double s) {
    const double a = 2 * kPi * s;
    return Eigen::Vector3d(0.0215 * std::cos(a), 0.0215 * std::sin(a), 0.01 * std::sin(5 * a));
  };
  auto normal = [](const Eigen::Vector3d& p) { return Eigen::Vector3d(p.x(), p.y(), 0).normalized().eval(); };
  const Slide a = slide(bar, path, normal, 500), b = slide(bar, path, normal, 500);
  ASSERT_EQ(a.forces.size(), b.forces.size());
  EXPECT_EQ(std::memcmp(a.forces.data(), b.forces.data(), a.forces.size() * sizeof(double)), 0);
}

TEST(Proxy, StepAndResetAllocateNothing) {
  const RigidSurface bar(tube_surface(0.02, 0.1, 64, 4, true), false, "rib bar");
  Proxy proxy(bar, ProxyParams{});
  double sum = 0;
  test::AllocationCounter counter;
  proxy.reset(Eigen::Vector3d(0.03, 0, 0));
  for (int i = 0; i < 1000; ++i) {
    const double a = 0.01 * i;
    sum += proxy.step(Eigen::Vector3d(0.0215 * std::cos(a), 0.0215 * std::sin(a), 0), kDt).norm();
  }
  proxy.reset(Eigen::Vector3d::Zero());  // inside the bar: pushed out
  EXPECT_EQ(counter.count(), 0);
  EXPECT_GT(sum, 0);
}

TEST(Proxy, ResetInsideAnOrganPutsTheProxyOutside) {
  const RigidSurface block(box_surface(Eigen::Vector3d(0.05, 0.04, 0.03), 2), false, "block");
  Proxy proxy(block, ProxyParams{});
  proxy.reset(Eigen::Vector3d(0.01, 0.02, 0.025));  // 5 mm under the top face
  EXPECT_NEAR(proxy.proxy_point().z(), 0.03 + ProxyParams{}.radius, 1e-8);
  const Eigen::Vector3d f = proxy.step(Eigen::Vector3d(0.01, 0.02, 0.025), kDt);
  EXPECT_NEAR(f.norm(), ProxyParams{}.max_force, 1e-12);  // 2000 N/m x 7.5 mm = 15 N, clamped
  EXPECT_GT(f.z(), 0);
}

TEST(Proxy, BadParametersAreRefusedNamingTheSurface) {
  const RigidSurface floor(plane_patch(0.1, 0.1, 2), false, "scene.yaml: organs.ribs");
  ProxyParams p;
  p.stiffness = 0;
  const std::string m = test::error_of([&] { Proxy(floor, p); });
  EXPECT_TRUE(test::contains(m, "organs.ribs") && test::contains(m, "stiffness")) << m;
  p = ProxyParams{};
  p.radius = std::nan("");
  EXPECT_TRUE(test::contains(test::error_of([&] { Proxy(floor, p); }), "radius"));
}

}  // namespace
}  // namespace surgsim::rigid
