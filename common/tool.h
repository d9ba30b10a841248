// Laparoscopic tool kinematics: 5-DOF pose about a trocar -> shaft direction, tip, contact points, jaws.
#pragma once
#include <Eigen/Core>
#include <array>

#include "scene.h"
#include "trajectory.h"

namespace surgsim {

constexpr int kMaxShaftPoints = 32;

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

}  // namespace surgsim
