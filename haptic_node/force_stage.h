// The last stage before the device: a contact damper (the virtual coupling) and a passivity
// observer / passivity controller (Hannaford & Ryu 2002, "Time-domain passivity control of haptic interfaces") on the
// force sent. Organ-independent: it sees only the tool's tip and ContactTick::device_force, so it serves the liver and
// the intestine alike.
//
// The organ is an impedance (pose in -> force out) behind a sample-and-hold: the force F_k sent at tick k is what the
// device HOLDS over the next interval, from tip_k to tip_{k+1}. Per tick k, with dt the tick, dx_k = tip_k - tip_{k-1}
// the tool tip's motion over the interval just ended and v_k = dx_k / dt its velocity:
//
//  1. Coupling (a spring-damper between the device and the tool proxy whose spring is the organ itself, so the proxy
//     is the device's pose and only the damper is added): along the contact force's direction n = F / |F|,
//         F <- F + d_k n,   d_k = -B (v_k . n) clamped to [-0.35 |F|, 0.35 |F|]
//                           and to d_{k-1} +- (0.35 | |F_k| - |F_{k-1}| | + 0.04 |F_k|),
//     B = haptic.coupling_damping (N s/m). It acts only in contact (F = 0 gives no force and resets d), never pulls the
//     tool into the organ (the normal force stays >= 0.65 |F|) and grows with the contact force from 0, so it adds no
//     step at contact onset; it leaves sliding at constant depth untouched (v . n = 0 there: no drag). The slew bound
//     (beyond following its share of the contact force's change, d moves by at most 4 % of the contact force a tick)
//     is for a tool that stops dead (scripted; a device with mass cannot): B v would vanish in one tick and the force
//     would step by up to the 35 % share; instead the damper fades over up to 9 ticks, each step within 5 % of the
//     force held at rest (4 % from the damper, the rest left to the organ's own change). A tool that starts dead
//     inside the organ gets the damper the same way.
//  2. Passivity observer. Sign convention: the power flowing INTO the environment (the organ with the coupling) is
//     F_env . v with F_env = -F the force the tool applies to the organ. Over interval k the device held F_{k-1} (what
//     this stage sent last tick, after the controller and the device limit), so the energy into the environment is
//         E_k = E_{k-1} - F_{k-1} . dx_k,     E_0 = 0,
//     exact for any motion within the interval, since the force is constant over it. E_k < 0 means the environment
//     has handed the hand more energy than it ever received. Pairing F_k (computed from tip_k) with dx_k instead, as a
//     continuous-time observer does, credits a spring K with +K dx^2 / 2 per tick where the hold hands out K dx^2 / 2:
//     it cannot see the energy a sample-and-hold makes (the one-tick-delayed stiff wall of the tests).
//  3. Passivity controller: the force sent now acts over the next interval, so the controller looks one interval
//     ahead. If the tool keeps v_k, the next interval ends with
//         E^_{k+1} = E_k - F . v_k dt;
//     when that is negative a variable damper
//         alpha_k = min(-E^_{k+1} / (v_k . v_k dt), haptic.passivity_max_damping),   F <- F - alpha_k v_k
//     dissipates the deficit (the observed one and the one this force would add) over the next interval; what it did
//     dissipate is measured there with the force held, and any deficit left (a capped alpha, a change of velocity) is
//     taken up by the next ticks. The damper is itself held for a tick, i.e. an explicit one on the device's mass m:
//     its cap must stay below m / dt (50 N s/m for a 50 g device at 1 kHz), or it rings on its own and the observer
//     (rightly) sees it add energy. Then |F| is clamped to the device limit.
//
// Without haptic.passivity (true by default) the controller does not act (the observer still runs, so its energy says
// whether the environment was active). A tick without a pose (device input lost) passes the force through and forgets
// the previous tip: that interval is not observed and the velocity of the next tick is 0, not the jump from the held
// pose. No allocation, noexcept, the force sent stays finite and within the device limit.
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

  double energy() const { return energy_; }                       // J, E_k (into the environment, with the held force)
  double energy_min() const { return energy_min_; }               // J, lowest E_k
  double energy_min_predicted() const { return predicted_min_; }  // J, lowest E^_{k+1} before the controller acted
  double pc_dissipated() const { return pc_dissipated_; }         // J, removed by the controller's held force
  double coupling_dissipated() const { return coupling_dissipated_; }  // J, removed by the coupling damper's
  std::uint64_t pc_ticks() const { return pc_ticks_; }                 // ticks the controller acted
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
  // The force sent last tick, which the device holds over the interval now ending, and the shares of it the coupling
  // damper and the controller added (each one's dissipation is its share dotted with the motion).
  Eigen::Vector3d held_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d held_damper_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d held_pc_ = Eigen::Vector3d::Zero();
  double damper_ = 0;        // N, d_{k-1}: the damper's force along the contact force last tick (slew-bounded)
  double contact_prev_ = 0;  // N, |F| last tick (the contact force before the damper)
  double energy_ = 0;
  double energy_min_ = 0;
  double predicted_min_ = 0;
  double pc_dissipated_ = 0;
  double coupling_dissipated_ = 0;
  std::uint64_t pc_ticks_ = 0;
  std::uint64_t clamped_ticks_ = 0;
  std::uint64_t ticks_ = 0;
};

}  // namespace surgsim
