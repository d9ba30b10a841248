// surgsim-web's DDS side: one participant that reads what the page shows (the visual node's JPEG Frames,
// one instrument's ForceFeedback, ContactFrame, SceneInfo, VisualStatus) and writes that instrument's ToolCommand.
// Listener callbacks run on DDS threads and only store the newest of each under a mutex; the web server reads
// snapshots from its own thread.
#pragma once
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "core/stats.h"
#include "dds_support.h"
#include "tool/trajectory.h"

namespace surgsim::web {

/// The newest frame as the WebSocket sends it: a 48-byte little-endian header then the JPEG (see www/app.js).
///   0 magic "SGF1" | 4 width u32 | 8 height u32 | 12 quality u32 | 16 frame_number u64 | 24 render_stamp_ns u64 |
///   32 haptic_stamp_ns u64 | 40 reserved (0) | 48.. JPEG
inline constexpr std::size_t kFrameHeaderBytes = 48;

/// What the page's plots and panels show, at one instant.
struct Telemetry {
  // ForceFeedback of the driven instrument.
  std::array<double, 3> force{0, 0, 0};  // N
  std::uint32_t force_flags = 0;         // msg::kFlag*
  std::uint64_t force_received = 0;
  std::uint64_t force_stamp_ns = 0;
  // ContactFrame.
  std::uint64_t contact_frames = 0;
  std::uint64_t contact_seq = 0;
  std::uint32_t contacts = 0;            // contact entries of the newest frame (every instrument)
  std::uint32_t instrument_contacts = 0; // the driven instrument's contact points
  double sim_time = 0;                   // s
  tool::Pose5 pose;                      // the driven instrument's pose as the haptic node used it
  // VisualStatus echoes: the haptic -> visual one-way latency of the newest echo (same host clocks), us.
  double haptic_visual_latency_us = -1;
  double visual_fps = 0;
  // SceneInfo.
  bool have_scene = false;
  std::string scene_name;
  std::uint64_t scene_hash = 0, mesh_hash = 0, material_hash = 0, tensor_hash = 0;
  std::uint32_t instrument_count = 0;
  double haptic_rate_hz = 0;
  std::string organs;                    // "name (model), ..." in the scene's order (SceneInfo.organs)
  // Frames.
  std::uint64_t frames_received = 0;
  std::uint64_t frame_number = 0;
  std::uint64_t frame_render_stamp_ns = 0;
};

class WebDds {
 public:
  /// Init: the participant, the five readers and the ToolCommand writer (throws std::runtime_error on a DDS failure).
  WebDds(const dds::DdsOptions& options, std::uint32_t instrument);
  ~WebDds();
  WebDds(const WebDds&) = delete;
  WebDds& operator=(const WebDds&) = delete;

  Telemetry telemetry();
  /// Called on the DDS thread after each new frame is stored (set before frames can arrive matters not: it is read
  /// under the mutex). The server posts the broadcast to its own thread from it.
  void set_frame_callback(std::function<void()> callback);
  /// The newest frame message (header + JPEG) when one arrived since `last_number`, else null.
  std::shared_ptr<const std::string> frame_since(std::uint64_t last_number);
  /// Publishes the driven instrument's ToolCommand (stamped now).
  void publish(const tool::Pose5& pose, std::uint64_t seq);
  /// Render -> received here (us, same-host clocks) of every frame so far.
  core::Percentiles frame_arrival_us();
  /// The render stamp of frame `number` when it is among the last frames received (0: unknown).
  std::uint64_t render_stamp_of(std::uint64_t number);
  const dds::Participant& participant() const;

 private:
  struct State;
  std::unique_ptr<State> s_;
};

}  // namespace surgsim::web
