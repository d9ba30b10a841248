#include "instruments.h"

#include <algorithm>

#include "render/renderer.h"
#include "surgsim_types.h"

using namespace surgsim::tool;

namespace surgsim {

void take_instruments(const std::vector<msg::InstrumentState>& states, int tools, InstrumentPoses& out) noexcept {
  out.present.fill(false);
  out.direction.fill(Eigen::Vector3d::Zero());
  out.ignored = 0;
  const int n = std::clamp(tools, 0, kMaxInstruments);
  for (const msg::InstrumentState& s : states) {
    const std::uint32_t i = s.instrument();
    if (i >= static_cast<std::uint32_t>(n) || out.present[i]) {
      ++out.ignored;
      continue;
    }
    out.present[i] = true;
    Pose5& p = out.pose[i];
    p.pitch = s.pose().pitch();
    p.yaw = s.pose().yaw();
    p.insertion = s.pose().insertion();
    p.roll = s.pose().roll();
    p.jaw = s.pose().jaw();
    out.direction[i] = Eigen::Vector3d(s.direction().x(), s.direction().y(), s.direction().z());
  }
}

int draw_instruments(Renderer& renderer, const std::vector<ToolSpec>& tools, const InstrumentPoses& poses) noexcept {
  int drawn = 0;
  const int n = std::min(static_cast<int>(tools.size()), kMaxInstruments);
  for (int i = 0; i < n; ++i) {
    if (!poses.present[static_cast<std::size_t>(i)]) continue;
    const ToolSpec& spec = tools[static_cast<std::size_t>(i)];
    renderer.draw_tool(tool_geometry(spec, poses.pose[static_cast<std::size_t>(i)]),
                       static_cast<float>(spec.shaft_radius), instrument_rgb(i));
    ++drawn;
  }
  return drawn;
}

}  // namespace surgsim
