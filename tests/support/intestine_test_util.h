// Shared by the intestine tests: a scripted probe that pushes and lifts the folds (the scripted run of the recall
// test, also used by intestine_bench), and the body's lowest point, its weight and what its root carries (the tests of
// the bowel resting on other organs).
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "intestine/intestine_model.h"

namespace surgsim::intestine::test {

/// Probe path for the default model (vessel along x through the origin, the folds hanging below it once gravity has
/// acted): settle 0.4 s, push the folds sideways, lift them, sweep along the vessel, pull back. Piecewise linear.
inline intestine::Probe scripted_probe(double t) {
  struct Key {
    double t;
    double x, y, z;
  };
  static constexpr std::array<Key, 6> keys{{{0.4, 0.0, 0.22, -0.12},
                                            {1.0, 0.0, -0.02, -0.12},
                                            {1.6, 0.08, -0.02, -0.01},
                                            {2.2, -0.12, 0.0, -0.08},
                                            {2.8, 0.1, 0.05, -0.13},
                                            {3.4, 0.0, 0.25, -0.1}}};
  intestine::Probe p;
  p.radius = 0.01;
  if (t < keys.front().t || t > keys.back().t) return p;
  p.active = true;
  for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
    if (t <= keys[i + 1].t) {
      const double f = (t - keys[i].t) / (keys[i + 1].t - keys[i].t);
      p.center = Eigen::Vector3d((1 - f) * keys[i].x + f * keys[i + 1].x, (1 - f) * keys[i].y + f * keys[i + 1].y,
                                 (1 - f) * keys[i].z + f * keys[i + 1].z);
      break;
    }
  }
  return p;
}

/// Lowest point (m) of the body's spheres at positions `x` (3 x N): the tube's radius on the intestine's row, half the
/// membrane's thickness on the mesentery, free nodes only, and of those only the nodes with |x|, |y| <= `half` (m).
inline double lowest_sphere(const intestine::IntestineModel& model, const Eigen::Matrix3Xd& x,
                            double half = std::numeric_limits<double>::infinity()) {
  const intestine::IntestineParams& p = model.params();
  double z = std::numeric_limits<double>::infinity();
  for (int n = 0; n < model.node_count(); ++n) {
    if (model.mass_spring().fixed(n) || std::abs(x(0, n)) > half || std::abs(x(1, n)) > half) continue;
    z = std::min(z, x(2, n) - (n < p.columns ? p.intestine_radius : 0.5 * p.mesentery_thickness));
  }
  return z;
}

/// The force (N) the fixed nodes (the mesentery's root) exert on the free ones through the springs, from positions
/// and velocities.
inline Eigen::Vector3d root_reaction(const intestine::IntestineModel& model, const intestine::IntestineState& state) {
  const intestine::MassSpring& m = model.mass_spring();
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  for (const intestine::Spring& s : m.springs()) {
    const bool fi = m.fixed(s.i), fj = m.fixed(s.j);
    if (fi == fj) continue;
    const int free = fi ? s.j : s.i, fixed = fi ? s.i : s.j;
    const Eigen::Vector3d d = state.x.col(fixed) - state.x.col(free);
    const double l = d.norm();
    const Eigen::Vector3d u = d / l;
    const double rate = (state.v.col(fixed) - state.v.col(free)).dot(u);
    f += (s.stiffness * (l - s.rest) + s.damping * rate) * u;
  }
  return f;
}

/// The weight (N) of the free nodes.
inline Eigen::Vector3d weight(const intestine::IntestineModel& model) {
  double mass = 0;
  for (int n = 0; n < model.node_count(); ++n) {
    if (!model.mass_spring().fixed(n)) mass += model.mass_spring().mass()[static_cast<std::size_t>(n)];
  }
  return mass * model.params().gravity;
}

}  // namespace surgsim::intestine::test
