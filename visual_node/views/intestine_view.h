// The intestine scene in the visual node (docs/DESIGN.md, section 'Intestine rendering'): the newest BodyState from the
// haptic node drawn as a generalized cylinder around the intestine's points (cardinal spline, curvature-refined
// samples, rotation-minimizing frames, two-matrix skinning of a cylinder primitive: TubeBuilder) and the mesentery as
// a membrane over the whole grid, with the tube's level of detail chosen by the guaranteed-frame-rate controller
// (paper eq. 15). A liver scene never builds one, and an intestine scene loads no tetrahedral mesh and no tensors.
//
// Skinning (TubeSkinning, --tube-skinning in the visual node) runs by default on the GPU: the builder makes only the
// per-interval matrices (TubeMesh::skin) and Renderer::draw_skinned_tube sends them, the cylinder primitive of each
// LOD (TubeBuilder::primitive, both end caps included) being uploaded once; the vertex shader does the two-matrix
// blend. With TubeSkinning::kCpu the builder writes the skinned vertices and the tube is drawn as a triangle surface
// (draw_surface: normals recomputed from the positions), as before. Spline, RMF, ring guard and caps' frames are
// the same CPU code in both (the matrices come from the same build). tests/bench/tube_skinning_bench prints the
// frame time of both per LOD.
//
// The picture: the mesentery is drawn as a smooth surface, the mass-spring grid refined by a bicubic
// Catmull-Rom patch (intestine::MesenterySurface, kMesenteryRowSteps x kMesenteryColSteps vertices per grid cell,
// analytic per-vertex normals) in translucent pinkish-yellow fat with its vessels drawn by the shader
// (Renderer::draw_membrane); the tube in glossy pink-red (kIntestineLook) with its rounded ends; behind them a dark
// abdominal backdrop (Renderer::draw_backdrop). The tube is drawn before the membrane so that it shows through it.
// The refinement is fixed (the frame-rate controller drives the tube's LOD only): about 0.1 ms of CPU per build.
//
// The controller is fed with each frame's work time (update + draw + end_frame, not the pacing sleep): the LOD is the
// finest whose work still allows the target rate (visual.target_fps; visual.rate_hz when 0), so the displayed rate
// (visual.rate_hz) holds with the margin the target leaves.
//
// Phases: construction allocates everything (tube meshes for the finest LOD, the mesentery's triangles, the
// BodyState sample); update(), set_positions(), frame_done() allocate nothing; stats() is for shutdown.
//
// IntestineOrganView is the intestine behind the visual node's OrganView (organ_view.h): an IntestineView, the
// fallback to CPU skinning when the renderer has none, the BodyState subscription, the intestine's stats and lines.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/stats.h"
#include "dds_support.h"
#include "instruments.h"
#include "intestine/frame_rate_controller.h"
#include "intestine/tube_geometry.h"
#include "organ_view.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace surgsim {

class BodyStateListener;

/// Colours, display RGB in [0, 1].
inline const Eigen::Vector3f kIntestineRgb(0.86f, 0.45f, 0.44f);  // pink bowel wall
inline const Eigen::Vector3f kMesenteryRgb(0.96f, 0.80f, 0.60f);  // pinkish-yellow fat
/// The bowel wall is wet serosa: a glossy highlight.
inline const SurfaceLook kIntestineLook{kIntestineRgb, 0.55f, 60.0f};
/// The mesentery: translucent fat over dark red vessels.
inline const MembraneLook kMesenteryLook{kMesenteryRgb, Eigen::Vector3f(0.55f, 0.13f, 0.14f), 0.80f, 1.0f, 0.30f,
                                         30.0f};
/// The abdominal cavity behind: dark red-brown in the middle of the image, nearly black in its corners.
inline const Eigen::Vector3f kCavityCentreRgb(0.30f, 0.13f, 0.11f);
inline const Eigen::Vector3f kCavityEdgeRgb(0.05f, 0.025f, 0.025f);
/// Vertices per mass-spring grid cell of the drawn mesentery: across the membrane and along the intestine.
constexpr int kMesenteryRowSteps = 3;
constexpr int kMesenteryColSteps = 2;

class IntestineView {
 public:
  /// Init (allocates; throws surgsim::core::Error on bad parameters): the tube builder for scene.intestine's columns,
  /// the meshes at the finest LOD, the mesentery's refined surface, the frame-rate controller. BodyStates whose scene
  /// hash differs from `scene_hash` are refused.
  IntestineView(const scene::Scene& scene, std::uint64_t scene_hash,
                intestine::TubeSkinning skinning = intestine::TubeSkinning::kGpu);
  ~IntestineView();
  IntestineView(const IntestineView&) = delete;
  IntestineView& operator=(const IntestineView&) = delete;

  /// Init: where the tube is skinned from now on (e.g. kCpu when the renderer has no GPU skinning).
  void set_skinning(intestine::TubeSkinning skinning) noexcept;
  intestine::TubeSkinning skinning() const { return skinning_; }

  /// Init: the BodyState reader (stream profile: best effort, keep last 1; the listener keeps the newest of organ
  /// `organ`, BodyState's key: the intestine's index in the scene's organs list, 0 in a one-organ scene).
  void subscribe(dds::Participant& participant, int organ = 0);

  /// Per frame, no allocation: takes the newest BodyState when there is a newer one (its positions and its
  /// instruments, the probes at the body's tick), and rebuilds the tube and the mesentery when the body or the
  /// controller's LOD changed. True when a new body state was taken.
  bool update() noexcept;
  /// The same from positions (tests, no DDS): `count` points (x, y, z; m), node (r, c) at r columns + c, and when
  /// given the instruments of that state. False (and the previous shape and instruments kept) on a wrong count or a
  /// non-finite value.
  bool set_positions(const double* xyz, int count, const InstrumentPoses* instruments = nullptr) noexcept;

