#include "views/intestine_view.h"

#include <algorithm>
#include <cmath>
#include <iostream>

#include "surgsim_types.h"
#include "core/clock.h"
#include "render/renderer.h"
#include "views/body_state_listener.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {

namespace {

intestine::TubeParams tube_params(const Scene& scene) {
  intestine::TubeParams p;
  p.radius = scene.intestine.params.intestine_radius;
  return p;
}

intestine::FrameRateParams rate_params(const Scene& scene) {
  intestine::FrameRateParams p;  // the paper's alpha and beta
  p.target_hz = scene.visual.target_fps > 0 ? scene.visual.target_fps : scene.visual.rate_hz;
  p.lod_min = 0;
  p.lod_max = intestine::kTubeMaxLod;
  p.initial_lod = intestine::kTubeMaxLod;
  return p;
}

}  // namespace

IntestineView::IntestineView(const Scene& scene, std::uint64_t scene_hash, intestine::TubeSkinning skinning)
    : rows_(scene.intestine.params.rows),
      cols_(scene.intestine.params.columns),
      tools_(static_cast<int>(scene.tools.size())),
      look_{scene.organs.empty() ? kIntestineRgb : organ_rgb(scene.organs[0]), kIntestineLook.specular,
            kIntestineLook.shininess},
      scene_hash_(scene_hash),
      target_fps_(rate_params(scene).target_hz),
      points_(static_cast<std::size_t>(3 * rows_ * cols_), 0.0),
      builder_(tube_params(scene), cols_),
      tube_(builder_.make_mesh(intestine::kTubeMaxLod)),
      mesentery_(intestine::make_mesentery_surface(rows_, cols_, kMesenteryRowSteps, kMesenteryColSteps)),
      controller_(rate_params(scene)),
      skinning_(skinning),
      incoming_(3 * static_cast<std::size_t>(msg::kMaxBodyPoints), 0.0) {
  tube_positions_.resize(static_cast<Eigen::Index>(tube_.positions.size() / 3), 3);
  tube_tris_.resize(static_cast<Eigen::Index>(tube_.indices.size() / 3), 3);
}

IntestineView::~IntestineView() = default;

void IntestineView::set_skinning(intestine::TubeSkinning skinning) noexcept {
  skinning_ = skinning;
  built_lod_ = -1;  // rebuild on the next update()
}

void IntestineView::subscribe(dds::Participant& participant, int organ) {
  listener_ = subscribe_body_states(participant, organ);
}

bool IntestineView::accept(const double* xyz, int count, const InstrumentPoses* instruments) noexcept {
  if (count != rows_ * cols_) return false;
  for (int i = 0; i < 3 * count; ++i) {
    if (!std::isfinite(xyz[i])) return false;
  }
  std::copy(xyz, xyz + 3 * count, points_.begin());
  if (instruments != nullptr) {
    instruments_ = *instruments;
    instrument_states_ignored_ += static_cast<std::uint64_t>(instruments->ignored);
  }
  have_body_ = true;
  ++states_shown_;
  return true;
}

bool IntestineView::update() noexcept {
  bool fresh = false;
  if (listener_ != nullptr) {
    BodyStateHeader header;
    const int count = listener_->take(incoming_.data(), tools_, incoming_instruments_, header, states_received_);
    if (count >= 0) {
      if (header.scene_hash == scene_hash_ && accept(incoming_.data(), count, &incoming_instruments_)) {
        fresh = true;
        last_seq_ = header.seq;
      } else {
        ++states_rejected_;
      }
    }
  }
  const int lod = controller_.lod();
  if (have_body_ && (fresh || lod != built_lod_)) rebuild(lod);
  return fresh;
}

bool IntestineView::set_positions(const double* xyz, int count, const InstrumentPoses* instruments) noexcept {
  if (!accept(xyz, count, instruments)) {
    ++states_rejected_;
    return false;
  }
  rebuild(controller_.lod());
  return true;
}

void IntestineView::rebuild(int lod) noexcept {
  const std::uint64_t t0 = monotonic_ns();
  // The tube through the intestine's points (row 0 of the grid): the skinning matrices, and with kCpu the vertices.
  const bool cpu = skinning_ == intestine::TubeSkinning::kCpu;
  if (builder_.build(points_.data(), cols_, lod, tube_, skinning_)) {
    for (int v = 0; cpu && v < tube_.vertex_count; ++v) {
      tube_positions_.row(v) << tube_.positions[3 * static_cast<std::size_t>(v)],
          tube_.positions[3 * static_cast<std::size_t>(v) + 1], tube_.positions[3 * static_cast<std::size_t>(v) + 2];
    }
    const int tris = tube_.index_count / 3;
    for (int t = 0; cpu && t < tris; ++t) {
      for (int k = 0; k < 3; ++k) {
        tube_tris_(t, k) = static_cast<int>(tube_.indices[3 * static_cast<std::size_t>(t) + static_cast<std::size_t>(k)]);
      }
    }
    tube_vertices_max_ = std::max(tube_vertices_max_, tube_.vertex_count);
    tube_triangles_max_ = std::max(tube_triangles_max_, tris);
  } else {
    ++build_failures_;  // the tube is not drawn until a build succeeds
  }
  // The mesentery over the whole grid, refined, with its normals (accept() checked the points: it cannot fail).
  intestine::mesentery_surface(points_.data(), mesentery_);
  built_lod_ = lod;
  build_us_.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
}

