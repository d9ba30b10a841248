// What one haptic tick of a contact model gives the loop, and what it takes from each instrument: plain data shared
// by the contact models (contact/tool_contacts.h), the organs of the haptic node and its force stage.
#pragma once
#include <Eigen/Core>

#include "tool/tool.h"

namespace surgsim::contact {

/// What one tick of an organ gives the loop.
struct ContactTick {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();         // N, on the tool, after the organ's force law
  Eigen::Vector3d device_force = Eigen::Vector3d::Zero();  // N, clamped to the device limit, always finite
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();     // unit mean imposed displacement (0 without contact)
  bool saturated = false;
  bool over_capacity = false;
  bool nonfinite = false;      // a non-finite value was refused this tick (force zeroed)
  bool grasp = false;
  int points_in_contact = 0;   // tool points (liver) or body elements (intestine) the tool touches
};

/// One instrument's input for a tick (issue 19: an organ is stepped with every instrument of the scene at once).
struct InstrumentInput {
  const tool::ToolGeometry* tool = nullptr;  // the instrument's geometry, or null while its device input is lost
  double jaw = 0;                      // rad, jaw opening
};

}  // namespace surgsim::contact
