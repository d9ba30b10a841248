// What the visual node draws for one organ (one organ interface per node). The app (visual_app.h) knows
// only this interface: it receives contact frames, paces the loop, draws the instruments and writes the outputs;
// everything that depends on the organ model is behind an OrganView. make_organ_view() is the only place that looks
// at scene.model: adding an organ is one implementation (visual_node/views/) and one line there.
//
// Implementations: LiverView (views/liver_view.h: the visual rows of the precomputed tensors, the non-linear law,
// the deformed boundary or an embedded finer surface, contact markers) and IntestineOrganView
// (views/intestine_view.h: the newest BodyState as tube and mesentery, LOD by the frame-rate controller).
//
// Phases as in the app: construction and the init hooks (attach, subscribe, print_init) may allocate and throw
// surgsim::core::Error; update, draw, draw_markers, frame_done run every frame and allocate nothing; the rest is for
// the frame output (write_vtk, with a PNG) and shutdown (stats).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "intestine/tube_geometry.h"
#include "scene/scene.h"

namespace surgsim {

namespace dds {
class Participant;
}
namespace msg {
namespace v3 {
class ContactFrame;
}  // namespace v3
using namespace v3;  // NOLINT: the wire version in use (idl/surgsim_types.h)
}
class Renderer;
struct InstrumentPoses;

class OrganView {
 public:
  virtual ~OrganView() = default;

  /// Hash of the organ's mesh, mixed into the scene identity both nodes compare (0: no tetrahedral mesh).
  virtual std::uint64_t mesh_hash() const { return 0; }
  /// Identity of the tensors this view loaded (SceneInfo.tensor_hash of the haptic node; 0: none).
  virtual std::uint64_t tensor_hash() const { return 0; }
  /// Triangles of the drawn organ surface known at init (the start-up line; 0 when built per frame).
  virtual long surface_triangles() const { return 0; }

  /// Init, once the renderer exists: adapts to what it can do (e.g. the intestine falls back to CPU skinning).
  virtual void attach(const Renderer&) {}
  /// Init, with the DDS participant (the app's DDS threads priority still in effect): extra topics.
  virtual void subscribe(dds::Participant&) {}
  /// Init: extra start-up lines (not called with --quiet).
  virtual void print_init(std::ostream&) const {}

  /// Per frame, before drawing. `frame`: the newest contact frame shown (null before the first); `fresh`: it arrived
  /// since the last call (and belongs to this scene). Returns the deformation time (us) when the organ did
  /// deformation work this frame (stats "deform_us"), else a negative value.
  virtual double update(const msg::ContactFrame* frame, bool fresh) noexcept = 0;
  /// Draws the organ (before the instruments).
  virtual void draw(Renderer& renderer) const = 0;
  /// Where the organ comes in a picture of several, seen from `eye` (m): smaller first. Opaque organs nearest first
  /// (a pixel they cover is not shaded again behind them); a cavity seen from inside and translucent parts after them.
  virtual double draw_depth(const Eigen::Vector3d& /*eye*/) const { return 0; }
  /// The instruments the organ's own state carries (e.g. the intestine's newest BodyState: the probes at the body's
  /// tick), or null: the app draws those of the newest contact frame (instruments.h).
  virtual const InstrumentPoses* instruments() const { return nullptr; }
  /// Draws the contact markers (after the instruments).
  virtual void draw_markers(Renderer&) const {}
  /// This frame's work time (s: update, draws, end_frame), for a level-of-detail controller.
  virtual void frame_done(double /*work_seconds*/) noexcept {}
  /// Level of detail drawn (VisualStatus.lod; 0 when the organ has none).
  virtual std::uint32_t lod() const { return 0; }

  /// Contacts of the frame shown (frames.csv).
  virtual int contacts_shown() const { return 0; }
  /// Largest displacement of the shown shape from rest, m (frames.csv).
  virtual double max_displacement() const { return 0; }
  /// Writes the shown surface as VTK to `path` (with a PNG, when the scene asks); false when the organ has none.
  /// Throws surgsim::core::Error when the file cannot be written.
  virtual bool write_vtk(const std::string& /*path*/) const { return false; }
  /// Contact frames that could not be applied (e.g. naming nodes this scene does not have).
  virtual std::uint64_t deform_errors() const { return 0; }

  /// Shutdown: "model_built" and the organ's own keys (the app has already set visible_nodes and tensor_rows to 0).
  virtual void add_stats(nlohmann::json& stats) const = 0;
  /// Shutdown: extra summary lines from the finished stats (not called with --quiet).
  virtual void print_summary(std::ostream&, const nlohmann::json& /*stats*/) const {}
};

struct OrganViewOptions {
  std::string cache_dir;   // meshes and tensors
  intestine::TubeSkinning tube_skinning = intestine::TubeSkinning::kGpu;
  std::ostream* log = nullptr;  // progress of mesh and tensor loading; null: quiet
  int organ_index = 0;          // the organ drawn: its index in the scene's organs list (wire v3: ContactEntry.organ,
                                // BodyState.organ); 0 in a one-organ scene
};

/// An organ's display colour (sRGB): the scene's `colour`, else a default by its model and name: the liver dark
/// red-brown, the bowel pink, a rigid wall pinkish red, a floor (retroperitoneum) darker, ribs and bones pale.
Eigen::Vector3f organ_rgb(const scene::OrganSpec& organ);
/// Whether a rigid organ is bone (generated ribs, tube or box, or named rib, bone, spine, pelvis): drawn pale,
/// smoother.
bool organ_is_bone(const scene::OrganSpec& organ);

/// The scene identity both nodes compare: the scene's hash mixed with its mesh's (0 without a tetrahedral mesh).
std::uint64_t visual_scene_hash(const scene::Scene& scene, std::uint64_t mesh_hash);

/// The view of scene.model (the only switch on it in the visual node). Throws surgsim::core::Error when the organ
/// cannot be built (mesh, tensors, law, embedded surface).
std::unique_ptr<OrganView> make_organ_view(const scene::Scene& scene, const OrganViewOptions& options);

}  // namespace surgsim
