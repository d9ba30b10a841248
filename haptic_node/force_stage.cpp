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
// ... and moves by at most this share of the contact force per tick beyond its share of the contact force's own change:
// a tool that stops dead (B v gone in one tick) sees the damper fade over up to 9 ticks, each force step within 5 % of
// the force held (force_stage.h), while at an onset it still follows the contact force as it grows.
constexpr double kDamperSlew = 0.04;
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
    // Passed through: the device holds the organ's own force, and the interval it ends is not observed.
    has_prev_ = false;
    damper_ = 0;
    contact_prev_ = 0;
    held_ = f;
    held_damper_.setZero();
    held_pc_.setZero();
    out.device_force = f;
    return;
  }

  // Observer: the interval just ended, with the force the device held over it (sent last tick).
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  if (has_prev_) {
    const Eigen::Vector3d dx = tool->tip - prev_tip_;
    energy_ -= held_.dot(dx);
    coupling_dissipated_ -= held_damper_.dot(dx);
    pc_dissipated_ -= held_pc_.dot(dx);
    energy_min_ = std::min(energy_min_, energy_);
    v = dx / dt;
  }
  prev_tip_ = tool->tip;
  has_prev_ = true;

  // 1. Coupling damper along the contact force, bounded by the contact force itself and slew-bounded.
  const double fn = f.norm();
  Eigen::Vector3d f_damper = Eigen::Vector3d::Zero();
  if (coupling_damping_ > 0 && fn > 0) {
    const Eigen::Vector3d n = f / fn;
    const double cap = kDamperShare * fn;
    const double slew = kDamperShare * std::abs(fn - contact_prev_) + kDamperSlew * fn;
    const double target = std::clamp(-coupling_damping_ * v.dot(n), -cap, cap);
    damper_ = std::clamp(std::clamp(target, damper_ - slew, damper_ + slew), -cap, cap);
    f_damper = damper_ * n;
    f += f_damper;
  } else {
    damper_ = 0;
  }
  contact_prev_ = fn;

  // 2-3. Controller: the energy at the end of the next interval if the tool keeps its velocity, and a variable
  // damper dissipating its deficit there.
  const double vv = v.squaredNorm();
  const double e_next = energy_ - f.dot(v) * dt;
  predicted_min_ = std::min(predicted_min_, e_next);
  Eigen::Vector3d f_pc = f;
  bool acted = false;
  if (passivity_ && e_next < 0 && vv > 0) {
    const double alpha = std::min(-e_next / (vv * dt), max_damping_);
    if (alpha > 0 && std::isfinite(alpha)) {
      f_pc = f - alpha * v;
      acted = true;
    }
  }
  // The device limit.
  const double n_pc = f_pc.norm();
  if (n_pc > force_limit_) {
    f_pc *= force_limit_ / n_pc;
    out.saturated = true;
    ++clamped_ticks_;
  }
  if (!f_pc.allFinite()) {
    f_pc = f.allFinite() ? f : Eigen::Vector3d::Zero();
    acted = false;
  }
  if (acted) ++pc_ticks_;
  held_ = f_pc;
  held_damper_ = f_damper;
  held_pc_ = acted ? Eigen::Vector3d(f_pc - f) : Eigen::Vector3d::Zero();
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
  j["energy_min_before_pc_j"] = predicted_min_;
  j["energy_dissipated_pc_j"] = pc_dissipated_;
  j["energy_dissipated_coupling_j"] = coupling_dissipated_;
  j["pc_ticks"] = pc_ticks_;
  j["clamped_ticks"] = clamped_ticks_;
  return j;
}

}  // namespace surgsim
