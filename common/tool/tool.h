// Laparoscopic tool kinematics: 5-DOF pose about a trocar -> shaft direction, tip, contact points, jaws.
#pragma once
#include <Eigen/Core>
#include <array>
#include <string>

#include "tool/trajectory.h"

namespace surgsim::tool {

constexpr int kMaxShaftPoints = 32;

/// How a liver contact is imposed on the organ: `patch` (default) spreads one constraint along the surface
/// normal (frictionless) or a sticking 3-D constraint (friction, grasp) over every free surface node within
/// tip_radius of the contact point with smooth weights; `triangle` is the paper's distribution of the contact
/// displacement over the three vertices of the touched triangle (alpha_v d, all three components imposed).
enum class ContactModel : int { kPatch = 0, kTriangle = 1 };

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
  double tip_radius = 0;         // m, radius of the patch contact; 0: 2.5 x the organ's mean surface edge
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
