// The visual node: init (scene, organ view, renderer, frame output, DDS), run (frame-paced loop drawing the newest
// contact frame), shutdown (video, stats). The organ is behind OrganView (organ_view.h): nothing here depends on
// which model the scene uses.
//
// Pacing: frame k is due at start + k / rate; a frame that ends late by less than one period starts the next one at
// once (the schedule catches up, so an occasional slow frame, e.g. a PNG, does not lower the mean rate), one later
// than that restarts the schedule from now (no burst of frames after a stall).
//
// Frame trace: one row per frame, written at shutdown to OUT/frame_trace.csv (--out; nothing when
// headless): the time since the first frame shown, the LOD drawn, the frame's work (organ update, draw, end_frame: what
// the LOD controller is fed, the pacing sleep and the PNG excluded), the interval since the previous frame, the
// measured rate (1 s window) and whether the synthetic load is on. Rows are preallocated (kTraceCapacity); later
// frames are counted, not kept.
//
// Synthetic load (for showing the controller live around a load change): SURGSIM_VISUAL_LOAD_STEP=AT:FOR:X
// makes every frame's work X times longer (a busy wait of (X - 1) x its measured work, counted as work) from AT s
// after the first frame shown, for FOR s. Unset: no extra load.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "core/stats.h"
#include "frame_rate.h"
#include "haptic_watch.h"
#include "instruments.h"
#include "render/image.h"
#include "render/render_scale.h"
#include "scene/scene.h"

namespace surgsim {

namespace msg {
namespace v3 {
class ContactFrame;
}  // namespace v3
using namespace v3;  // NOLINT: the wire version in use (idl/surgsim_types.h)
}
class FrameOutput;
class FrameStream;
class OrganView;
class Renderer;
class VisualDds;

struct VisualOptions {
  std::string scene = "liver";
  double duration = -1;          // s of wall time; < 0: until stopped (SIGINT/SIGTERM) or idle exit
  double idle_exit = 0;          // s without frames, after some were received, before exiting (0 = never)
  std::string out = "out/frames";  // PNG / VTK output folder
  bool headless = false;         // null renderer: no GL context
  std::string stats;
  std::string cache_dir;
  int domain = -1;
  std::string dds_profiles;
  std::string dds_participant;   // empty: $SURGSIM_DDS_PARTICIPANT, else surgsim_default
  double rate_hz = 0;            // > 0 overrides the scene's visual rate
  int png_every = -1;            // >= 0 overrides the scene's png_every
  bool video = false;            // assemble out/video.mp4 with ffmpeg at exit (also when the scene asks)
  std::string tube_skinning = "gpu";  // intestine tube: "gpu" (vertex shader) or "cpu" (skinned vertices uploaded)
  int dds_rt_priority = 20;      // SCHED_FIFO priority of the DDS threads (receive, events); 0 = normal scheduling
  double stream_fps = -1;        // >= 0 overrides the scene's visual.stream_fps (JPEG frames on surgsim/frame; 0 = off)
  int stream_quality = -1;       // 1..100 overrides the scene's visual.stream_quality
  bool quiet = false;
};

class VisualApp {
 public:
  explicit VisualApp(const VisualOptions& options);
  ~VisualApp();
  VisualApp(const VisualApp&) = delete;
  VisualApp& operator=(const VisualApp&) = delete;

  int run();
  void stop() { stop_requested_.store(true, std::memory_order_relaxed); }
  void shutdown();

 private:
  /// Once the haptic side's SceneInfo is known: whether it runs this scene with the same tensors and as many
  /// instruments as the scene's tools (else frames are ignored, one stderr line says why, and run() returns 3).
  /// Until it is known no contact frame is taken: the newest one waits in VisualDds.
  void check_scene_identity();
  /// One stderr line per foreign scene hash seen on contact frames (those frames are dropped by VisualDds).
  void report_wrong_scene();
  /// The instruments of a fresh contact frame (instruments_); states naming no instrument of the scene are counted
  /// and the first such frame is named on stderr.
  void take_frame_instruments(const msg::ContactFrame& frame);
  /// Init: the frame stream of the web view when asked (visual.stream_fps or --stream-fps), writing surgsim/frame.
  void start_stream();
  /// When a streamed picture is due at `now` (the frame's end) and the encoder is idle: the picture read into its
  /// slot (copied from `read`, this frame's picture when already read back for the PNG) and handed over.
  void offer_stream_frame(const msg::ContactFrame& frame, bool have_frame, std::uint64_t now, const Image* read);
  /// Deformation, drawing (the organ, every instrument, the markers) and the PNG of one frame: `frame` is the newest
  /// frame taken (shown when `have_frame`), `fresh` when it arrived since the last one.
  void render_frame(const msg::ContactFrame& frame, bool have_frame, bool fresh);

