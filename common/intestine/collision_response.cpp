#include "intestine/collision_response.h"

#include <algorithm>

namespace surgsim::intestine {

namespace {

// sum_k s_k w_k q_k over the contact's nodes, s = +1 on side A and -1 on side B: p_A - p_B for positions,
// v_A - v_B for velocities.
Eigen::Vector3d relative(const CollisionContact& c, const Eigen::Matrix3Xd& q) noexcept {
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  const int n = c.count_a + c.count_b;
  for (int k = 0; k < n; ++k) {
    const double w = c.weights[static_cast<std::size_t>(k)];
    const auto col = q.col(c.nodes[static_cast<std::size_t>(k)]);
    if (k < c.count_a) {
      r += w * col;
    } else {
      r -= w * col;
    }
  }
  return r;
}

// sum over both sides of w^2 m^-1: the compliance of the contact points along n.
double compliance(const CollisionContact& c, const double* inverse_mass) noexcept {
  double s = 0;
  for (int k = 0; k < c.count_a + c.count_b; ++k) {
    const double w = c.weights[static_cast<std::size_t>(k)];
    s += w * w * inverse_mass[c.nodes[static_cast<std::size_t>(k)]];
  }
  return s;
}

// Moves node k by +-lambda w_k m_k^-1 n: the contact points move apart by lambda * compliance along n.
void apply(const CollisionContact& c, const double* inverse_mass, double lambda, Eigen::Matrix3Xd& q) noexcept {
  for (int k = 0; k < c.count_a + c.count_b; ++k) {
    const int node = c.nodes[static_cast<std::size_t>(k)];
    const double s = lambda * c.weights[static_cast<std::size_t>(k)] * inverse_mass[node];
    if (k < c.count_a) {
      q.col(node) += s * c.normal;
    } else {
      q.col(node) -= s * c.normal;
    }
  }
}

}  // namespace

double contact_gap(const CollisionContact& c, const Eigen::Matrix3Xd& x) noexcept {
  return relative(c, x).dot(c.normal) - c.radius_sum;
}

void respond(const ContactList& contacts, const double* inverse_mass, const ResponseParams& params,
             Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, ResponseReport& report) noexcept {
  report = ResponseReport{};
  for (const CollisionContact& c : contacts) {
    report.max_penetration_before = std::max(report.max_penetration_before, -contact_gap(c, x));
  }
  for (int it = 0; it < params.iterations; ++it) {
    for (const CollisionContact& c : contacts) {
      const double w = compliance(c, inverse_mass);
      if (!(w > 0)) continue;  // both sides fixed
      // Velocity (eqs. 2-5): cancel the approach along n.
      if (params.correct_velocity) {
        const double vn = relative(c, v).dot(c.normal);
        if (vn < 0) {
          apply(c, inverse_mass, -vn / w, v);
          if (it == 0) ++report.velocity_corrections;
        }
      }
      // Position (eqs. 6-9): restore the sum of the radii along n.
      if (params.correct_position) {
        const double gap = contact_gap(c, x);
        if (gap < 0) apply(c, inverse_mass, -gap / w, x);
      }
    }
  }
  for (const CollisionContact& c : contacts) {
    report.max_penetration_after = std::max(report.max_penetration_after, -contact_gap(c, x));
  }
}

}  // namespace surgsim::intestine