  /// The instruments of the shown body state (none present before one that carried them).
  const InstrumentPoses& instruments() const { return instruments_; }

  /// Draws (once a body state came) the tube, the backdrop, then the translucent mesentery over both.
  void draw(Renderer& renderer) const;
  /// Feeds the frame-rate controller with this frame's work time (s); the next update() uses the LOD it returns.
  void frame_done(double work_seconds) noexcept;

  int lod() const { return controller_.lod(); }
  bool has_body() const { return have_body_; }
  std::uint64_t states_received() const { return states_received_; }
  std::uint64_t last_seq() const { return last_seq_; }
  int tube_vertices() const { return tube_.vertex_count; }  // caps included; drawn by either path
  int tube_triangles() const { return tube_.index_count / 3; }
  const Eigen::MatrixX3f& tube_positions() const { return tube_positions_; }  // first tube_vertices() rows (kCpu only)
  const intestine::TubeMesh& tube() const { return tube_; }  // counts and matrices; vertices with kCpu only
  const intestine::TubePrimitive& tube_primitive() const { return builder_.primitive(tube_.lod); }
  const intestine::FrameRateController& controller() const { return controller_; }
  const intestine::MesenterySurface& mesentery() const { return mesentery_; }  // the drawn surface

  /// Shutdown: states, LOD histogram and mean, the controller's target, work and build times, tube sizes.
  nlohmann::json stats() const;

 private:
  bool accept(const double* xyz, int count, const InstrumentPoses* instruments) noexcept;
  void rebuild(int lod) noexcept;

  int rows_ = 0, cols_ = 0;
  int tools_ = 1;  // the scene's instruments
  SurfaceLook look_ = kIntestineLook;  // the tube's: the organ's colour (organ_rgb), wet
  std::uint64_t scene_hash_ = 0;
  double target_fps_ = 0;
  std::vector<double> points_;  // 3 rows cols, the shown body state
  intestine::TubeBuilder builder_;
  intestine::TubeMesh tube_;
  intestine::MesenterySurface mesentery_;
  intestine::FrameRateController controller_;
  // What the renderer draws (column-major copies, sized for the finest LOD).
  Eigen::MatrixX3f tube_positions_;
  Eigen::MatrixX3i tube_tris_;
  int built_lod_ = -1;
  bool have_body_ = false;
  intestine::TubeSkinning skinning_ = intestine::TubeSkinning::kGpu;

  std::unique_ptr<BodyStateListener> listener_;
  std::vector<double> incoming_;  // 3 x kMaxBodyPoints, the listener's newest copied out under its lock
  InstrumentPoses incoming_instruments_;  // its instruments
  InstrumentPoses instruments_;           // those of the shown body state

  // Statistics (fixed storage).
  std::uint64_t states_received_ = 0;
  std::uint64_t states_shown_ = 0;
  std::uint64_t states_rejected_ = 0;  // another scene's hash, a wrong point count or a non-finite value
  std::uint64_t instrument_states_ignored_ = 0;  // instrument states of shown body states naming no tool of the scene
  std::uint64_t build_failures_ = 0;
  std::uint64_t last_seq_ = 0;
  std::array<std::uint64_t, intestine::kTubeMaxLod + 1> lod_frames_{};
  core::SampleRecorder work_ms_{1 << 18};
  core::SampleRecorder build_us_{1 << 18};
  int tube_vertices_max_ = 0;
  int tube_triangles_max_ = 0;
};

/// The intestine as the visual node's organ: the frame loop's update() takes the newest BodyState (contact frames do
/// not deform it), the instruments drawn are the probes that BodyState carries (in step with the body), the
/// frame-rate controller gets each frame's work time.
class IntestineOrganView : public OrganView {
 public:
  /// Init: see IntestineView (no mesh, no tensors); `organ` is the intestine's index in the scene's organs list (the
  /// BodyStates drawn are that organ's).
  IntestineOrganView(const scene::Scene& scene, std::uint64_t scene_hash, intestine::TubeSkinning skinning,
                     int organ = 0);

  /// Skins the tube on the CPU when the renderer cannot on the GPU (says so on stderr).
  void attach(const Renderer& renderer) override;
  void subscribe(dds::Participant& participant) override { view_.subscribe(participant, organ_); }
  void print_init(std::ostream& out) const override;

  /// The newest BodyState as tube and mesentery, at the LOD the frame-rate controller chose; the time of a frame that
  /// took a new body state is its deformation time.
  double update(const msg::ContactFrame* frame, bool fresh) noexcept override;
  void draw(Renderer& renderer) const override { view_.draw(renderer); }
  /// After the other organs: its translucent mesentery blends over what they drew.
  double draw_depth(const Eigen::Vector3d&) const override { return 2e9; }
  /// The instruments of the shown body state once one carried any (else null: those of the contact frame).
  const InstrumentPoses* instruments() const override {
    return view_.has_body() && view_.instruments().count() > 0 ? &view_.instruments() : nullptr;
  }
  void frame_done(double work_seconds) noexcept override { view_.frame_done(work_seconds); }
  std::uint32_t lod() const override { return static_cast<std::uint32_t>(view_.lod()); }

  /// "model_built", "intestine" (IntestineView::stats), "lod_mean", "lod_target_fps".
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out, const nlohmann::json& stats) const override;

  const IntestineView& view() const { return view_; }
  IntestineView& view() { return view_; }  // tests: a body state without DDS (IntestineView::set_positions)

 private:
  IntestineView view_;
  int organ_ = 0;
};

}  // namespace surgsim
