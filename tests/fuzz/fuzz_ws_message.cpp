// Fuzz target: a page's WebSocket message to surgsim-web (visual_node/web/web_logic.cpp, parse_client_message),
// then what the server does with a pose: clamped to the device's range and stepped towards from the start pose.
// Expected: none. A malformed message is refused by returning false, never thrown, so any exception escaping is a
// finding (see fuzz_support.h); so is a non-finite pose leaving the clamp or the step.
#include <cmath>
#include <cstdlib>

#include "fuzz_support.h"
#include "web_logic.h"

namespace {

bool finite(const surgsim::tool::Pose5& p) {
  return std::isfinite(p.pitch) && std::isfinite(p.yaw) && std::isfinite(p.insertion) && std::isfinite(p.roll) &&
         std::isfinite(p.jaw);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim::web;
  ClientMessage m;
  std::string error;
  if (!parse_client_message(surgsim::fuzz::as_text(data, size), m, error)) return 0;
  if (m.type == ClientMessage::Type::kPose) {
    const DeviceLimits limits;
    const surgsim::tool::Pose5 target = clamp_pose(m.pose, limits);
    const surgsim::tool::Pose5 next = step_towards(surgsim::tool::Pose5{}, target, limits, 0.005);
    if (!finite(target) || !finite(next)) std::abort();  // the device would be sent a non-finite pose
  }
  return 0;
}
