#include "visual_app.h"

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "Surgsim.h"
#include "SurgsimPubSubTypes.h"
#include "core/clock.h"
#include "dds_support.h"
#include "core/error.h"
#include "image.h"
#include "intestine_view.h"
#include "renderer.h"
#include "liver/liver_setup.h"
#include "mesher/scene_mesh.h"
#include "os/thread_priority.h"
#include "tool/tool.h"

namespace surgsim {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

namespace {

// Keeps the newest ContactFrame and the one-way latency of each (same-host clocks).
class ContactFrameListener : public DataReaderListener {
 public:
  /// Every received frame's stamp is echoed at once on `echo` (VisualStatus), so the haptic node measures the
  /// network round trip on its own clock, independent of the frame rate.
  void set_echo(DataWriter* echo) { echo_ = echo; }
  /// Lost / back detection of the haptic node (deadline and liveliness QoS of the contact reader).
  void set_watch(HapticWatch* watch) { watch_ = watch; }
  void on_requested_deadline_missed(DataReader*, const eprosima::fastdds::dds::RequestedDeadlineMissedStatus&) override {
    if (watch_ != nullptr) watch_->on_deadline_missed(monotonic_ns());
  }
  void on_liveliness_changed(DataReader*, const eprosima::fastdds::dds::LivelinessChangedStatus& s) override {
    if (watch_ != nullptr) watch_->on_liveliness_changed(s.alive_count, s.not_alive_count_change, monotonic_ns());
  }
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&incoming_, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      const std::uint64_t now = monotonic_ns();
      if (watch_ != nullptr) watch_->on_frame(now);
      if (echo_ != nullptr) {
        echo_msg_.stamp_ns(now);
        echo_msg_.echoed_stamp_ns(incoming_.stamp_ns());
        echo_msg_.last_seq_shown(incoming_.seq());
        echo_->write(&echo_msg_);
      }
      std::lock_guard<std::mutex> lock(mutex_);
      latency_us_.add(static_cast<double>(now - incoming_.stamp_ns()) * 1e-3);
      newest_ = incoming_;
      ++received_;
      last_receive_ns_ = now;
    }
  }
  /// Copies the newest frame if it is newer than `seq_seen`; returns true then.
  bool newest(msg::ContactFrame& out, std::uint64_t& count) {
    std::lock_guard<std::mutex> lock(mutex_);
    count = received_;
    if (received_ == taken_) return false;
    taken_ = received_;
    out = newest_;
    return true;
  }
  std::uint64_t received() {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }
  std::uint64_t last_receive_ns() {
    std::lock_guard<std::mutex> lock(mutex_);
    return last_receive_ns_;
  }
  Percentiles latency() {
    std::lock_guard<std::mutex> lock(mutex_);
    return latency_us_.summary();
  }

 private:
  std::mutex mutex_;
  DataWriter* echo_ = nullptr;
  HapticWatch* watch_ = nullptr;
  msg::VisualStatus echo_msg_;
  msg::ContactFrame incoming_;
  msg::ContactFrame newest_;
  SampleRecorder latency_us_{1 << 20};
  std::uint64_t received_ = 0;
  std::uint64_t taken_ = 0;
  std::uint64_t last_receive_ns_ = 0;
};

class SceneInfoListener : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    msg::SceneInfo s;
    while (reader->take_next_sample(&s, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      info_ = s;
      have_ = true;
    }
  }
  bool get(msg::SceneInfo& out) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (have_) out = info_;
    return have_;
  }

 private:
  std::mutex mutex_;
  msg::SceneInfo info_;
  bool have_ = false;
};

Eigen::Vector3d from_msg(const msg::Vec3& v) { return {v.x(), v.y(), v.z()}; }

Pose5 from_msg(const msg::ToolPose& p) {
  Pose5 o;
  o.pitch = p.pitch();
  o.yaw = p.yaw();
  o.insertion = p.insertion();
  o.roll = p.roll();
  o.jaw = p.jaw();
  return o;
}

}  // namespace

struct VisualApp::Dds {
  explicit Dds(const dds::DdsOptions& o) : participant(o) {}
  // Listeners first: members are destroyed in reverse order, so the participant (and its readers, whose callbacks
  // use the listeners, e.g. a deadline timer firing during shutdown) goes before them.
  ContactFrameListener frames;
  SceneInfoListener scene_info;
  dds::Participant participant;
  DataReader* frame_reader = nullptr;
  DataReader* scene_reader = nullptr;
  DataWriter* status_writer = nullptr;
  msg::VisualStatus status;
};

