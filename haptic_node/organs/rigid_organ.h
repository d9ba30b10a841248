// A rigid organ in the haptic node (the abdominal wall, ribs, a spine segment: an entry `model: rigid` of a scene's
// `organs:` list): a static triangle surface (rigid/rigid_surface.h) in the scene's frame, and for each instrument a
// god-object proxy of its tip sphere (tool tip_radius; the sphere's leading point is the tip) coupled to the device
// point by the scene's spring and damper (rigid/proxy.h). A rigid organ has no compliance of its own: the coupling is
// the spring of the contact. It deforms nothing, so it gives no contact entries and no points; its force joins the
// other organs' in CompositeOrgan, and the force stage clamps the sum once.
//
// Phases as organ.h: the constructor allocates (the surface, its grid, the proxies); step() allocates nothing.
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "intestine/intestine_model.h"
#include "organ.h"
#include "rigid/proxy.h"
#include "rigid/rigid_surface.h"
#include "scene/scene.h"

namespace surgsim {

/// A rigid surface as an obstacle for a deformable body (the bowel resting on the wall): its nearest point and the
/// free side's normal there.
class RigidObstacle final : public intestine::Obstacle {
 public:
  explicit RigidObstacle(const rigid::RigidSurface& surface) : surface_(surface) {}
  bool nearest(const Eigen::Vector3d& p, double max_distance, intestine::ObstacleHit& hit) const noexcept override;

 private:
  const rigid::RigidSurface& surface_;
};

class RigidOrgan final : public HapticOrgan {
 public:
  /// Init: the surface of scene.rigid placed by scene.placement (mesher::load_scene_surface), one proxy per
  /// instrument (radius its tip_radius).
  explicit RigidOrgan(const scene::Scene& scene);

  const char* model_name() const override { return "rigid"; }
  /// Run phase: each instrument's proxy follows its tip (reset when the instrument comes back after a lost input);
  /// out[i].force = device_force = the coupling's force (N), unclamped (the force stage clamps the sum once).
  using HapticOrgan::step;
  void step(const contact::InstrumentInput* inputs, int count, double dt, contact::ContactTick* out) noexcept override;
  int contacts() const noexcept override;
  int instrument_contacts(int i) const noexcept override;
  std::uint64_t mesh_hash() const override { return surface_hash_; }
  std::uint32_t node_count() const override { return static_cast<std::uint32_t>(surface_.surface().vertices.rows()); }
  std::uint32_t surface_node_count() const override { return node_count(); }
  std::string describe() const override;
  /// "rigid": {triangles, contact_ticks, max_penetration_mm per instrument}.
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out) const override;

  const rigid::RigidSurface& surface() const { return surface_; }
  /// The surface's stiffness (N/m, scene rigid.stiffness).
  double stiffness() const { return stiffness_; }
  /// The surface as an obstacle for the field's deformable organs (CompositeOrgan gives it to the intestine).
  const intestine::Obstacle& obstacle() const { return obstacle_; }
  const rigid::Proxy& proxy(int i) const { return proxies_[static_cast<std::size_t>(i)]; }
  /// Deepest the device point went past the surface (offset by the tip radius), m, instrument i.
  double max_penetration(int i) const { return max_penetration_[static_cast<std::size_t>(i)]; }

 private:
  std::string name_;
  rigid::RigidSurface surface_;
  RigidObstacle obstacle_{surface_};
  std::uint64_t surface_hash_ = 0;
  double stiffness_ = 0;
  std::vector<rigid::Proxy> proxies_;  // one per instrument
  std::array<bool, tool::kMaxInstruments> tracking_{};  // the proxy follows a tip (false: reset at the next input)
  std::array<double, tool::kMaxInstruments> max_penetration_{};
  std::array<std::uint64_t, tool::kMaxInstruments> contact_ticks_{};
};

}  // namespace surgsim
