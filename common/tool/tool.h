// Laparoscopic tool kinematics: 5-DOF pose about a trocar -> shaft direction, tip, contact points, jaws.
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>

#include "tool/trajectory.h"

namespace surgsim::tool {

constexpr int kMaxShaftPoints = 32;

/// How a liver contact is imposed on the organ: `patch` (default) spreads one constraint along the surface
/// normal (frictionless) or a sticking 3-D constraint (friction, grasp) over the tip's footprint (TipModel); `triangle`
/// is the paper's distribution of the contact displacement over the three vertices of the touched triangle (alpha_v d,
/// all three components imposed).
enum class ContactModel : int { kPatch = 0, kTriangle = 1 };

/// How the patch model sees the tip (patch model only). `footprint` (default): the shape functions integrated over
/// the tip's disc of radius tip_radius, plus the near field the mesh cannot resolve (contact/near_field.h): the
/// same force on any mesh. `nodes`: the earlier model, Wendland weights over the free nodes within tip_radius and no
/// near field (its force depends on the mesh); kept for comparison in the benchmarks, not read from scenes.
enum class TipModel : int { kFootprint = 0, kNodes = 1 };

/// Laparoscopic tool through a trocar (5 DOF: pitch, yaw, insertion, roll, jaw).
struct ToolSpec {
  std::string name = "tool";    // unique in the scene; names the instrument in stats, logs and trajectories
  Eigen::Vector3d trocar = Eigen::Vector3d(0, 0, 0.2);   // m, fulcrum in world coordinates
  Eigen::Vector3d axis = Eigen::Vector3d(0, 0, -1);      // unit shaft direction (into the body) at pitch = yaw = 0
  double shaft_length = 0.35;    // m
  double shaft_radius = 0.0025;  // m, for drawing
  int shaft_points = 4;          // contact points along the shaft, tip first, 1..32
  double shaft_spacing = 0.01;   // m between contact points
  double jaw_length = 0.015;     // m
  double force_limit = 8.0;      // N, device force clamp
  int contact_capacity = 20;     // simultaneous contact nodes, 1..64 (ContactFrame bound)
  ContactModel contact_model = ContactModel::kPatch;
  double tip_radius = 0.0025;  // m, the tip's own radius (a 5 mm instrument), whatever the mesh
  TipModel tip_model = TipModel::kFootprint;
  double friction = 0;           // Coulomb coefficient mu >= 0 between tip and tissue (0: frictionless)
};

/// World-space geometry of the tool for one pose. Plain data, no allocation.
struct ToolGeometry {
  Eigen::Vector3d trocar;                                 // m
  Eigen::Vector3d direction;                              // unit, from trocar towards the tip
  Eigen::Vector3d tip;                                    // m
  Eigen::Vector3d jaw_normal;                             // unit, the jaws open in the plane (direction, jaw_normal)
  std::array<Eigen::Vector3d, 2> jaw_tips;                // m, ends of the two jaws
  int point_count = 0;                                    // contact points, tip first
  std::array<Eigen::Vector3d, kMaxShaftPoints> points;    // m
};

/// Computes the tool geometry. pitch rotates the base axis about the trocar frame's first normal, yaw about its
/// second normal; insertion is the tip's distance past the trocar; roll turns the jaw plane about the shaft.
ToolGeometry tool_geometry(const ToolSpec& spec, const Pose5& pose);

}  // namespace surgsim::tool
