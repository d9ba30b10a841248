// The liver in the visual node (Cotin et al. 1998): the scene's tetrahedral mesh and its boundary, the "visual" rows
// of the precomputed tensors (visible x surface, from the cache both nodes share; no interior rows), the quasi
// non-linear law, the SurfaceDeformer (u_n = sum_k G_nk lambda_k for the newest contacts), an optional finer visual
// surface embedded in the boundary (visual.surface), and the contact nodes drawn as markers. With several instruments
// (issue 19) the contacts of all of them deform the organ together (one solve on the haptic side); the non-linear law
// bends each instrument's share about that instrument's own direction (SurfaceDeformer::apply with instruments).
// liver.deformation corotational (issue 16): the deformer recomputes the rotations from the received forces (no
// more data on the wire); liver.curves organ: the law from the organ's own curves (liver/organ_curves.h).
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>

#include "instruments.h"
#include "liver/nonlinear_law.h"
#include "liver/precompute.h"
#include "liver/superposition.h"
#include "mesh/mesh.h"
#include "organ_view.h"
#include "views/surface_deformer.h"

namespace surgsim {

class LiverView : public OrganView {
 public:
  /// Init: loads (or generates) the mesh, the tensors' "visual" block and the law; embeds visual.surface when the
  /// scene names one. Throws surgsim::Error (the embedded surface's errors name the scene key).
  LiverView(const Scene& scene, const OrganViewOptions& options);

  std::uint64_t mesh_hash() const override { return mesh_hash_; }
  std::uint64_t tensor_hash() const override { return tensor_hash_; }
  long surface_triangles() const override { return static_cast<long>(surface_.tris.rows()); }

  double update(const msg::ContactFrame* frame, bool fresh) noexcept override;
  void draw(Renderer& renderer) const override;
  void draw_markers(Renderer& renderer) const override;

  int contacts_shown() const override { return contacts_; }
  double max_displacement() const override { return deformer_->max_displacement(); }
  bool write_vtk(const std::string& path) const override;
  std::uint64_t deform_errors() const override { return deform_errors_; }
  void add_stats(nlohmann::json& stats) const override;

  const SurfaceDeformer& deformer() const { return *deformer_; }

 private:
  TetMesh mesh_;
  SurfaceMesh surface_;
  std::uint64_t mesh_hash_ = 0;
  std::uint64_t tensor_hash_ = 0;
  Tensors tensors_;  // "visual" block only (no interior rows)
  std::unique_ptr<NonlinearLaw> law_;
  std::unique_ptr<SurfaceDeformer> deformer_;
  int tools_ = 1;  // the scene's instruments
  // The shown frame's contacts (the last fresh frame's nodes, forces and instruments; fixed storage) and its
  // instruments' directions (the non-linear law's axis of each instrument's share).
  std::array<int, kMaxContacts> contact_nodes_{};
  std::array<Eigen::Vector3d, kMaxContacts> contact_lambda_{};
  std::array<int, kMaxContacts> contact_instrument_{};
  InstrumentPoses instruments_;
  int contacts_ = 0;
  Eigen::MatrixX3f markers_;  // contact points drawn as markers
  int marker_count_ = 0;
  std::uint64_t deform_errors_ = 0;
};

}  // namespace surgsim
