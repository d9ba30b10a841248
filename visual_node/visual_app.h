// The visual node: init (scene, organ view, renderer, frame output, DDS), run (frame-paced loop drawing the newest
// contact frame), shutdown (video, stats). The organ is behind OrganView (organ_view.h): nothing here depends on
// which model the scene uses.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "core/stats.h"
#include "frame_rate.h"
#include "haptic_watch.h"
#include "instruments.h"
#include "render/image.h"
#include "scene/scene.h"

namespace surgsim {

namespace msg {
namespace v2 {
class ContactFrame;
}  // namespace v2
using namespace v2;  // NOLINT: the wire version in use (idl/surgsim_types.h)
}
class FrameOutput;
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
  /// Deformation, drawing (the organ, every instrument, the markers) and the PNG of one frame: `frame` is the newest
  /// frame taken (shown when `have_frame`), `fresh` when it arrived since the last one.
  void render_frame(const msg::ContactFrame& frame, bool have_frame, bool fresh);

  VisualOptions options_;
  std::string dds_threads_note_;            // how the DDS threads are scheduled (stats "dds_threads")
  Scene scene_;
  std::unique_ptr<OrganView> organ_;        // the scene's organ (organ_view.h); the only organ-specific part
  std::uint64_t scene_hash_ = 0;
  std::unique_ptr<Renderer> renderer_;
  std::unique_ptr<FrameOutput> output_;     // PNG, frames.csv, VTK, video
  HapticWatch watch_;                       // built before the constructor body: its clock origin is the node's start
  std::unique_ptr<VisualDds> dds_;
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
  Image image_;  // read-back buffer, reused every frame
  double wall_seconds_ = 0;
  SampleRecorder deform_us_{1 << 18};
  SampleRecorder render_ms_{1 << 18};
};

}  // namespace surgsim