VisualApp::VisualApp(const VisualOptions& options) : options_(options), watch_(monotonic_ns(), options.quiet) {
  // --- init: scene and the visible mesh ---
  scene_ = load_scene(resolve_scene_path(options_.scene));
  rate_hz_ = options_.rate_hz > 0 ? options_.rate_hz : scene_.visual.rate_hz;
  png_every_ = options_.png_every >= 0 ? options_.png_every : scene_.visual.png_every;
  const std::string cache = options_.cache_dir.empty() ? default_cache_dir() : options_.cache_dir;
  std::uint64_t scene_mesh_hash = 0;  // the intestine has no tetrahedral mesh (hash 0, as in the haptic node)
  if (scene_.model != "intestine") {
    mesh_ = load_scene_mesh(scene_, cache, options_.quiet ? nullptr : &std::cerr);
    surface_ = boundary_surface(mesh_);
    scene_mesh_hash = mesh_hash(mesh_);
  }
  scene_hash_ = scene_.hash() ^ (scene_mesh_hash * 0x9E3779B97F4A7C15ull);

  // --- init: the visual rows of the tensors (visible x surface), from the cache both nodes share ---
  if (scene_.model == "liver") {
    const LiverTensorSetup setup = liver_tensor_setup(scene_.material, scene_.fixed, mesh_, cache, scene_.file);
    tensors_ = load_liver_tensors(setup, mesh_, scene_.material, {"visual"}, options_.quiet ? nullptr : &std::cerr,
                                  nullptr, scene_.file);
    tensor_hash_ = setup.key.combined();
  }
  if (options_.tube_skinning != "gpu" && options_.tube_skinning != "cpu") {
    throw_error("--tube-skinning '", options_.tube_skinning, "' is not a skinning path (use gpu or cpu)");
  }
  if (scene_.model == "intestine") {
    // The intestine: a skinned tube and the mesentery from BodyStates (intestine_view.h); no deformer, no tensors.
    intestine_ = std::make_unique<IntestineView>(
        scene_, scene_hash_,
        options_.tube_skinning == "cpu" ? intestine::TubeSkinning::kCpu : intestine::TubeSkinning::kGpu);
  } else {
    law_ = std::make_unique<NonlinearLaw>(load_nonlinear_law(scene_.nonlinear, scene_.material));
    deformer_ = std::make_unique<SurfaceDeformer>(mesh_, surface_, scene_.model == "liver" ? &tensors_ : nullptr,
                                                  law_->identity() ? nullptr : law_.get());
    if (!scene_.visual.surface.empty()) {
      // A finer visual surface embedded in the mechanical boundary (within 1 % of the organ's size).
      const double size = (mesh_.nodes.colwise().maxCoeff() - mesh_.nodes.colwise().minCoeff()).norm();
      try {
        deformer_->embed(read_obj(scene_.visual.surface), mesh_, surface_, 0.01 * size);
      } catch (const Error& e) {
        throw_error(scene_.file, ": key 'visual.surface': ", e.what());
      }
    }
  }
  markers_.resize(kMaxContacts, 3);

  // --- init: renderer (no GL context at all when headless) ---
  renderer_ = make_renderer(options_.headless ? "null" : "osmesa", scene_.visual.width, scene_.visual.height);
  if (intestine_ != nullptr && intestine_->skinning() == intestine::TubeSkinning::kGpu && !renderer_->gpu_skinning()) {
    std::cerr << "visual_node: " << renderer_->info() << ": skinning the intestine tube on the CPU instead "
              << "(--tube-skinning cpu)\n";
    intestine_->set_skinning(intestine::TubeSkinning::kCpu);
  }
  if (!options_.headless && png_every_ > 0) {
    std::error_code ec;
    std::filesystem::create_directories(options_.out, ec);
    if (ec) throw_error(options_.out, ": cannot create the output folder (", ec.message(), ")");
    // Index of the written frames, so a reader knows what each PNG shows.
    index_ = std::fopen((options_.out + "/frames.csv").c_str(), "w");
    if (index_ == nullptr) throw_error(options_.out, "/frames.csv: cannot create the frame index");
    std::fprintf(index_, "png,seq,sim_time,contacts,max_displacement_m\n");
  }

  // --- init: DDS ---
  // Its threads are started at SCHED_FIFO (thread_priority.h), so a contact frame preempts rendering when it arrives:
  // on 2 cores with rendering competing, the one-way latency p99 was above 1 ms otherwise (about 0.2 ms with it).
  std::optional<ScopedFifo> dds_priority(std::in_place, options_.dds_rt_priority);
  dds_threads_note_ = dds_priority->note();
  dds::DdsOptions dopt;
  dopt.domain = options_.domain >= 0 ? options_.domain : dds::default_domain();
  dopt.profiles_file = options_.dds_profiles.empty() ? config_dir() + "/dds/profiles.xml" : options_.dds_profiles;
  dopt.participant_profile = options_.dds_participant;
  dopt.name = "surgsim_visual";
  dds_ = std::make_unique<Dds>(dopt);
  auto& p = dds_->participant;
  dds_->scene_reader = p.reader(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedReader,
                                &dds_->scene_info);
  dds_->frames.set_watch(&watch_);
  dds_->frame_reader = p.reader(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()),
                                dds::kContactReader, &dds_->frames);
  dds_->status_writer = p.writer(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()), dds::kStreamWriter);
  dds_->frames.set_echo(dds_->status_writer);
  watch_.mark_dds_ready(monotonic_ns());
  if (intestine_ != nullptr) intestine_->subscribe(p);  // BodyState
  dds_priority.reset();  // this thread renders at its previous scheduling
  if (!options_.quiet)
    std::cerr << "visual_node: DDS " << p.profile() << ": " << p.description() << "; DDS threads " << dds_threads_note_
              << "\n";

  if (!options_.quiet) {
    std::cerr << "visual_node: scene '" << scene_.name << "', " << surface_.tris.rows() << " surface triangles, "
              << renderer_->name() << " renderer " << scene_.visual.width << "x" << scene_.visual.height << " at "
              << rate_hz_ << " Hz\n";
  }
  if (!options_.quiet && intestine_ != nullptr) {
    std::cerr << "visual_node: intestine: tube skinned on the "
              << (intestine_->skinning() == intestine::TubeSkinning::kGpu ? "GPU (vertex shader)" : "CPU")
              << " + mesentery strip, LOD by the frame-rate "
              << "controller (target " << intestine_->controller().params().target_hz << " Hz)\n";
  }
}

