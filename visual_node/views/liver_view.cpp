#include "views/liver_view.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "liver/liver_setup.h"
#include "nonlinear/organ_curves.h"
#include "mesher/scene_mesh.h"
#include "render/renderer.h"
#include "render/surface_detail.h"
#include "views/body_state_listener.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::liver;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {

namespace {
Eigen::Vector3d from_msg(const msg::Vec3& v) { return {v.x(), v.y(), v.z()}; }
}  // namespace

LiverView::LiverView(const Scene& scene, const OrganViewOptions& options)
    : tools_(static_cast<int>(scene.tools.size())), organ_(options.organ_index) {
  // The visible mesh.
  mesh_ = load_scene_mesh(scene, options.cache_dir, options.log);
  surface_ = boundary_surface(mesh_);
  mesh_hash_ = surgsim::mesh::mesh_hash(mesh_);

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

  // The look: the organ's colour, wet, mottled per vertex at rest; a gallbladder region tinted green.
  look_ = SurfaceLook{scene.organs.empty() ? kLiverRgb : organ_rgb(scene.organs[0]), 0.3f, 80.0f};
  const Eigen::MatrixX3f& rest = deformer_->drawn_positions();
  SurfaceDetail detail;
  detail.scale = 45.0f;
  detail.mottle = 0.16f;
  detail.seed = static_cast<std::uint32_t>(mesh_hash_);
  tint_ = surface_tint(rest, detail);
  Eigen::VectorXf gallbladder = Eigen::VectorXf::Zero(rest.rows());
  for (const auto& region : scene.material.regions) {
    if (region.name.find("gall") == std::string::npos) continue;
    for (Eigen::Index v = 0; v < rest.rows(); ++v) {
      if (region.contains(scene.material.frame.to_organ(rest.row(v).transpose().cast<double>()))) gallbladder[v] = 1.0f;
    }
  }
  blend_tint(tint_, gallbladder, kGallbladderRgb.cwiseQuotient(look_.rgb.cwiseMax(1e-3f)));
  centre_ = (0.5f * (rest.colwise().minCoeff() + rest.colwise().maxCoeff())).transpose().cast<double>();

  // Multirate: the tracker's shape arrives as BodyState, one position per boundary node.
  multirate_ = scene.liver.deformation == LiverDeformation::kMultirate;
  scene_hash_ = visual_scene_hash(scene, mesh_hash_);
  scene_name_ = scene.name;
  scene_file_ = scene.file;
  if (multirate_) {
    body_xyz_.assign(3 * static_cast<std::size_t>(msg::kMaxBodyPoints), 0.0);
    snapshot_xyz_.assign(3 * surface_.nodes.size(), 0.0);
  }
}

LiverView::~LiverView() = default;

void LiverView::subscribe(dds::Participant& participant) {
  if (multirate_) listener_ = subscribe_body_states(participant, organ_);
}

void LiverView::say_rejection(BodyRejection why, std::uint64_t seq, int count, std::uint64_t scene_hash) noexcept {
  const auto r = static_cast<std::size_t>(why);
  ++body_rejected_[r];
  if (body_rejection_said_[r]) return;
  body_rejection_said_[r] = true;
  std::cerr << "visual_node: body state " << seq << " ignored: ";
  switch (why) {
    case BodyRejection::kWrongScene:
      std::cerr << "scene hash " << scene_hash << " but this node's scene '" << scene_name_ << "' (" << scene_file_
                << ") with its mesh has hash " << scene_hash_
                << ": start both nodes with the same scene and mesh (counted in stats "
                   "multirate.body_states_rejected.wrong_scene)\n";
      break;
    case BodyRejection::kWrongCount:
      std::cerr << count << " positions but the liver of scene '" << scene_name_ << "' (" << scene_file_ << ") has "
                << surface_.nodes.size()
                << " boundary surface nodes (liver.deformation multirate: one position per boundary node, in "
                   "SurfaceMesh order; counted in stats multirate.body_states_rejected.wrong_count)\n";
      break;
    case BodyRejection::kNonFinite:
      std::cerr << "a position is not finite (NaN or infinite) in scene '" << scene_name_ << "' (" << scene_file_
                << "): the previous shape is kept (counted in stats multirate.body_states_rejected.non_finite)\n";
      break;
  }
}

