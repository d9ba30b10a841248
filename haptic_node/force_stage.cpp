#include "force_stage.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

using namespace surgsim::tool;
using namespace surgsim::contact;
using namespace surgsim::scene;

namespace surgsim {

namespace {
// The damper never exceeds this share of the contact force: it starts from zero with the contact, and at a 0.1 m/s
// onset it steepens the force ramp by at most this factor (1.35 x 3.6 % per tick on the slab, under the 5 % bound).
constexpr double kDamperShare = 0.35;
}  // namespace

ForceStage::ForceStage(const HapticSpec& haptic, double force_limit)
    : passivity_(haptic.passivity),
      coupling_damping_(haptic.coupling_damping),
      max_damping_(haptic.passivity_max_damping),
      force_limit_(force_limit) {}

void ForceStage::apply(const ToolGeometry& tool, double dt, ContactTick& out) noexcept { apply(&tool, dt, out); }

void ForceStage::apply(const ToolGeometry* tool, double dt, ContactTick& out) noexcept {
  ++ticks_;
  Eigen::Vector3d f = out.device_force;
  if (!f.allFinite()) f.setZero();  // the organ guarantees a finite force; keep the guarantee whatever came in
  const bool pose_ok = tool != nullptr && tool->tip.allFinite() && dt > 0 && std::isfinite(dt);
  if (!pose_ok) {
    has_prev_ = false;
    out.device_force = f;
    return;
  }
  const Eigen::Vector3d v = has_prev_ ? Eigen::Vector3d((tool->tip - prev_tip_) / dt) : Eigen::Vector3d::Zero();
  prev_tip_ = tool->tip;
  has_prev_ = true;

  // 1. Coupling damper along the contact force, bounded by the contact force itself.
  const double fn = f.norm();
  if (coupling_damping_ > 0 && fn > 0) {
    const Eigen::Vector3d n = f / fn;
    const double cap = kDamperShare * fn;
    const double d = std::clamp(-coupling_damping_ * v.dot(n), -cap, cap);
    f += d * n;
    coupling_dissipated_ += -d * v.dot(n) * dt;
  }

  // 2. Observer: the energy into the environment with this tick's force.
  const double vv = v.squaredNorm();
  double e = energy_ - f.dot(v) * dt;
  observed_min_ = std::min(observed_min_, e);

  // 3. Controller: a variable damper dissipating the deficit this tick.
  Eigen::Vector3d f_pc = f;
  bool acted = false;
  if (passivity_ && e < 0 && vv > 0) {
    const double alpha = std::min(-e / (vv * dt), max_damping_);
    if (alpha > 0 && std::isfinite(alpha)) {
      f_pc = f - alpha * v;
      acted = true;
    }
  }
  // The device limit, then the energy of the force actually sent.
  const double n_pc = f_pc.norm();
  if (n_pc > force_limit_) {
    f_pc *= force_limit_ / n_pc;
    out.saturated = true;
    ++clamped_ticks_;
  }
  if (!f_pc.allFinite()) f_pc = f.allFinite() ? f : Eigen::Vector3d::Zero();
  if (acted) {
    ++pc_ticks_;
    pc_dissipated_ += -(f_pc - f).dot(v) * dt;
  }
  energy_ -= f_pc.dot(v) * dt;
  energy_min_ = std::min(energy_min_, energy_);
  out.device_force = f_pc;
}

void ForceStage::add_stats(nlohmann::json& stats) const { stats["force_stage"] = to_json(); }

nlohmann::json ForceStage::to_json() const {
  nlohmann::json j;
  j["passivity"] = passivity_;
  j["coupling_damping_ns_per_m"] = coupling_damping_;
  j["passivity_max_damping_ns_per_m"] = max_damping_;
  j["energy_observed_j"] = energy_;
  j["energy_min_j"] = energy_min_;
  j["energy_min_before_pc_j"] = observed_min_;
  j["energy_dissipated_pc_j"] = pc_dissipated_;
  j["energy_dissipated_coupling_j"] = coupling_dissipated_;
  j["pc_ticks"] = pc_ticks_;
  j["clamped_ticks"] = clamped_ticks_;
  return j;
}

}  // namespace surgsim
