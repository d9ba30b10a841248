// The god-object step: constrained motion towards the device point by sweeps of the tip sphere, the constraint
// planes from the features touching it, and the coupling force.
#include "rigid/proxy.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace surgsim::rigid {

namespace {

// m: a stopped proxy is left this far outside the surface offset by the radius (so that rounding never puts it
// inside), and features within this of the offset surface hold it (constraint planes).
constexpr double kSkin = 1e-9;
constexpr double kTouch = 1e-7;
// m: a constrained motion shorter than this ends the tick's sweeps.
constexpr double kStill = 1e-13;

}  // namespace

Proxy::Proxy(const RigidSurface& surface, const ProxyParams& params) : surface_(&surface), params_(params) {
  auto check = [&](double v, bool zero_ok, const char* name, const char* unit) {
    if (!std::isfinite(v) || v < 0 || (!zero_ok && v == 0))
      core::throw_error(surface.where(), ": proxy ", name, " must be ", zero_ok ? "non-negative" : "positive",
                        " and finite (", unit, "), got ", v);
  };
  check(params.stiffness, false, "stiffness", "N/m");
  check(params.damping, true, "damping", "N s/m");
  check(params.radius, false, "radius", "m");
  check(params.max_force, false, "max_force", "N");
}

void Proxy::reset(const Eigen::Vector3d& device_point) noexcept {
  const double r = params_.radius;
  Eigen::Vector3d x = device_point;
  // Far enough to reach every triangle: the device point may be deep inside an organ.
  const double everywhere = surface_->bounds().exteriorDistance(x) + surface_->bounds().diagonal().norm() + r + 1;
  for (int i = 0; i < kMaxIterations; ++i) {
    const ClosestPoint cp = surface_->closest_point(x, everywhere);
    if (!cp.found || cp.distance >= r + kSkin) break;
    x = cp.point + (r + 2 * kSkin) * cp.normal;  // out along the free side's normal (again if that nears another)
  }
  proxy_ = x;
  gap_ = 0;
  was_in_contact_ = false;
  resumed_ = true;
  active_ = 0;
}

int Proxy::collect_planes(const Eigen::Vector3d& x) noexcept {
  plane_count_ = surface_->touching(x, params_.radius + kTouch, planes_.data(), kMaxPlanes);
  return plane_count_;
}

Eigen::Vector3d Proxy::constrain(const Eigen::Vector3d& x, const Eigen::Vector3d& goal, int& active) const noexcept {
  // Projection of w = goal - x on the cone {z : n_i . z >= 0}: the nearest feasible candidate among w itself, its
  // projections on each plane and on each two planes' line, and the apex (always feasible). The cone's projection
  // lies on one of these faces, so the nearest feasible candidate is it.
  const Eigen::Vector3d w = goal - x;
  const double tol = -1e-12 * w.norm();
  auto feasible = [&](const Eigen::Vector3d& z) {
    for (int i = 0; i < plane_count_; ++i)
      if (planes_[static_cast<std::size_t>(i)].normal.dot(z) < tol) return false;
    return true;
  };
  if (feasible(w)) {
    active = 0;
    return goal;
  }
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  double best_cost = w.squaredNorm();
  active = std::min(plane_count_, 3);
  for (int i = 0; i < plane_count_; ++i) {
    const Eigen::Vector3d& ni = planes_[static_cast<std::size_t>(i)].normal;
    const double into = ni.dot(w);
    if (into >= 0) continue;
    const Eigen::Vector3d z = w - into * ni;
    if (into * into < best_cost && feasible(z)) {
      best = z;
      best_cost = into * into;
      active = 1;
    }
  }
  for (int i = 0; i < plane_count_; ++i)
    for (int j = i + 1; j < plane_count_; ++j) {
      Eigen::Vector3d line =
          planes_[static_cast<std::size_t>(i)].normal.cross(planes_[static_cast<std::size_t>(j)].normal);
      if (line.squaredNorm() < 1e-12) continue;  // (anti)parallel planes: their line is one of theirs
      line.normalize();
      const Eigen::Vector3d z = w.dot(line) * line;
      const double cost = (z - w).squaredNorm();
      if (cost < best_cost && feasible(z)) {
        best = z;
        best_cost = cost;
        active = 2;
      }
    }
  return x + best;
}

Eigen::Vector3d Proxy::step(const Eigen::Vector3d& device_point, double dt) noexcept {
  const double r = params_.radius;
  Eigen::Vector3d x = proxy_;
  if (device_point.allFinite()) {
    for (int it = 0; it < kMaxIterations; ++it) {
      collect_planes(x);
      int active = 0;
      const Eigen::Vector3d y = constrain(x, device_point, active);
      const Eigen::Vector3d d = y - x;
      if (d.squaredNorm() <= kStill * kStill) break;  // converged
      const SegmentHit hit = surface_->segment_hit(x, y, r);
      if (!hit.hit) {
        x = y;
        if (active == 0) break;  // reached the device point
        continue;                // along the planes: they may have ended (a convex edge) or new ones begin
      }
      // Stop short of the contact by kSkin along its normal, then slide on it in the next sweep.
      const double approach = -hit.normal.dot(d);
      const double t = approach > 0 ? std::max(0.0, hit.t - kSkin / approach) : 0.0;
      x += t * d;
    }
  }
  proxy_ = x;
  collect_planes(x);
  constrain(x, device_point.allFinite() ? device_point : x, active_);

  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  const Eigen::Vector3d gap = x - device_point;
  const double g = gap.norm();
  if (active_ > 0 && g > 0 && std::isfinite(g)) {
    const Eigen::Vector3d u = gap / g;
    // Rate of the gap (m/s): from 0 at the first tick of a contact (the impact is damped too).
    // After a reset (an instrument back from a lost input, perhaps already pressing) the gap found is not an
    // impact: its rate starts at 0, or the damper would kick the device with B g / dt.
    const double previous = was_in_contact_ ? gap_ : resumed_ ? g : 0.0;
    const double rate = dt > 0 ? (g - previous) / dt : 0.0;
    force = params_.stiffness * gap + params_.damping * rate * u;
    const double normal = force.dot(u);
    if (normal < 0) force -= normal * u;  // the damper may cancel the spring, never pull the device in
    gap_ = g;
    was_in_contact_ = true;
  } else {
    gap_ = 0;
    was_in_contact_ = false;
  }
  resumed_ = false;
  const double magnitude = force.norm();
  if (magnitude > params_.max_force) force *= params_.max_force / magnitude;
  return force;
}

}  // namespace surgsim::rigid