bool LiverView::take_body_state(const double* xyz, int count, std::uint64_t scene_hash, std::uint64_t stamp_ns,
                                std::uint64_t seq) noexcept {
  if (scene_hash != scene_hash_) {
    say_rejection(BodyRejection::kWrongScene, seq, count, scene_hash);
    return false;
  }
  if (count != static_cast<int>(surface_.nodes.size())) {
    say_rejection(BodyRejection::kWrongCount, seq, count, scene_hash);
    return false;
  }
  // SurfaceDeformer's vertices are the boundary's nodes in SurfaceMesh order: position k is vertex k.
  if (!deformer_->set_positions(xyz, count)) {
    say_rejection(BodyRejection::kNonFinite, seq, count, scene_hash);
    return false;
  }
  std::copy(xyz, xyz + 3 * count, snapshot_xyz_.begin());  // carried to the contacts of every later frame
  body_shown_ = true;
  body_stamp_ns_ = stamp_ns;
  body_seq_ = seq;
  body_new_ = true;
  ++body_states_shown_;
  return true;
}

double LiverView::update(const msg::ContactFrame* frame, bool fresh) noexcept {
  // Deformation of the visible mesh from the newest contacts: u_n = sum_k G_nk lambda_k over the visible rows; with
  // multirate, once a BodyState was drawn, the tracker's shape carried to the frame's contacts instead.
  // Only this organ's contact entries (a scene with several organs sends every organ's in one frame).
  contacts_ = 0;
  if (frame != nullptr) {
    for (const auto& e : frame->contacts()) contacts_ += e.organ() == static_cast<std::uint32_t>(organ_) ? 1 : 0;
    contacts_ = std::min<int>(contacts_, kMaxContacts);
  }
  double deform_us = -1;
  // Multirate: the newest BodyState, when one arrived since the last frame.
  if (listener_ != nullptr) {
    const std::uint64_t b0 = monotonic_ns();
    BodyStateHeader header;
    const int count = listener_->take(body_xyz_.data(), tools_, body_instruments_, header, body_states_received_);
    if (count >= 0 && take_body_state(body_xyz_.data(), count, header.scene_hash, header.stamp_ns, header.seq)) {
      body_state_instruments_ = body_instruments_.count();
      deform_us = static_cast<double>(monotonic_ns() - b0) * 1e-3;
      body_apply_us_.add(deform_us);
    }
  }
  if (fresh && frame != nullptr) {
    const std::uint64_t d0 = monotonic_ns();
    int l = 0;
    for (const auto& e : frame->contacts()) {
      if (e.organ() != static_cast<std::uint32_t>(organ_)) {
        ++other_organ_contacts_;  // another organ's node: not this mesh's
        continue;
      }
      if (l >= contacts_) break;
      contact_nodes_[static_cast<std::size_t>(l)] = static_cast<int>(e.node());
      contact_lambda_[static_cast<std::size_t>(l)] = from_msg(e.lambda());
      // Multirate: u_tilde is the node's imposed displacement this tick (the tracker's target).
      carry_contacts_[static_cast<std::size_t>(l)].node = static_cast<int>(e.node());
      carry_contacts_[static_cast<std::size_t>(l)].displacement = from_msg(e.u_tilde());
      // An instrument the scene does not have (or without a state in the frame): its contact is superposed linearly.
      const std::uint32_t i = e.instrument();
      contact_instrument_[static_cast<std::size_t>(l)] =
          i < static_cast<std::uint32_t>(kMaxInstruments) ? static_cast<int>(i) : -1;
      ++l;
    }
    take_instruments(frame->instruments(), tools_, instruments_);  // absent instruments get a zero direction
    // Once the tracker's shape is drawn (multirate) the contacts carry it (below) and place the markers.
    if (!body_shown_) {
      if (deformer_->apply(contact_nodes_.data(), contact_lambda_.data(), contact_instrument_.data(), contacts_,
                           instruments_.direction.data(), std::min(tools_, kMaxInstruments)) != ContactStatus::kOk) {
        ++deform_errors_;  // a frame naming nodes this scene does not have: keep the last good shape
      }
      deform_us = static_cast<double>(monotonic_ns() - d0) * 1e-3;
    }
  }
  // Multirate: the tracker's last shape carried to this frame's contacts (the tracker publishes a few times a second;
  // between two of its states the contact nodes follow the tool and the rest follows them linearly).
  if (body_shown_ && (body_new_ || fresh)) {
    const std::uint64_t c0 = monotonic_ns();
    const int count = static_cast<int>(surface_.nodes.size());
    const int m = frame != nullptr ? contacts_ : 0;
    if (deformer_->carry_positions(snapshot_xyz_.data(), count, carry_contacts_.data(), m) != ContactStatus::kOk) {
      ++carry_failures_;  // the tracker's shape as it came
      deformer_->set_positions(snapshot_xyz_.data(), count);
    }
    deform_us = static_cast<double>(monotonic_ns() - c0) * 1e-3;
  }
  // The shape's age at draw (the same host's CLOCK_MONOTONIC as the publisher's stamp).
  if (body_shown_) {
    ++frames_body_;
    const std::uint64_t now = monotonic_ns();
    if (now >= body_stamp_ns_) {
      const double age_ms = static_cast<double>(now - body_stamp_ns_) * 1e-6;
      body_age_ms_.add(age_ms);
      if (body_new_) body_first_age_ms_.add(age_ms);
    } else {
      ++age_unknown_;
    }
    body_new_ = false;
  } else if (multirate_) {
    ++frames_linear_;
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
  renderer.draw_surface(deformer_->drawn_positions(), deformer_->drawn_tris(), look_, &tint_);
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
  if (!multirate_) return;
  nlohmann::json m;
  m["surface_nodes"] = surface_.nodes.size();
  m["body_states_received"] = body_states_received_;
  m["body_states_shown"] = body_states_shown_;
  std::uint64_t rejected = 0;
  for (const std::uint64_t r : body_rejected_) rejected += r;
  m["body_states_rejected"] = {{"total", rejected},
                               {"wrong_scene", body_rejected_[static_cast<std::size_t>(BodyRejection::kWrongScene)]},
                               {"wrong_count", body_rejected_[static_cast<std::size_t>(BodyRejection::kWrongCount)]},
                               {"non_finite", body_rejected_[static_cast<std::size_t>(BodyRejection::kNonFinite)]}};
  m["last_seq_shown"] = body_seq_;
  m["last_state_instruments"] = body_state_instruments_;  // instruments of the scene the last state drawn carried
  m["frames_linear_fallback"] = frames_linear_;
  m["frames_body_state"] = frames_body_;
  m["shape_age_ms"] = to_json(body_age_ms_.summary());  // draw time - BodyState stamp_ns, per frame drawn
  m["shape_age_first_draw_ms"] = to_json(body_first_age_ms_.summary());  // each state's age at its first frame
  m["shape_age_unknown_frames"] = age_unknown_;
  m["body_apply_us"] = to_json(body_apply_us_.summary());
  m["carry_failures"] = carry_failures_;  // frames drawn with the tracker's shape as it came (contacts not solvable)
  j["multirate"] = m;
}

void LiverView::print_summary(std::ostream& out, const nlohmann::json& j) const {
  if (!multirate_ || !j.contains("multirate")) return;
  const nlohmann::json& m = j["multirate"];
  const nlohmann::json& r = m["body_states_rejected"];
  out << "visual_node: multirate liver: " << m["body_states_shown"].get<std::uint64_t>() << " body states shown of "
      << m["body_states_received"].get<std::uint64_t>() << " received (ignored: " << r["wrong_scene"].get<std::uint64_t>()
      << " other scene, " << r["wrong_count"].get<std::uint64_t>() << " wrong count, "
      << r["non_finite"].get<std::uint64_t>() << " non-finite), " << m["frames_linear_fallback"].get<std::uint64_t>()
      << " frames by the linear deformer before the first; shape age at its first draw p50 "
      << m["shape_age_first_draw_ms"]["p50"].get<double>() << " ms p99 "
      << m["shape_age_first_draw_ms"]["p99"].get<double>() << " ms, at every draw p50 "
      << m["shape_age_ms"]["p50"].get<double>() << " ms p99 " << m["shape_age_ms"]["p99"].get<double>() << " ms\n";
}

}  // namespace surgsim