VisualApp::~VisualApp() {
  if (index_ != nullptr) std::fclose(index_);
}

int VisualApp::run() {
  using clock = std::chrono::steady_clock;
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / rate_hz_));
  const std::uint64_t wall_start = monotonic_ns();
  auto next = clock::now();

  msg::ContactFrame frame;
  bool have_frame = false;
  if (index_ != nullptr) std::fflush(index_);
  bool hash_checked = false;
  bool hash_ok = true;
  const Eigen::Vector3f organ_rgb = kLiverRgb;

  while (!stop_requested_.load(std::memory_order_relaxed)) {
    if (options_.duration >= 0 && static_cast<double>(monotonic_ns() - wall_start) * 1e-9 >= options_.duration) break;
    if (options_.idle_exit > 0 && dds_->frames.received() > 0 &&
        static_cast<double>(monotonic_ns() - dds_->frames.last_receive_ns()) * 1e-9 > options_.idle_exit) {
      break;
    }

    // Check the haptic side's scene identity once it is known; refuse to draw frames of another scene.
    msg::SceneInfo info;
    if (!hash_checked && dds_->scene_info.get(info)) {
      hash_checked = true;
      const bool scene_ok = info.scene_hash() == scene_hash_;
      const bool tensors_ok = info.tensor_hash() == tensor_hash_;
      hash_ok = scene_ok && tensors_ok;
      if (!scene_ok) {
        std::cerr << "visual_node: the haptic node runs scene '" << info.scene_name() << "' (hash " << info.scene_hash()
                  << ", mesh hash " << info.mesh_hash() << ") but this node loaded '" << scene_.name << "' (hash "
                  << scene_hash_ << "): start both nodes with the same scene and mesh; contact frames are ignored\n";
      } else if (!tensors_ok) {
        std::cerr << "visual_node: the haptic node's tensors (hash " << info.tensor_hash() << ") differ from this "
                  << "node's (hash " << tensor_hash_ << ") for the same scene: both must use the same tensor settings; "
                  << "contact frames are ignored\n";
      }
    }

    std::uint64_t received = 0;
    const bool fresh = dds_->frames.newest(frame, received) && hash_ok;
    if (fresh) have_frame = true;

    // Deformation of the visible mesh from the newest contacts: u_n = sum_k G_nk lambda_k over the visible rows.
    const int m = have_frame && deformer_ != nullptr
                      ? std::min<int>(static_cast<int>(frame.contacts().size()), kMaxContacts) : 0;
    if (fresh && deformer_ != nullptr) {
      const std::uint64_t d0 = monotonic_ns();
      for (int l = 0; l < m; ++l) {
        const auto& e = frame.contacts()[static_cast<std::size_t>(l)];
        contact_nodes_[static_cast<std::size_t>(l)] = static_cast<int>(e.node());
        contact_lambda_[static_cast<std::size_t>(l)] = from_msg(e.lambda());
      }
      if (deformer_->apply(contact_nodes_.data(), contact_lambda_.data(), m, from_msg(frame.direction())) !=
          ContactStatus::kOk) {
        ++deform_errors_;  // a frame naming nodes this scene does not have: keep the last good shape
      }
      deform_us_.add(static_cast<double>(monotonic_ns() - d0) * 1e-3);
    }
    // Contact nodes as markers (visual feedback only).
    int marker_count = 0;
    for (int l = 0; l < m; ++l) {
      const int v = deformer_->vertex_of(contact_nodes_[static_cast<std::size_t>(l)]);
      if (v >= 0) markers_.row(marker_count++) = deformer_->positions().row(v);
    }
    // Intestine: the newest BodyState as tube and mesentery, at the LOD the frame-rate controller chose.
    const std::uint64_t work0 = monotonic_ns();
    if (intestine_ != nullptr && intestine_->update()) {
      deform_us_.add(static_cast<double>(monotonic_ns() - work0) * 1e-3);
    }

    const std::uint64_t r0 = monotonic_ns();
    renderer_->begin_frame(scene_.visual.camera);
    if (deformer_ != nullptr) renderer_->draw_surface(deformer_->drawn_positions(), deformer_->drawn_tris(), organ_rgb);
    if (intestine_ != nullptr) intestine_->draw(*renderer_);
    if (have_frame) renderer_->draw_tool(tool_geometry(scene_.tool, from_msg(frame.pose())), scene_.tool.shaft_radius);
    if (marker_count > 0) renderer_->draw_points(markers_.topRows(marker_count), 0.0015f, kMarkerRgb);
    renderer_->end_frame();
    if (intestine_ != nullptr) intestine_->frame_done(static_cast<double>(monotonic_ns() - work0) * 1e-9);
    ++frames_rendered_;
    if (png_every_ > 0 && !options_.headless && frames_rendered_ % static_cast<std::uint64_t>(png_every_) == 0) {
      if (renderer_->read_image(image_)) {
        char name[64];
        std::snprintf(name, sizeof name, "frame_%06llu.png", static_cast<unsigned long long>(frames_rendered_));
        const std::string path = options_.out + "/" + name;
        // A full disk must not stop the display: count the failure, keep drawing.
        try {
          write_png(path, image_);
          if (scene_.visual.vtk && deformer_ != nullptr) {
            write_vtk_surface(path.substr(0, path.size() - 4) + ".vtk", deformer_->drawn_positions().cast<double>(),
                              deformer_->drawn_tris());
            ++vtk_written_;
          }
          if (index_ != nullptr) {
            std::fprintf(index_, "%s,%llu,%.6f,%d,%.9g\n", name, static_cast<unsigned long long>(frame.seq()),
                         have_frame ? frame.sim_time() : -1.0, m,
                         deformer_ != nullptr ? deformer_->max_displacement() : 0.0);
          }
          if (first_png_.empty()) first_png_ = path;
          last_png_ = path;
          ++pngs_written_;
        } catch (const Error& e) {
          if (png_errors_++ == 0) std::cerr << "visual_node: " << e.what() << " (further PNG errors counted)\n";
        }
      }
    }
    render_ms_.add(static_cast<double>(monotonic_ns() - r0) * 1e-6);

    // Echo the newest haptic stamp so the haptic node measures the round trip on its own clock.
    auto& st = dds_->status;
    st.stamp_ns(monotonic_ns());
    st.fps(rate_hz_);
    st.lod(intestine_ != nullptr ? static_cast<std::uint32_t>(intestine_->lod()) : 0);
    st.last_seq_shown(have_frame ? frame.seq() : 0);
    st.echoed_stamp_ns(0);  // round trips are echoed by the frame listener, on arrival
    st.frames_rendered(frames_rendered_);
    dds_->status_writer->write(&st);

    next += period;
    const auto now = clock::now();
    if (next < now) next = now;  // fell behind: do not burst
    std::this_thread::sleep_until(next);
  }
  wall_seconds_ = static_cast<double>(monotonic_ns() - wall_start) * 1e-9;
  return hash_ok ? 0 : 3;
}

