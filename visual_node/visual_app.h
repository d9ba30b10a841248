// The visual node: init (scene, mesh, renderer, DDS), run (frame-paced loop drawing the newest contact frame),
// shutdown (video, stats).
#pragma once
#include <array>
#include <atomic>
#include <cstdio>
#include <cstdint>
#include <memory>
#include <string>

#include "haptic_watch.h"
#include "image.h"
#include "mesh/mesh.h"
#include "liver/precompute.h"
#include "liver/nonlinear_law.h"
#include "surface_deformer.h"
#include "scene/scene.h"
#include "core/stats.h"

namespace surgsim {

class Renderer;
class IntestineView;

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
  struct Dds;

  VisualOptions options_;
  std::string dds_threads_note_;            // how the DDS threads are scheduled (stats "dds_threads")
  Scene scene_;
  TetMesh mesh_;
  SurfaceMesh surface_;
  std::uint64_t scene_hash_ = 0;
  std::uint64_t tensor_hash_ = 0;
  Tensors tensors_;                         // "visual" block only (no interior rows)
  std::unique_ptr<NonlinearLaw> law_;
  std::unique_ptr<SurfaceDeformer> deformer_;    // liver-type scenes only
  std::unique_ptr<IntestineView> intestine_;     // model "intestine" only (then no mesh, tensors or deformer_)
  std::FILE* index_ = nullptr;              // frames.csv: which contact frame each PNG shows
  std::array<int, 64> contact_nodes_{};
  std::array<Eigen::Vector3d, 64> contact_lambda_{};
  Eigen::MatrixX3f markers_;                // contact points drawn as markers
  std::uint64_t deform_errors_ = 0;
  std::uint64_t vtk_written_ = 0;
  std::unique_ptr<Renderer> renderer_;
  HapticWatch watch_;                       // built before the constructor body: its clock origin is the node's start
  std::unique_ptr<Dds> dds_;
  std::atomic<bool> stop_requested_{false};

  double rate_hz_ = 50;
  int png_every_ = 5;
  std::uint64_t frames_rendered_ = 0;
  std::uint64_t pngs_written_ = 0;
  std::uint64_t png_errors_ = 0;
  Image image_;  // read-back buffer, reused every frame
  double wall_seconds_ = 0;
  SampleRecorder deform_us_{1 << 18};
  SampleRecorder render_ms_{1 << 18};
  std::string video_;            // path of the MP4 written, or why not
  std::string first_png_;
  std::string last_png_;
};

}  // namespace surgsim
