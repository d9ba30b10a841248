// The god-object proxy (Zilles and Salisbury 1995; Ruspini's finger proxy) of one instrument tip against one rigid
// organ, and the virtual coupling that turns it into the device's force. The tip is a sphere of `radius` about the
// device point; the proxy is where that sphere's centre may be: it follows the device point as far as the surface
// lets it, sliding frictionlessly along up to three constraint planes, and never crosses the surface (every motion
// is swept against it). The force is a spring from the device point to the proxy plus a damper on the rate of that
// gap, which keeps the closed loop passive at 1 kHz with a zero-order hold and a tick of delay (see ProxyParams).
#pragma once
#include <Eigen/Core>
#include <array>

#include "rigid/rigid_surface.h"

namespace surgsim::rigid {

struct ProxyParams {
  double stiffness = 2000;  // N/m, the coupling spring k (a scene value; 2 N/mm is what a desktop device renders)
  // N s/m, the damper B on the rate of the gap |proxy - device| while in contact (never pulls the device in). The
  // bare spring is not passive when sampled (zero-order hold, plus a tick of delay: it gives out energy on every
  // bounce); with k = 2000 N/m at 1 kHz a device of 0.05-0.2 kg, 0.1-1 N s/m pushed with 0.5-3 N takes out of the
  // environment no energy at any instant for B in about 7-30 N s/m (below, a light device bounces and gains energy;
  // above, the delayed damper itself rings): 15 is the middle of that window. Scale it with k.
  double damping = 15;
  double radius = 0.0025;  // m, the tip sphere (ToolSpec::tip_radius)
  double max_force = 8;    // N, the force's magnitude is clamped to this (ToolSpec::force_limit)
};

class Proxy {
 public:
  /// Checks the parameters (Error naming the surface's `where` when one is not positive and finite, damping may be
  /// 0). The surface must outlive the proxy.
  Proxy(const RigidSurface& surface, const ProxyParams& params);

  /// Puts the proxy at the device point, or, when that is within `radius` of the surface or on its far side, at the
  /// nearest place on the free side (the tip pushed out along the closest point's normal); clears the damper.
  void reset(const Eigen::Vector3d& device_point) noexcept;

  /// One haptic tick: moves the proxy towards the device point (m) and returns the force on the device (N). `dt`
  /// (s) is the tick. Allocation-free, deterministic.
  Eigen::Vector3d step(const Eigen::Vector3d& device_point, double dt) noexcept;

  const Eigen::Vector3d& proxy_point() const { return proxy_; }  // m, the tip sphere's centre
  double penetration() const {
    return gap_;
  }                                                   // m, >= 0: the device point's depth past the
                                                      // surface offset by radius (|proxy - device|)
  bool in_contact() const { return active_ > 0; }     // the surface holds the proxy back
  int active_constraints() const { return active_; }  // 0-3 planes the proxy slides on
  const ProxyParams& params() const { return params_; }

 private:
  static constexpr int kMaxPlanes = 8;      // distinct contact normals considered at once
  static constexpr int kMaxIterations = 6;  // sweeps per tick
  // The point nearest `goal` in the cone {y : n_i . (y - x) >= 0} of the current planes; `active` gets how many
  // planes it lies on (0 when the goal is free).
  Eigen::Vector3d constrain(const Eigen::Vector3d& x, const Eigen::Vector3d& goal, int& active) const noexcept;
  int collect_planes(const Eigen::Vector3d& x) noexcept;  // fills planes_, returns their count

  const RigidSurface* surface_;
  ProxyParams params_;
  Eigen::Vector3d proxy_ = Eigen::Vector3d::Zero();
  double gap_ = 0;  // m, |proxy - device| while in contact
  bool was_in_contact_ = false;
  bool resumed_ = false;  // reset() just ran: the next contact is not an impact (its gap rate starts at 0)
  int active_ = 0;
  int plane_count_ = 0;
  std::array<Touch, kMaxPlanes> planes_;
};

}  // namespace surgsim::rigid
