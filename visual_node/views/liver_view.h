// The liver in the visual node (Cotin et al. 1998): the scene's tetrahedral mesh and its boundary, the "visual" rows
// of the precomputed tensors (visible x surface, from the cache both nodes share; no interior rows), the quasi
// non-linear law, the SurfaceDeformer (u_n = sum_k G_nk lambda_k for the newest contacts), an optional finer visual
// surface embedded in the boundary (visual.surface), and the contact nodes drawn as markers. With several instruments
// the contacts of all of them deform the organ together (one solve on the haptic side); the non-linear law
// bends each instrument's share about that instrument's own direction (SurfaceDeformer::apply with instruments).
// liver.deformation corotational: the deformer recomputes the rotations from the received forces (no
// more data on the wire); liver.curves organ: the law from the organ's own curves (nonlinear/organ_curves.h).
//
// liver.deformation multirate: the haptic node's neo-Hookean tracker publishes the organ's shape as
// BodyState (one position per boundary surface node, SurfaceMesh node order, the scene identity as scene_hash; see
// the wire protocol in the README). The view subscribes to it and each frame draws the newest valid one: the boundary
// takes the positions, an embedded visual.surface follows through its embedding, normals are recomputed by the
// renderer as for every surface. A state of another scene, with another position count than the boundary's node
// count, or with a non-finite position is ignored and counted by reason (one stderr line per reason, the first time,
// naming what was expected). Until the first valid state the linear deformer draws the ContactFrame's contacts, so
// the picture is never empty; the contact markers always come from the ContactFrame. The tracker publishes a few
// states a second, so each frame carries the last one to the frame's contacts (SurfaceDeformer::carry_positions: the
// ContactFrame's u_tilde is each contact node's imposed displacement in this mode; the linear response that takes
// those nodes from the state to there is added to the whole shape): the contact nodes stay under the tool and the
// rest follows linearly until the next state. Stats: key "multirate".
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/stats.h"
#include "instruments.h"
#include "nonlinear/nonlinear_law.h"
#include "compliance/precompute.h"
#include "compliance/superposition.h"
#include "mesh/mesh.h"
#include "organ_view.h"
#include "render/renderer.h"
#include "views/surface_deformer.h"

namespace surgsim {

class BodyStateListener;

class LiverView : public OrganView {
 public:
  /// Init: loads (or generates) the mesh, the tensors' "visual" block and the law; embeds visual.surface when the
  /// scene names one. Throws surgsim::core::Error (the embedded surface's errors name the scene key).
  LiverView(const scene::Scene& scene, const OrganViewOptions& options);
  ~LiverView() override;

  std::uint64_t mesh_hash() const override { return mesh_hash_; }
  std::uint64_t tensor_hash() const override { return tensor_hash_; }
  long surface_triangles() const override { return static_cast<long>(surface_.tris.rows()); }

  /// Init (multirate only): the BodyState reader.
  void subscribe(dds::Participant& participant) override;

  double update(const msg::ContactFrame* frame, bool fresh) noexcept override;
  void draw(Renderer& renderer) const override;
  /// The distance from `eye` to its bounding box's centre at rest.
  double draw_depth(const Eigen::Vector3d& eye) const override { return (centre_ - eye).norm(); }
  void draw_markers(Renderer& renderer) const override;

  int contacts_shown() const override { return contacts_; }
  double max_displacement() const override { return deformer_->max_displacement(); }
  bool write_vtk(const std::string& path) const override;
  std::uint64_t deform_errors() const override { return deform_errors_; }
  void add_stats(nlohmann::json& stats) const override;
  /// Multirate: one line with the body states shown and ignored and the shape's age at draw.
  void print_summary(std::ostream& out, const nlohmann::json& stats) const override;

  const SurfaceDeformer& deformer() const { return *deformer_; }