  /// One row of the frame trace.
  struct TraceRow {
    double t_s;          // since the first frame shown (negative before it)
    double work_ms;      // update + draw + end_frame (+ the synthetic load)
    double interval_ms;  // since the previous frame ended
    double fps;          // FrameRateMeter, 1 s window
    int lod;             // the organ's LOD drawn (0 for organs without one)
    bool load_on;        // the synthetic load was on
    double scale;        // the render scale it was drawn at (1: full size; visual.min_render_scale)
  };
  static constexpr std::size_t kTraceCapacity = 1 << 16;  // 36 min at 30 Hz
  void write_trace(nlohmann::json& stats) const;

  VisualOptions options_;
  std::string dds_threads_note_;            // how the DDS threads are scheduled (stats "dds_threads")
  scene::Scene scene_;
  std::unique_ptr<OrganView> organ_;        // the scene's organ (organ_view.h); the only organ-specific part
  std::uint64_t scene_hash_ = 0;
  std::unique_ptr<Renderer> renderer_;
  std::unique_ptr<FrameOutput> output_;     // PNG, frames.csv, VTK, video
  HapticWatch watch_;                       // built before the constructor body: its clock origin is the node's start
  std::unique_ptr<VisualDds> dds_;
  std::unique_ptr<FrameStream> stream_;     // the web view's JPEG frames (null when off)
  double stream_fps_ = 0;
  std::uint64_t next_stream_ns_ = 0;        // the next streamed picture is due then (monotonic)
  std::atomic<bool> stop_requested_{false};

  double rate_hz_ = 50;
  bool hash_checked_ = false;
  bool hash_ok_ = true;
  bool scene_confirmed_ = false;                 // SceneInfo received and matching: frames may be drawn
  std::uint64_t frames_before_scene_info_ = 0;   // frames of this scene received before the confirmation
  std::uint64_t frames_shown_ = 0;               // fresh frames handed to the organ
  std::uint64_t wrong_scene_reported_hash_ = 0;  // the foreign hash last named on stderr
  std::uint64_t frames_rendered_ = 0;
  InstrumentPoses instruments_;                   // of the newest contact frame taken
  std::uint64_t instrument_states_ignored_ = 0;   // InstrumentStates naming no instrument of the scene (or repeated)
  bool instrument_states_reported_ = false;       // the first such frame was named on stderr
  FrameRateMeter frame_rate_;                    // measured rate, sent as VisualStatus.fps
  RenderScaleController render_scale_{RenderScaleParams{}};  // dynamic resolution (off unless the scene asks)
  Image image_;  // read-back buffer, reused every frame
  double wall_seconds_ = 0;
  core::SampleRecorder deform_us_{1 << 18};
  core::SampleRecorder render_ms_{1 << 18};
  core::SampleRecorder interval_ms_{1 << 18};     // between frame ends
  std::uint64_t frames_late_ = 0;                 // ended after the next frame was due
  std::uint64_t schedule_restarts_ = 0;           // frames that ended more than a period late: schedule reset
  // Synthetic load (SURGSIM_VISUAL_LOAD_STEP) and the frame trace.
  double load_at_s_ = -1, load_for_s_ = 0, load_factor_ = 1;
  std::uint64_t first_shown_ns_ = 0;              // the first fresh frame (0 before)
  double last_work_ms_ = 0;
  double drawn_scale_ = 1.0;  // the render scale of the frame drawn last
  bool last_load_on_ = false;
  std::uint64_t last_frame_end_ns_ = 0;
  std::vector<TraceRow> trace_;                   // reserved kTraceCapacity rows at init
  std::uint64_t trace_dropped_ = 0;
};

}  // namespace surgsim