void IntestineView::draw(Renderer& renderer) const {
  // The opaque tube first: the backdrop is then shaded only where the tube leaves pixels, and the translucent
  // mesentery blends over both.
  if (have_body_ && tube_.vertex_count > 0) {
    if (skinning_ == intestine::TubeSkinning::kGpu) {
      renderer.draw_skinned_tube(builder_.primitive(tube_.lod), tube_.skin.data(), tube_.intervals, look_);
    } else {
      renderer.draw_surface(tube_positions_.topRows(tube_.vertex_count), tube_tris_.topRows(tube_.index_count / 3),
                            look_);
    }
  }
  renderer.draw_backdrop(kCavityCentreRgb, kCavityEdgeRgb);
  if (have_body_) renderer.draw_membrane(mesentery_, kMesenteryLook);
}

void IntestineView::frame_done(double work_seconds) noexcept {
  if (have_body_) ++lod_frames_[static_cast<std::size_t>(std::clamp(built_lod_, 0, intestine::kTubeMaxLod))];
  if (work_seconds > 0 && std::isfinite(work_seconds)) {
    work_ms_.add(work_seconds * 1e3);
    controller_.update_from_frame_time(work_seconds);
  }
}

nlohmann::json IntestineView::stats() const {
  nlohmann::json j;
  j["body_states_received"] = states_received_;
  j["body_states_shown"] = states_shown_;
  j["body_states_rejected"] = states_rejected_;
  j["instrument_states_ignored"] = instrument_states_ignored_;
  j["last_seq"] = last_seq_;
  j["build_failures"] = build_failures_;
  std::uint64_t frames = 0;
  double lod_sum = 0;
  for (std::size_t l = 0; l < lod_frames_.size(); ++l) {
    frames += lod_frames_[l];
    lod_sum += static_cast<double>(l) * static_cast<double>(lod_frames_[l]);
  }
  j["lod_histogram"] = lod_frames_;  // frames drawn at LOD 0..6
  j["lod_mean"] = frames > 0 ? lod_sum / static_cast<double>(frames) : 0.0;
  j["lod_final"] = controller_.lod();
  j["target_fps"] = target_fps_;
  j["tube_skinning"] = skinning_ == intestine::TubeSkinning::kGpu ? "gpu" : "cpu";
  const Percentiles work = work_ms_.summary();
  j["work_ms"] = to_json(work);
  j["work_fps_mean"] = work.mean > 0 ? 1e3 / work.mean : 0.0;  // the rate the frames' work alone would allow
  j["build_us"] = to_json(build_us_.summary());
  j["tube_vertices_max"] = tube_vertices_max_;
  j["tube_triangles_max"] = tube_triangles_max_;
  j["mesentery_triangles"] = mesentery_.indices.size() / 3;
  j["mesentery_vertices"] = mesentery_.vertex_count;
  const intestine::TubeStats& ts = builder_.stats();
  j["tube_last"] = {{"samples", ts.samples},
                    {"flagged_segments", ts.flagged_segments},
                    {"extra_samples", ts.extra_samples},
                    {"removed_samples", ts.removed_samples},
                    {"tilted_rings", ts.tilted_rings},
                    {"narrowed_rings", ts.narrowed_rings},
                    {"min_radius_m", ts.min_radius}};
  return j;
}

IntestineOrganView::IntestineOrganView(const Scene& scene, std::uint64_t scene_hash, intestine::TubeSkinning skinning,
                                       int organ)
    : view_(scene, scene_hash, skinning), organ_(organ) {}

void IntestineOrganView::attach(const Renderer& renderer) {
  if (view_.skinning() == intestine::TubeSkinning::kGpu && !renderer.gpu_skinning()) {
    std::cerr << "visual_node: " << renderer.info() << ": skinning the intestine tube on the CPU instead "
              << "(--tube-skinning cpu)\n";
    view_.set_skinning(intestine::TubeSkinning::kCpu);
  }
}

void IntestineOrganView::print_init(std::ostream& out) const {
  out << "visual_node: intestine: tube skinned on the "
      << (view_.skinning() == intestine::TubeSkinning::kGpu ? "GPU (vertex shader)" : "CPU")
      << " + smooth mesentery (" << view_.mesentery().vertex_count << " vertices), LOD by the frame-rate "
      << "controller (target " << view_.controller().params().target_hz << " Hz)\n";
}

double IntestineOrganView::update(const msg::ContactFrame*, bool) noexcept {
  const std::uint64_t t0 = monotonic_ns();
  if (!view_.update()) return -1;
  return static_cast<double>(monotonic_ns() - t0) * 1e-3;
}

void IntestineOrganView::add_stats(nlohmann::json& j) const {
  // Which organ model this run built (an intestine run builds no mesh or tensors).
  j["model_built"] = "intestine";
  j["intestine"] = view_.stats();
  j["lod_mean"] = j["intestine"]["lod_mean"];
  j["lod_target_fps"] = j["intestine"]["target_fps"];
}

void IntestineOrganView::print_summary(std::ostream& out, const nlohmann::json& j) const {
  const nlohmann::json& in = j["intestine"];
  out << "visual_node: intestine: " << in["body_states_received"].get<std::uint64_t>()
      << " body states received, LOD mean " << in["lod_mean"].get<double>() << " (final "
      << in["lod_final"].get<int>() << ", target " << in["target_fps"].get<double>() << " Hz, frame work p50 "
      << in["work_ms"]["p50"].get<double>() << " ms), tube up to " << in["tube_triangles_max"].get<int>()
      << " triangles\n";
}

}  // namespace surgsim
