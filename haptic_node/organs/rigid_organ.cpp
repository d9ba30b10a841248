#include "organs/rigid_organ.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <ostream>

#include "core/error.h"
#include "mesher/scene_mesh.h"

namespace surgsim {

bool RigidObstacle::nearest(const Eigen::Vector3d& p, double max_distance, intestine::ObstacleHit& hit) const noexcept {
  const rigid::ClosestPoint c = surface_.closest_point(p, max_distance);
  if (!c.found) return false;
  hit.distance = c.distance;
  hit.normal = c.normal;
  return true;
}

namespace {

// Bound on a proxy's force (N): a guard against a wild input, far above any device limit (the force stage clamps
// the sum of the organs' forces to the device's).
constexpr double kProxyForceGuard = 1e4;

}  // namespace

RigidOrgan::RigidOrgan(const scene::Scene& scene)
    : name_(scene.organs.at(0).name),
      surface_(mesher::load_scene_surface(scene), scene.rigid.cavity, mesher::organ_where(scene)),
      surface_hash_(mesher::rigid_surface_hash(surface_.surface(), scene.rigid.cavity)),
      stiffness_(scene.rigid.stiffness) {
  proxies_.reserve(scene.tools.size());
  for (const tool::ToolSpec& t : scene.tools) {
    rigid::ProxyParams p;
    p.stiffness = scene.rigid.stiffness;
    p.damping = scene.rigid.damping;
    p.radius = t.tip_radius;
    p.max_force = kProxyForceGuard;
    proxies_.emplace_back(surface_, p);
  }
}

void RigidOrgan::step(const contact::InstrumentInput* inputs, int count, double dt,
                      contact::ContactTick* out) noexcept {
  count = std::clamp(count, 0, static_cast<int>(proxies_.size()));
  for (int i = 0; i < count; ++i) {
    const auto si = static_cast<std::size_t>(i);
    contact::ContactTick& o = out[i];
    o = contact::ContactTick{};
    const tool::ToolGeometry* tool = inputs[i].tool;
    if (tool == nullptr || !tool->tip.allFinite() || !tool->direction.allFinite() || !(dt > 0)) {
      tracking_[si] = false;  // input lost: the proxy starts again from the tip when it comes back
      o.nonfinite = tool != nullptr && !(tool->tip.allFinite() && tool->direction.allFinite());
      continue;
    }
    rigid::Proxy& proxy = proxies_[si];
    // The instrument's end is a hemisphere of its tip radius whose leading point is the tip: as on a deformable
    // organ, the contact begins when the tip itself reaches the surface.
    const Eigen::Vector3d centre = tool->tip - proxy.params().radius * tool->direction;
    if (!tracking_[si]) {
      proxy.reset(centre);
      tracking_[si] = true;
    }
    Eigen::Vector3d f = proxy.step(centre, dt);
    if (!f.allFinite()) {
      f.setZero();
      o.nonfinite = true;
      tracking_[si] = false;
    }
    o.force = f;
    o.device_force = f;
    if (proxy.in_contact()) {
      o.points_in_contact = 1;
      ++contact_ticks_[si];
      max_penetration_[si] = std::max(max_penetration_[si], proxy.penetration());
      const double n = f.norm();
      if (n > 0) o.direction = -f / n;  // the tip presses against the force it feels
    }
  }
}

int RigidOrgan::contacts() const noexcept {
  int n = 0;
  for (int i = 0; i < static_cast<int>(proxies_.size()); ++i) n += instrument_contacts(i);
  return n;
}

int RigidOrgan::instrument_contacts(int i) const noexcept {
  if (i < 0 || i >= static_cast<int>(proxies_.size())) return 0;
  const auto si = static_cast<std::size_t>(i);
  return tracking_[si] && proxies_[si].in_contact() ? 1 : 0;
}

std::string RigidOrgan::describe() const {
  return std::to_string(surface_.triangle_count()) + " triangles (rigid" +
         (surface_.cavity() ? std::string(", cavity") : std::string()) + "); ";
}

void RigidOrgan::add_stats(nlohmann::json& j) const {
  nlohmann::json r;
  r["triangles"] = surface_.triangle_count();
  r["cavity"] = surface_.cavity();
  nlohmann::json per = nlohmann::json::array();
  for (std::size_t i = 0; i < proxies_.size(); ++i) {
    per.push_back({{"contact_ticks", contact_ticks_[i]}, {"max_penetration_mm", 1e3 * max_penetration_[i]}});
  }
  r["instruments"] = per;
  j["rigid"] = r;
}

void RigidOrgan::print_summary(std::ostream& out) const {
  out << "haptic_node: rigid organ '" << name_ << "':";
  for (std::size_t i = 0; i < proxies_.size(); ++i) {
    out << " instrument " << i << " in contact " << contact_ticks_[i] << " ticks, deepest " << 1e3 * max_penetration_[i]
        << " mm;";
  }
  out << "\n";
}

}  // namespace surgsim
