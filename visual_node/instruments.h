// The instruments the visual node draws (two or more instruments on one organ). A ContactFrame (and for the
// intestine a BodyState) carries one InstrumentState per instrument of the scene, by its index in scene.tools; the
// node takes each state whose index names a tool of its scene (the others are ignored and counted) and draws every
// instrument i with scene.tools[i]: its geometry at the received pose (tool_geometry), its own shaft radius and its
// own colour (instrument_rgb(i), so the instruments are told apart in a picture).
//
// Phases: everything here is run phase (per frame): no allocation, no exception.
#pragma once
#include <Eigen/Core>
#include <array>
#include <vector>

#include "tool/tool.h"

namespace surgsim {

namespace msg {
namespace v3 {
class InstrumentState;
}  // namespace v3
using namespace v3;  // NOLINT: the wire version in use (idl/surgsim_types.h)
}  // namespace msg
class Renderer;

/// The instruments of one received frame, by index in the scene's tools list.
struct InstrumentPoses {
  InstrumentPoses() { direction.fill(Eigen::Vector3d::Zero()); }

  std::array<bool, tool::kMaxInstruments> present{};  // the frame carried a state for instrument i
  std::array<tool::Pose5, tool::kMaxInstruments> pose{};
  /// Unit mean imposed displacement of its contacts (the non-linear law's axis; zero: none).
  std::array<Eigen::Vector3d, tool::kMaxInstruments> direction;
  int ignored = 0;  // states of the frame naming no tool of the scene (index >= tools) or an instrument twice

  int count() const {
    int n = 0;
    for (bool p : present) n += p ? 1 : 0;
    return n;
  }
};

/// The poses and directions of `states` (a frame's instruments) for a scene with `tools` instruments: instrument i
/// for each state whose index i < tools (the first state of an index; a repeated one and out-of-range ones are
/// ignored and counted in out.ignored). Instruments without a state are absent.
void take_instruments(const std::vector<msg::InstrumentState>& states, int tools, InstrumentPoses& out) noexcept;

/// Draws every present instrument i < tools.size() with tools[i]: tool_geometry(tools[i], pose[i]), its shaft radius,
/// colour instrument_rgb(i). Returns the number of draw_tool calls.
int draw_instruments(Renderer& renderer, const std::vector<tool::ToolSpec>& tools,
                     const InstrumentPoses& poses) noexcept;

}  // namespace surgsim