namespace {
// Finds a program on PATH.
bool on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (path == nullptr) return false;
  std::stringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (!dir.empty() && ::access((dir + "/" + name).c_str(), X_OK) == 0) return true;
  }
  return false;
}
}  // namespace

void VisualApp::shutdown() {
  // The PNG frames as an MP4 when asked and Debian's ffmpeg is there (never required).
  if ((options_.video || scene_.visual.video) && pngs_written_ > 1) {
    if (!on_path("ffmpeg")) {
      video_ = "skipped: ffmpeg not found (apt-get install ffmpeg, or SURGSIM_WITH_VIDEO=1 scripts/setup.sh)";
    } else {
      const double fps = rate_hz_ / std::max(1, png_every_);
      const std::string out = options_.out + "/video.mp4";
      const std::string cmd = "ffmpeg -y -loglevel error -framerate " + std::to_string(fps) + " -pattern_type glob -i '" +
                              options_.out + "/frame_*.png' -c:v libx264 -pix_fmt yuv420p '" + out + "'";
      video_ = std::system(cmd.c_str()) == 0 ? out : "failed: " + cmd;
    }
    if (!options_.quiet) std::cerr << "visual_node: video " << video_ << "\n";
  }
  msg::SceneInfo info;
  const bool have_info = dds_->scene_info.get(info);
  const Percentiles latency = dds_->frames.latency();
  const Percentiles deform = deform_us_.summary();
  const Percentiles render = render_ms_.summary();
  nlohmann::json j;
  j["node"] = "visual";
  j["scene"] = scene_.name;
  j["renderer"] = renderer_->name();
  j["frames_received"] = dds_->frames.received();
  j["frames_rendered"] = frames_rendered_;
  j["pngs_written"] = pngs_written_;
  j["png_errors"] = png_errors_;
  j["vtk_written"] = vtk_written_;
  j["video"] = video_;
  j["deform_errors"] = deform_errors_;
  j["visible_nodes"] = deformer_ != nullptr ? deformer_->visible_nodes().size() : 0;
  j["tensor_rows"] = tensors_.find("visual") != nullptr ? tensors_.find("visual")->row_count() : 0;
  j["fps"] = wall_seconds_ > 0 ? static_cast<double>(frames_rendered_) / wall_seconds_ : 0.0;
  j["wall_seconds"] = wall_seconds_;
  j["deform_us"] = to_json(deform);
  j["render_ms"] = to_json(render);
  j["latency_us"] = to_json(latency);
  j["scene_info_received"] = have_info;
  j["scene_hash_ok"] = have_info && info.scene_hash() == scene_hash_;
  j["tensor_hash_ok"] = have_info && info.tensor_hash() == tensor_hash_;
  j["out"] = options_.out;
  j["first_png"] = first_png_;
  j["last_png"] = last_png_;
  j["dds_participant"] = dds_->participant.profile();
  j["dds_threads"] = dds_threads_note_;
  watch_.add_stats(j);
  // Which organ model this run built (a liver run builds no intestine objects, an intestine run no mesh or tensors).
  j["model_built"] = intestine_ != nullptr ? "intestine" : "liver";
  if (intestine_ != nullptr) {
    j["intestine"] = intestine_->stats();
    j["lod_mean"] = j["intestine"]["lod_mean"];
    j["lod_target_fps"] = j["intestine"]["target_fps"];
  }
  if (!options_.stats.empty()) write_json_file(options_.stats, j);
  if (!options_.quiet) {
    std::cerr << "visual_node: " << frames_rendered_ << " frames rendered (" << j["fps"].get<double>() << " fps), "
              << j["frames_received"].get<std::uint64_t>() << " contact frames received, latency p50 " << latency.p50
              << " us p99 " << latency.p99 << " us, " << pngs_written_ << " PNG in " << options_.out << "\n";
  }
  if (!options_.quiet && intestine_ != nullptr) {
    const nlohmann::json& in = j["intestine"];
    std::cerr << "visual_node: intestine: " << in["body_states_received"].get<std::uint64_t>()
              << " body states received, LOD mean " << in["lod_mean"].get<double>() << " (final "
              << in["lod_final"].get<int>() << ", target " << in["target_fps"].get<double>() << " Hz, frame work p50 "
              << in["work_ms"]["p50"].get<double>() << " ms), tube up to " << in["tube_triangles_max"].get<int>()
              << " triangles\n";
  }
}

}  // namespace surgsim
