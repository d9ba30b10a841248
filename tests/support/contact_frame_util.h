// Contact frames the visual node's tests hand to a liver view (as the haptic node would send them).
#pragma once
#include "surgsim_types.h"

namespace surgsim::testing {

/// One contact of instrument 0 on `node` with force (0, 0, lambda_z) N, and that instrument pressing down (direction
/// -z, insertion 0.1 m).
inline msg::ContactFrame press_frame(int node, double lambda_z) {
  msg::ContactFrame frame;
  msg::ContactEntry e;
  e.node(static_cast<std::uint32_t>(node));
  e.instrument(0);
  e.lambda().z(lambda_z);
  frame.contacts().push_back(e);
  msg::InstrumentState tool;
  tool.instrument(0);
  tool.direction().z(-1.0);
  tool.pose().insertion(0.1);
  frame.instruments().push_back(tool);
  return frame;
}

}  // namespace surgsim::testing