  /// Why a BodyState was not drawn (multirate).
  enum class BodyRejection { kWrongScene = 0, kWrongCount, kNonFinite };
  static constexpr int kBodyRejections = 3;
  /// Multirate: takes one BodyState (the DDS path and tests): `xyz` holds `count` points (x, y, z; m) for the boundary
  /// surface nodes in SurfaceMesh order, `scene_hash` its scene identity, `stamp_ns` its publication time
  /// (CLOCK_MONOTONIC), `seq` its number. True when it is the shape drawn from now on; false when it is ignored (the
  /// previous shape kept; counted by reason, the first of each reason named on stderr). No allocation.
  bool take_body_state(const double* xyz, int count, std::uint64_t scene_hash, std::uint64_t stamp_ns,
                       std::uint64_t seq) noexcept;
  bool multirate() const { return multirate_; }
  /// A valid BodyState has been taken: the drawn shape is the tracker's, no longer the linear deformer's.
  bool body_shown() const { return body_shown_; }
  std::uint64_t body_states_shown() const { return body_states_shown_; }
  std::uint64_t body_states_rejected(BodyRejection why) const {
    return body_rejected_[static_cast<std::size_t>(why)];
  }
  /// The scene identity BodyStates must carry (visual_scene_hash of the scene and this mesh).
  std::uint64_t scene_hash() const { return scene_hash_; }
  /// The organ drawn (OrganViewOptions::organ_index): contact entries of other organs are skipped.
  int organ_index() const { return organ_; }
  /// Contact entries of other organs skipped so far (fresh frames only).
  std::uint64_t other_organ_contacts() const { return other_organ_contacts_; }

 private:
  mesh::TetMesh mesh_;
  mesh::SurfaceMesh surface_;
  std::uint64_t mesh_hash_ = 0;
  std::uint64_t tensor_hash_ = 0;
  compliance::Tensors tensors_;  // "visual" block only (no interior rows)
  std::unique_ptr<nonlinear::NonlinearLaw> law_;
  std::unique_ptr<SurfaceDeformer> deformer_;
  int tools_ = 1;  // the scene's instruments
  int organ_ = 0;  // the organ drawn: its index in the scene's organs list (ContactEntry.organ, BodyState.organ)
  std::uint64_t other_organ_contacts_ = 0;
  // The shown frame's contacts (the last fresh frame's nodes, forces and instruments; fixed storage) and its
  // instruments' directions (the non-linear law's axis of each instrument's share).
  std::array<int, compliance::kMaxContacts> contact_nodes_{};
  std::array<Eigen::Vector3d, compliance::kMaxContacts> contact_lambda_{};
  std::array<int, compliance::kMaxContacts> contact_instrument_{};
  InstrumentPoses instruments_;
  int contacts_ = 0;
  Eigen::MatrixX3f markers_;  // contact points drawn as markers
  SurfaceLook look_;          // the organ's colour (organ_rgb), wet
  Eigen::MatrixX3f tint_;     // per drawn vertex, from its rest position (render/surface_detail.h); regions named
                              // "gallbladder" greenish
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();  // of the rest bounding box, m
  int marker_count_ = 0;
  std::uint64_t deform_errors_ = 0;

  // --- multirate: the tracker's shape from BodyState ---
  bool multirate_ = false;
  std::uint64_t scene_hash_ = 0;
  std::string scene_name_, scene_file_;  // for the rejection lines
  std::unique_ptr<BodyStateListener> listener_;
  std::vector<double> body_xyz_;  // 3 x kMaxBodyPoints, the listener's newest copied out
  std::vector<double> snapshot_xyz_;  // 3 x surface nodes: the last state taken (carried to each frame's contacts)
  std::array<compliance::Contact, compliance::kMaxContacts>
      carry_contacts_{};  // the last fresh frame's nodes and imposed displacements
  std::uint64_t carry_failures_ = 0;
  InstrumentPoses body_instruments_;
  int body_state_instruments_ = 0;  // instruments the last state drawn carried (the wire protocol: all of them)
  bool body_shown_ = false;
  std::uint64_t body_stamp_ns_ = 0;  // of the shape drawn
  std::uint64_t body_seq_ = 0;
  std::uint64_t body_states_received_ = 0;
  std::uint64_t body_states_shown_ = 0;
  std::array<std::uint64_t, kBodyRejections> body_rejected_{};
  std::array<bool, kBodyRejections> body_rejection_said_{};
  std::uint64_t frames_linear_ = 0;  // frames drawn by the linear deformer before the first BodyState
  std::uint64_t frames_body_ = 0;    // frames drawn with the tracker's shape
  std::uint64_t age_unknown_ = 0;    // frames whose shape's stamp is after the draw (another host's clock)
  core::SampleRecorder body_age_ms_{1 << 18};        // the drawn shape's age at draw: draw time - BodyState stamp_ns
  core::SampleRecorder body_first_age_ms_{1 << 18};  // the same at the first frame that draws each state (its delivery)
  bool body_new_ = false;  // a state was taken since the last frame
  core::SampleRecorder body_apply_us_{1 << 18};
  void say_rejection(BodyRejection why, std::uint64_t seq, int count, std::uint64_t scene_hash) noexcept;
};

}  // namespace surgsim
