// The visual node's DDS entities: the participant, the ContactFrame reader (newest frame of this node's scene kept,
// frames of another scene_hash counted and dropped, one-way latency,
// each frame's stamp echoed at once on VisualStatus so the haptic node measures the round trip on its own clock,
// deadline and liveliness to the HapticWatch), the latched SceneInfo reader and the VisualStatus writer.
// Listener callbacks run on DDS threads; every method here is safe to call from the frame loop meanwhile.
#pragma once
#include <cstdint>
#include <memory>

#include "surgsim_types.h"
#include "core/stats.h"
#include "dds_support.h"

namespace surgsim {

class HapticWatch;

class VisualDds {
 public:
  /// Init: creates the participant, the readers and the writer (throws on a DDS failure). The caller sets the
  /// scheduling of the DDS threads around this (they start here). `watch` must outlive this object. `scene_hash`:
  /// this node's scene identity (visual_scene_hash); contact frames carrying another are never kept.
  VisualDds(const dds::DdsOptions& options, HapticWatch& watch, std::uint64_t scene_hash);
  ~VisualDds();
  VisualDds(const VisualDds&) = delete;
  VisualDds& operator=(const VisualDds&) = delete;

  dds::Participant& participant();

  /// Copies the newest contact frame of this scene if one arrived since the last call (true then); `received` is set
  /// to the count of frames received so far (any scene). No allocation.
  bool newest_frame(msg::ContactFrame& out, std::uint64_t& received);
  std::uint64_t frames_received();  // every valid frame
  std::uint64_t frames_accepted();  // frames of this scene
  /// Frames whose scene_hash was not this node's (dropped); `last_hash` is the newest such hash (0: none).
  std::uint64_t frames_wrong_scene(std::uint64_t& last_hash);
  std::uint64_t last_receive_ns();  // monotonic, of the newest frame (0: none yet)
  core::Percentiles latency();      // one-way, us (same-host clocks)

  /// The haptic node's SceneInfo when one was received (copied into `out`; true then).
  bool scene_info(msg::SceneInfo& out);

  /// Publishes this node's VisualStatus (stamped now; the round trip is echoed on frame arrival, not here).
  void publish_status(double fps, std::uint32_t lod, std::uint64_t last_seq_shown, std::uint64_t frames_rendered);

 private:
  struct State;
  std::unique_ptr<State> s_;
};

}  // namespace surgsim
