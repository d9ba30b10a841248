#include "views/liver_view.h"

#include <algorithm>
#include <nlohmann/json.hpp>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "liver/liver_setup.h"
#include "liver/organ_curves.h"
#include "mesher/scene_mesh.h"
#include "render/renderer.h"

namespace surgsim {

namespace {
Eigen::Vector3d from_msg(const msg::Vec3& v) { return {v.x(), v.y(), v.z()}; }
}  // namespace

LiverView::LiverView(const Scene& scene, const OrganViewOptions& options)
    : tools_(static_cast<int>(scene.tools.size())) {
  // The visible mesh.
  mesh_ = load_scene_mesh(scene, options.cache_dir, options.log);
  surface_ = boundary_surface(mesh_);
  mesh_hash_ = surgsim::mesh_hash(mesh_);

  // The visual rows of the tensors (visible x surface), from the cache both nodes share.
  const LiverTensorSetup setup = liver_tensor_setup(scene.material, scene.fixed, mesh_, options.cache_dir, scene.file);
  tensors_ = load_liver_tensors(setup, mesh_, scene.material, {"visual"}, options.log, nullptr, scene.file);
  tensor_hash_ = setup.key.combined();

  law_ = std::make_unique<NonlinearLaw>(
      scene.liver.organ_curves
          ? load_organ_law(mesh_, scene.material, setup.fixed, tensor_hash_, options.cache_dir, options.log)
          : load_nonlinear_law(scene.nonlinear, scene.material));
  deformer_ = std::make_unique<SurfaceDeformer>(mesh_, surface_, &tensors_, law_->identity() ? nullptr : law_.get(),
                                                scene.liver.deformation);
  if (!scene.visual.surface.empty()) {
    // A finer visual surface embedded in the mechanical boundary (within 1 % of the organ's size).
    const double size = (mesh_.nodes.colwise().maxCoeff() - mesh_.nodes.colwise().minCoeff()).norm();
    try {
      deformer_->embed(read_obj(scene.visual.surface), mesh_, surface_, 0.01 * size);
    } catch (const Error& e) {
      throw_error(scene.file, ": key 'visual.surface': ", e.what());
    }
  }
  markers_.resize(kMaxContacts, 3);
}

double LiverView::update(const msg::ContactFrame* frame, bool fresh) noexcept {
  // Deformation of the visible mesh from the newest contacts: u_n = sum_k G_nk lambda_k over the visible rows.
  contacts_ = frame != nullptr ? std::min<int>(static_cast<int>(frame->contacts().size()), kMaxContacts) : 0;
  double deform_us = -1;
  if (fresh && frame != nullptr) {
    const std::uint64_t d0 = monotonic_ns();
    for (int l = 0; l < contacts_; ++l) {
      const auto& e = frame->contacts()[static_cast<std::size_t>(l)];
      contact_nodes_[static_cast<std::size_t>(l)] = static_cast<int>(e.node());
      contact_lambda_[static_cast<std::size_t>(l)] = from_msg(e.lambda());
      // An instrument the scene does not have (or without a state in the frame): its contact is superposed linearly.
      const std::uint32_t i = e.instrument();
      contact_instrument_[static_cast<std::size_t>(l)] =
          i < static_cast<std::uint32_t>(kMaxInstruments) ? static_cast<int>(i) : -1;
    }
    take_instruments(frame->instruments(), tools_, instruments_);  // absent instruments get a zero direction
    if (deformer_->apply(contact_nodes_.data(), contact_lambda_.data(), contact_instrument_.data(), contacts_,
                         instruments_.direction.data(), std::min(tools_, kMaxInstruments)) != ContactStatus::kOk) {
      ++deform_errors_;  // a frame naming nodes this scene does not have: keep the last good shape
    }
    deform_us = static_cast<double>(monotonic_ns() - d0) * 1e-3;
  }
  // Contact nodes as markers (visual feedback only).
  marker_count_ = 0;
  for (int l = 0; l < contacts_; ++l) {
    const int v = deformer_->vertex_of(contact_nodes_[static_cast<std::size_t>(l)]);
    if (v >= 0) markers_.row(marker_count_++) = deformer_->positions().row(v);
  }
  return deform_us;
}

void LiverView::draw(Renderer& renderer) const {
  renderer.draw_surface(deformer_->drawn_positions(), deformer_->drawn_tris(), kLiverRgb);
}

void LiverView::draw_markers(Renderer& renderer) const {
  if (marker_count_ > 0) renderer.draw_points(markers_.topRows(marker_count_), 0.0015f, kMarkerRgb);
}

bool LiverView::write_vtk(const std::string& path) const {
  write_vtk_surface(path, deformer_->drawn_positions().cast<double>(), deformer_->drawn_tris());
  return true;
}

void LiverView::add_stats(nlohmann::json& j) const {
  j["model_built"] = "liver";
  j["visible_nodes"] = deformer_->visible_nodes().size();
  j["tensor_rows"] = tensors_.find("visual") != nullptr ? tensors_.find("visual")->row_count() : 0;
}

}  // namespace surgsim
