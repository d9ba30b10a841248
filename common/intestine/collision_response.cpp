#include "intestine/collision_response.h"

#include <algorithm>

namespace surgsim::intestine {

namespace {

// sum_k s_k w_k q_k over the contact's nodes, s = +1 on side A and -1 on side B, projected on n: (p_A - p_B).n for
// positions, (v_A - v_B).n for velocities. Raw columns: this runs for every contact of every sweep.
double relative_normal(const CollisionContact& c, const double* q) noexcept {
  double r0 = 0, r1 = 0, r2 = 0;
  const int n = c.count_a + c.count_b;
  for (int k = 0; k < n; ++k) {
    const double w = k < c.count_a ? c.weights[static_cast<std::size_t>(k)] : -c.weights[static_cast<std::size_t>(k)];
    const double* col = q + 3 * c.nodes[static_cast<std::size_t>(k)];
    r0 += w * col[0];
    r1 += w * col[1];
    r2 += w * col[2];
  }
  return r0 * c.normal.x() + r1 * c.normal.y() + r2 * c.normal.z();
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
void apply(const CollisionContact& c, const double* inverse_mass, double lambda, double* q) noexcept {
  for (int k = 0; k < c.count_a + c.count_b; ++k) {
    const int node = c.nodes[static_cast<std::size_t>(k)];
    const double w = lambda * c.weights[static_cast<std::size_t>(k)] * inverse_mass[node];
    const double s = k < c.count_a ? w : -w;
    double* col = q + 3 * node;
    col[0] += s * c.normal.x();
    col[1] += s * c.normal.y();
    col[2] += s * c.normal.z();
  }
}

}  // namespace

double contact_gap(const CollisionContact& c, const Eigen::Matrix3Xd& x) noexcept {
  return relative_normal(c, x.data()) - c.radius_sum;
}

void respond(const ContactList& contacts, const double* inverse_mass, const ResponseParams& params,
             Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, ResponseReport& report) noexcept {
  report = ResponseReport{};
  double* px = x.data();
  double* pv = v.data();
  for (const CollisionContact& c : contacts) {
    report.max_penetration_before = std::max(report.max_penetration_before, c.radius_sum - relative_normal(c, px));
  }
  for (int it = 0; it < params.iterations; ++it) {
    for (const CollisionContact& c : contacts) {
      const double w = compliance(c, inverse_mass);
      if (!(w > 0)) continue;  // both sides fixed
      // Velocity (eqs. 2-5): cancel the approach along n.
      if (params.correct_velocity) {
        const double vn = relative_normal(c, pv);
        if (vn < 0) {
          apply(c, inverse_mass, -vn / w, pv);
          if (it == 0) ++report.velocity_corrections;
        }
      }
      // Position (eqs. 6-9): restore the sum of the radii along n.
      if (params.correct_position) {
        const double gap = relative_normal(c, px) - c.radius_sum;
        if (gap < 0) apply(c, inverse_mass, -gap / w, px);
      }
    }
  }
  for (const CollisionContact& c : contacts) {
    report.max_penetration_after = std::max(report.max_penetration_after, c.radius_sum - relative_normal(c, px));
  }
}

}  // namespace surgsim::intestine
