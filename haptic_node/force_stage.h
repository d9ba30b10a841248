// The last stage before the device: a contact damper (the virtual coupling) and a passivity
// observer / passivity controller (Hannaford & Ryu 2002, "Time-domain passivity control of haptic interfaces") on the
// force sent. Organ-independent: it sees only the tool's tip and ContactTick::device_force, so it serves the liver and
// the intestine alike.
//
// The organ is an impedance (pose in -> force out). Per tick k, with dt the tick and v_k = (tip_k - tip_{k-1}) / dt
// the tool tip's velocity from successive tool poses (the device's, or the replayed ones):
//
//  1. Coupling (a spring-damper between the device and the tool proxy whose spring is the organ itself, so the proxy
//     is the device's pose and only the damper is added): along the contact force's direction n = F / |F|,
//         F <- F - B (v . n) n,   the damper force clamped to [-0.35 |F|, 0.35 |F|],
//     B = haptic.coupling_damping (N s/m). It acts only in contact (F = 0 gives no force), never pulls the tool into
//     the organ (the normal force stays >= 0) and grows with the contact force from 0, so it adds no step at contact
//     onset; it leaves sliding at constant depth untouched (v . n = 0 there: no drag).
//  2. Passivity observer. Sign convention: the power flowing INTO the environment (the organ with the coupling) is
//     P_k = F_env . v_k with F_env = -F the force the tool applies to the organ. The observed energy is
//         E_k = E_{k-1} + F_env,k . v_k dt = E_{k-1} - F_k . v_k dt,     E_0 = 0,
//     and E_k < 0 means the environment has handed the hand more energy than it ever received.
//  3. Passivity controller: when E_k (with this tick's force) would be negative, a variable damper
//         alpha_k = min(-E_k / (v_k . v_k dt), haptic.passivity_max_damping),   F <- F - alpha_k v_k
//     dissipates the deficit in the same tick (E_k = 0 when alpha is not capped; a capped or clamped deficit is carried
//     to the next ticks). Then |F| is clamped to the device limit and E_k updated with the force actually sent.
//
// Without haptic.passivity (true by default) the stage passes the force through unchanged (the observer still runs,
// so its energy says whether the environment was active). A tick without a pose (device input lost) forgets the
// previous tip: the velocity of the next tick is 0, not the jump from the held pose.
// No allocation, noexcept, the force sent stays finite and within the device limit.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json_fwd.hpp>

#include "organ.h"
#include "scene/scene.h"
#include "tool/tool.h"

namespace surgsim {

class ForceStage {
 public:
  ForceStage() = default;
  /// Parameters from the scene (haptic.passivity, coupling_damping, passivity_max_damping) and the device limit.
  ForceStage(const scene::HapticSpec& haptic, double force_limit);

  /// Run phase: modifies out.device_force for the tool `tool` after a tick of dt (s). No allocation.
  void apply(const tool::ToolGeometry& tool, double dt, contact::ContactTick& out) noexcept;
  /// The same; a null tool is a tick without a pose (input lost): nothing is observed and the next velocity is 0.
  void apply(const tool::ToolGeometry* tool, double dt, contact::ContactTick& out) noexcept;

  double energy() const { return energy_; }                   // J, E_k (into the environment)
  double energy_min() const { return energy_min_; }           // J, lowest E_k after the controller
  double energy_min_observed() const { return observed_min_; }  // J, lowest E_k before the controller acted
  double pc_dissipated() const { return pc_dissipated_; }     // J, removed by the passivity controller
  double coupling_dissipated() const { return coupling_dissipated_; }  // J, removed by the coupling damper
  std::uint64_t pc_ticks() const { return pc_ticks_; }        // ticks the controller acted
  std::uint64_t clamped_ticks() const { return clamped_ticks_; }

  /// Shutdown: the "force_stage" entry of the stats JSON.
  void add_stats(nlohmann::json& stats) const;
  /// Shutdown: that entry's value.
  nlohmann::json to_json() const;

 private:
  bool passivity_ = true;
  double coupling_damping_ = 0;  // N s/m
  double max_damping_ = 0;       // N s/m, cap of the controller's alpha
  double force_limit_ = 8.0;     // N

  bool has_prev_ = false;
  Eigen::Vector3d prev_tip_ = Eigen::Vector3d::Zero();
  double energy_ = 0;
  double energy_min_ = 0;
  double observed_min_ = 0;
  double pc_dissipated_ = 0;
  double coupling_dissipated_ = 0;
  std::uint64_t pc_ticks_ = 0;
  std::uint64_t clamped_ticks_ = 0;
  std::uint64_t ticks_ = 0;
};

}  // namespace surgsim
