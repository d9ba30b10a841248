// What one haptic tick of a contact model gives the loop, and what it takes from each instrument: plain data shared
// by the contact models (contact/tool_contacts.h), the organs of the haptic node and its force stage.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>

#include "tool/tool.h"

namespace surgsim::contact {

/// What one tick of an organ gives the loop.
struct ContactTick {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();         // N, on the tool, after the organ's force law
  Eigen::Vector3d device_force = Eigen::Vector3d::Zero();  // N, clamped to the device limit, always finite
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();     // unit mean imposed displacement (0 without contact)
  bool saturated = false;
  bool over_capacity = false;
  bool nonfinite = false;  // a non-finite value was refused this tick (force zeroed)
  bool grasp = false;
  int points_in_contact = 0;  // tool points (liver) or body elements (intestine) the tool touches
};

/// One instrument's input for a tick (an organ is stepped with every instrument of the scene at once).
struct InstrumentInput {
  const tool::ToolGeometry* tool = nullptr;  // the instrument's geometry, or null while its device input is lost
  double jaw = 0;                            // rad, jaw opening
};

/// The stages of one contact step, in their order (as mj_fwdPosition is a list of stage calls). The triangle model
/// runs them too (it has no friction stage).
enum class ContactStage : int {
  kTrackPoints = 0,       // each tool point against the rest surface: tracking, crossing, grasps closing and opening
  kBuildPatches = 1,      // one patch (or triangle) per contact: its nodes, weights, rows and imposed values
  kSolveActiveSet = 2,    // the constrained solve; unilateral contacts that pull let go one at a time
  kFriction = 3,          // Coulomb: sticking patches beyond their cone slide
  kDistributeForces = 4,  // node forces, each point's and each instrument's force, the law and the device clamp
};
inline constexpr int kContactStages = 5;
/// Column names of the stages (the --tick-trace columns, suffixed _us).
inline constexpr std::array<const char*, kContactStages> kContactStageNames = {"track_points", "build_patches",
                                                                               "solve_active_set", "friction",
                                                                               "distribute_forces"};
/// The time each stage took in the last step (ns; 0: the stage did not run).
struct ContactStageTimes {
  std::array<std::uint32_t, kContactStages> ns{};
};

}  // namespace surgsim::contact
