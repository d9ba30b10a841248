#include "visual_app.h"

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "dds_support.h"
#include "frame_output.h"
#include "frame_stream.h"
#include "instruments.h"
#include "mesher/scene_mesh.h"
#include "organ_view.h"
#include "os/thread_priority.h"
#include "render/renderer.h"
#include "visual_dds.h"

using namespace surgsim::core;
using namespace surgsim::os;
using namespace surgsim::tool;
using namespace surgsim::scene;
using namespace surgsim::mesher;

namespace surgsim {

namespace {

/// "'grasper', 'probe'": the scene's tool names, for messages.
std::string tool_names(const Scene& scene) {
  std::string out;
  for (const ToolSpec& t : scene.tools) out += (out.empty() ? "'" : ", '") + t.name + "'";
  return out;
}

/// SURGSIM_VISUAL_LOAD_STEP=AT:FOR:X (seconds, seconds, factor >= 1); false when unset. Throws on a malformed value.
bool parse_load_step(double& at, double& duration, double& factor) {
  const char* v = std::getenv("SURGSIM_VISUAL_LOAD_STEP");
  if (v == nullptr || *v == '\0') return false;
  char tail = 0;
  if (std::sscanf(v, "%lf:%lf:%lf%c", &at, &duration, &factor, &tail) != 3 || !(at >= 0) || !(duration > 0) ||
      !(factor >= 1) || !std::isfinite(at + duration + factor)) {
    throw_error("SURGSIM_VISUAL_LOAD_STEP='", v, "' is not AT:FOR:X (from AT >= 0 s after the first frame shown, for ",
                "FOR > 0 s, every frame's work X >= 1 times longer), e.g. 4:2:3");
  }
  return true;
}

}  // namespace

VisualApp::VisualApp(const VisualOptions& options) : options_(options), watch_(monotonic_ns(), options.quiet) {
  // --- init: scene and the organ (mesh, tensors, deformer or the intestine's tube) ---
  scene_ = load_scene(resolve_scene_path(options_.scene));
  rate_hz_ = options_.rate_hz > 0 ? options_.rate_hz : scene_.visual.rate_hz;
  if (!parse_load_step(load_at_s_, load_for_s_, load_factor_)) load_at_s_ = -1;
  trace_.reserve(kTraceCapacity);
  const int png_every = options_.png_every >= 0 ? options_.png_every : scene_.visual.png_every;
  if (options_.tube_skinning != "gpu" && options_.tube_skinning != "cpu") {
    throw_error("--tube-skinning '", options_.tube_skinning, "' is not a skinning path (use gpu or cpu)");
  }
  OrganViewOptions organ_options;
  organ_options.cache_dir = options_.cache_dir.empty() ? default_cache_dir() : options_.cache_dir;
  organ_options.tube_skinning =
      options_.tube_skinning == "cpu" ? intestine::TubeSkinning::kCpu : intestine::TubeSkinning::kGpu;
  organ_options.log = options_.quiet ? nullptr : &std::cerr;
  organ_ = make_organ_view(scene_, organ_options);
  scene_hash_ = visual_scene_hash(scene_, organ_->mesh_hash());

  // --- init: renderer (no GL context at all when headless) ---
  renderer_ = make_renderer(options_.headless ? "null" : "osmesa", scene_.visual.width, scene_.visual.height);
  renderer_->set_lighting(lighting_of(scene_.visual.render));
  // Dynamic resolution: frame work aimed at 0.6 of the period, so that the frames that overrun it still catch up.
  RenderScaleParams scale;
  scale.min_scale = scene_.visual.min_render_scale;
  scale.target_work_s = 0.6 / rate_hz_;
  render_scale_ = RenderScaleController(scale);
  organ_->attach(*renderer_);

  // --- init: frame output (the folder and frames.csv when PNGs are written) ---
  FrameOutputOptions out;
  out.out = options_.out;
  out.png_every = png_every;
  out.enabled = !options_.headless;
  out.vtk = scene_.visual.vtk;
  out.video = options_.video || scene_.visual.video;
  out.rate_hz = rate_hz_;
  out.quiet = options_.quiet;
  output_ = std::make_unique<FrameOutput>(out);

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
  dds_ = std::make_unique<VisualDds>(dopt, watch_, scene_hash_);
  watch_.mark_dds_ready(monotonic_ns());
  organ_->subscribe(dds_->participant());  // e.g. the intestine's BodyState
  dds_priority.reset();  // this thread renders at its previous scheduling
  start_stream();
  if (!options_.quiet) {
    const auto& p = dds_->participant();
    std::cerr << "visual_node: DDS " << p.profile() << ": " << p.description() << "; DDS threads " << dds_threads_note_
              << "\n";
  }

  if (!options_.quiet) {
    std::cerr << "visual_node: scene '" << scene_.name << "', " << organ_->surface_triangles() << " surface triangles, "
              << scene_.tools.size() << (scene_.tools.size() == 1 ? " instrument" : " instruments") << " ("
              << tool_names(scene_) << "), " << renderer_->name() << " renderer " << scene_.visual.width << "x"
              << scene_.visual.height << " at " << rate_hz_ << " Hz\n";
    organ_->print_init(std::cerr);
    if (load_at_s_ >= 0) {
      std::cerr << "visual_node: synthetic load (SURGSIM_VISUAL_LOAD_STEP): frame work x" << load_factor_ << " from "
                << load_at_s_ << " s after the first frame shown, for " << load_for_s_ << " s\n";
    }
  }
}

VisualApp::~VisualApp() {
  stream_.reset();  // the encoder thread writes on the DDS writer: joined before the participant goes
}

void VisualApp::start_stream() {
  stream_fps_ = options_.stream_fps >= 0 ? options_.stream_fps : scene_.visual.stream_fps;
  const int quality = options_.stream_quality > 0 ? options_.stream_quality : scene_.visual.stream_quality;
  if (!(stream_fps_ > 0)) return;
  if (!(stream_fps_ <= 120) || quality < 1 || quality > 100) {
    throw_error("--stream-fps ", stream_fps_, " / --stream-quality ", quality,
                " out of range: the stream rate is 0..120 Hz and the JPEG quality 1..100");
  }
  if (options_.headless) {
    std::cerr << "visual_node: --headless draws nothing: the frame stream (stream_fps " << stream_fps_
              << ") is off\n";
    stream_fps_ = 0;
    return;
  }
  auto& p = dds_->participant();
  auto* writer = p.writer(p.topic(kFrameTopic, new msg::FramePubSubType()), kFrameWriterProfile);
  FrameStreamOptions so;
  so.width = scene_.visual.width;
  so.height = scene_.visual.height;
  so.quality = quality;
  so.max_bytes = msg::kMaxFrameBytes;
  stream_ = std::make_unique<FrameStream>(so, [writer](const msg::Frame& f) { writer->write(const_cast<msg::Frame*>(&f)); });
  if (!options_.quiet) {
    std::cerr << "visual_node: streaming JPEG frames (quality " << quality << ") at " << stream_fps_ << " Hz on "
              << kFrameTopic << "\n";
  }
}

void VisualApp::offer_stream_frame(const msg::ContactFrame& frame, bool have_frame, std::uint64_t now,
                                   const Image* read) {
  if (!stream_ || now < next_stream_ns_) return;
  const auto period = static_cast<std::uint64_t>(1e9 / stream_fps_);
  next_stream_ns_ = next_stream_ns_ + period > now ? next_stream_ns_ + period : now + period;
  Image* slot = stream_->acquire();  // null: the encoder is still busy, this picture is dropped (counted)
  if (slot == nullptr) return;
  if (read != nullptr) {
    *slot = *read;  // same size as the preallocated slot: a copy, no allocation
  } else if (!renderer_->read_drawn_image(*slot)) {  // at the render scale: the page scales it to its view
    slot->resize(0, 0);
  }
  FrameStamp st;
  st.frame_number = frames_rendered_;
  st.render_stamp_ns = now;
  st.haptic_stamp_ns = have_frame ? frame.stamp_ns() : 0;
  st.haptic_seq = have_frame ? frame.seq() : 0;
  stream_->submit(st);
}

void VisualApp::check_scene_identity() {
  // Check the haptic side's scene identity once it is known; refuse to draw frames of another scene.
  msg::SceneInfo info;
  if (hash_checked_ || !dds_->scene_info(info)) return;
  hash_checked_ = true;
  const bool scene_ok = info.scene_hash() == scene_hash_;
  const bool tensors_ok = info.tensor_hash() == organ_->tensor_hash();
  const bool instruments_ok = info.instrument_count() == scene_.tools.size();
  hash_ok_ = scene_ok && tensors_ok && instruments_ok;
  scene_confirmed_ = hash_ok_;
  frames_before_scene_info_ = dds_->frames_accepted();
  if (!instruments_ok) {
    std::cerr << "visual_node: the haptic node drives " << info.instrument_count() << " instrument(s) in scene '"
              << info.scene_name() << "' but this node's scene '" << scene_.name << "' (" << scene_.file << ") has "
              << scene_.tools.size() << " (" << tool_names(scene_) << "): start both nodes with the same scene file; "
              << "contact frames are ignored\n";
  }
  if (!scene_ok) {
    std::cerr << "visual_node: the haptic node runs scene '" << info.scene_name() << "' (hash " << info.scene_hash()
              << ", mesh hash " << info.mesh_hash() << ") but this node loaded '" << scene_.name << "' (hash "
              << scene_hash_ << "): start both nodes with the same scene and mesh; contact frames are ignored\n";
  } else if (!tensors_ok) {
    std::cerr << "visual_node: the haptic node's tensors (hash " << info.tensor_hash() << ") differ from this "
              << "node's (hash " << organ_->tensor_hash() << ") for the same scene: both must use the same tensor "
              << "settings; contact frames are ignored\n";
  }
}

void VisualApp::report_wrong_scene() {
  std::uint64_t hash = 0;
  const std::uint64_t count = dds_->frames_wrong_scene(hash);
  if (count == 0 || hash == wrong_scene_reported_hash_) return;
  wrong_scene_reported_hash_ = hash;
  std::cerr << "visual_node: contact frame with scene hash " << hash << " ignored: this node's scene '" << scene_.name
            << "' has hash " << scene_hash_ << " (frames of another scene are dropped and counted in stats "
            << "frames_wrong_scene, " << count << " so far)\n";
}

void VisualApp::take_frame_instruments(const msg::ContactFrame& frame) {
  take_instruments(frame.instruments(), static_cast<int>(scene_.tools.size()), instruments_);
  if (instruments_.ignored == 0) return;
  instrument_states_ignored_ += static_cast<std::uint64_t>(instruments_.ignored);
  if (instrument_states_reported_) return;
  instrument_states_reported_ = true;
  std::uint32_t index = 0;  // the first state ignored, for the message
  std::array<bool, kMaxInstruments> seen{};
  for (const msg::InstrumentState& st : frame.instruments()) {
    const std::uint32_t i = st.instrument();
    if (i >= scene_.tools.size() || seen[i]) {
      index = i;
      break;
    }
    seen[i] = true;
  }
  std::cerr << "visual_node: contact frame " << frame.seq() << " carries a state for instrument " << index
            << " (out of range or repeated) but scene '" << scene_.name << "' (" << scene_.file << ") has "
            << scene_.tools.size() << " instrument(s) (" << tool_names(scene_) << "): such states are ignored "
            << "(counted in stats instrument_states_ignored)\n";
}

void VisualApp::render_frame(const msg::ContactFrame& frame, bool have_frame, bool fresh) {
  // The organ from the newest contacts (or its own state, e.g. the intestine's newest BodyState).
  const std::uint64_t work0 = monotonic_ns();
  const double deform_us = organ_->update(have_frame ? &frame : nullptr, fresh);
  if (deform_us >= 0) deform_us_.add(deform_us);
  if (fresh) take_frame_instruments(frame);

  const std::uint64_t r0 = monotonic_ns();
  drawn_scale_ = render_scale_.scale();
  renderer_->set_render_scale(static_cast<float>(drawn_scale_));
  renderer_->begin_frame(scene_.visual.camera);
  organ_->draw(*renderer_);
  // Every instrument: those of the organ's own state when it has them (the intestine's BodyState), else the newest
  // contact frame's.
  const InstrumentPoses* instruments = organ_->instruments();
  if (instruments == nullptr && have_frame) instruments = &instruments_;
  const int drawn = instruments != nullptr ? draw_instruments(*renderer_, scene_.tools, *instruments) : 0;
  if (scene_.visual.render.markers) organ_->draw_markers(*renderer_);
  renderer_->end_frame();
  // The synthetic load: this frame's work made load_factor_ times longer (a busy wait, as a slower renderer would).
  std::uint64_t work_end = monotonic_ns();
  last_load_on_ = false;
  if (load_at_s_ >= 0 && first_shown_ns_ != 0) {
    const double t = static_cast<double>(work_end - first_shown_ns_) * 1e-9;
    if (t >= load_at_s_ && t < load_at_s_ + load_for_s_) {
      last_load_on_ = true;
      const std::uint64_t until = work_end + static_cast<std::uint64_t>((load_factor_ - 1) * static_cast<double>(work_end - work0));
      while (monotonic_ns() < until) {
      }
      work_end = monotonic_ns();
    }
  }
  last_work_ms_ = static_cast<double>(work_end - work0) * 1e-6;
  organ_->frame_done(static_cast<double>(work_end - work0) * 1e-9);
  render_scale_.update(static_cast<double>(work_end - work0) * 1e-9);
  ++frames_rendered_;
  const std::uint64_t done_ns = monotonic_ns();
  const bool png = output_->due(frames_rendered_) && renderer_->read_image(image_);
  offer_stream_frame(frame, have_frame, done_ns, png ? &image_ : nullptr);  // a frame streamed and written: read once
  if (png) output_->write(image_, frames_rendered_, frame.seq(), have_frame ? frame.sim_time() : -1.0, *organ_, drawn);
  render_ms_.add(static_cast<double>(monotonic_ns() - r0) * 1e-6);
}

int VisualApp::run() {
  using clock = std::chrono::steady_clock;
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / rate_hz_));
  const std::uint64_t wall_start = monotonic_ns();
  auto next = clock::now();

  msg::ContactFrame frame;
  bool have_frame = false;
  output_->flush();

  while (!stop_requested_.load(std::memory_order_relaxed)) {
    if (options_.duration >= 0 && static_cast<double>(monotonic_ns() - wall_start) * 1e-9 >= options_.duration) break;
    if (options_.idle_exit > 0 && dds_->frames_received() > 0 &&
        static_cast<double>(monotonic_ns() - dds_->last_receive_ns()) * 1e-9 > options_.idle_exit) {
      break;
    }
    check_scene_identity();
    report_wrong_scene();

    // Frames are taken only once SceneInfo confirmed the scene (until then the newest one waits in VisualDds), and
    // only frames carrying this node's scene_hash are ever kept there.
    std::uint64_t received = 0;
    const bool fresh = scene_confirmed_ && dds_->newest_frame(frame, received);
    if (fresh) {
      have_frame = true;
      ++frames_shown_;
      if (first_shown_ns_ == 0) first_shown_ns_ = monotonic_ns();
    }
    const int lod_drawn = static_cast<int>(organ_->lod());
    render_frame(frame, have_frame, fresh);
    const std::uint64_t end_ns = monotonic_ns();
    frame_rate_.add(end_ns);
    const double interval_ms =
        last_frame_end_ns_ != 0 ? static_cast<double>(end_ns - last_frame_end_ns_) * 1e-6 : 0.0;
    if (last_frame_end_ns_ != 0) interval_ms_.add(interval_ms);
    last_frame_end_ns_ = end_ns;
    if (trace_.size() < kTraceCapacity) {
      const double t_s =
          first_shown_ns_ != 0 ? (static_cast<double>(end_ns) - static_cast<double>(first_shown_ns_)) * 1e-9 : -1.0;
      trace_.push_back(
          TraceRow{t_s, last_work_ms_, interval_ms, frame_rate_.fps(), lod_drawn, last_load_on_, drawn_scale_});
    } else {
      ++trace_dropped_;
    }

    // The measured frame rate (not the configured one); the frame shown.
    dds_->publish_status(frame_rate_.fps(), organ_->lod(), have_frame ? frame.seq() : 0, frames_rendered_);

    // This frame was due at `next`; the next one at next + period. Late by less than a period: start it at once
    // (catch up, the mean rate holds); later than that: restart the schedule from now (no burst after a stall).
    const auto now = clock::now();
    next += period;
    if (now > next) ++frames_late_;  // overran its period: the next frame starts at once
    if (now - next > period) {
      next = now;
      ++schedule_restarts_;
    }
    std::this_thread::sleep_until(next);
  }
  wall_seconds_ = static_cast<double>(monotonic_ns() - wall_start) * 1e-9;
  return hash_ok_ ? 0 : 3;
}

void VisualApp::shutdown() {
  output_->finish();  // the video, when asked
  msg::SceneInfo info;
  const bool have_info = dds_->scene_info(info);
  const Percentiles latency = dds_->latency();
  const Percentiles deform = deform_us_.summary();
  const Percentiles render = render_ms_.summary();
  nlohmann::json j;
  j["node"] = "visual";
  j["scene"] = scene_.name;
  j["renderer"] = renderer_->name();
  j["frames_received"] = dds_->frames_received();
  j["frames_rendered"] = frames_rendered_;
  std::uint64_t wrong_hash = 0;
  j["frames_wrong_scene"] = dds_->frames_wrong_scene(wrong_hash);  // dropped: another scene_hash
  j["frames_before_scene_info"] = scene_confirmed_ ? frames_before_scene_info_ : dds_->frames_accepted();
  j["frames_shown"] = frames_shown_;                               // fresh frames drawn
  j["scene_confirmed"] = scene_confirmed_;
  output_->add_stats(j);  // pngs_written, png_errors, vtk_written, video, out, first_png, last_png
  j["deform_errors"] = organ_->deform_errors();
  j["visible_nodes"] = 0;  // the organ's own keys below (model_built; visible_nodes, tensor_rows, ... when it has them)
  j["tensor_rows"] = 0;
  j["fps"] = wall_seconds_ > 0 ? static_cast<double>(frames_rendered_) / wall_seconds_ : 0.0;
  j["fps_configured"] = rate_hz_;
  j["frame_interval_ms"] = to_json(interval_ms_.summary());
  j["frames_late"] = frames_late_;                // ended after the next frame was due (overran their period)
  j["schedule_restarts"] = schedule_restarts_;    // more than a period late: the schedule restarted from then
  if (load_at_s_ >= 0) {
    j["load_step"] = {{"at_s", load_at_s_}, {"for_s", load_for_s_}, {"factor", load_factor_}};
  }
  write_trace(j);
  // Dynamic resolution (visual.min_render_scale): the scale drawn at the end, the lowest, the frames below 1.
  const RenderScaleParams& rs = render_scale_.params();
  j["render_scale"] = {{"min_allowed", rs.min_scale},
                       {"target_work_ms", rs.target_work_s * 1e3},
                       {"final", render_scale_.scale()},
                       {"min", render_scale_.min_seen()},
                       {"frames_scaled", render_scale_.frames_scaled()},
                       {"share_scaled", render_scale_.frames() > 0
                                            ? static_cast<double>(render_scale_.frames_scaled()) /
                                                  static_cast<double>(render_scale_.frames())
                                            : 0.0}};
  j["wall_seconds"] = wall_seconds_;
  j["deform_us"] = to_json(deform);
  j["render_ms"] = to_json(render);
  j["latency_us"] = to_json(latency);
  j["scene_info_received"] = have_info;
  j["scene_hash_ok"] = have_info && info.scene_hash() == scene_hash_;
  j["tensor_hash_ok"] = have_info && info.tensor_hash() == organ_->tensor_hash();
  j["instruments"] = scene_.tools.size();  // the scene's instruments, drawn from the frames' InstrumentStates
  j["instrument_count_ok"] = have_info && info.instrument_count() == scene_.tools.size();
  j["instrument_states_ignored"] = instrument_states_ignored_;  // states naming no instrument of the scene
  j["dds_participant"] = dds_->participant().profile();
  j["dds_threads"] = dds_threads_note_;
  if (stream_) stream_->add_stats(j, stream_fps_);
  watch_.add_stats(j);
  organ_->add_stats(j);
  if (!options_.stats.empty()) write_json_file(options_.stats, j);
  if (!options_.quiet) {
    std::cerr << "visual_node: " << frames_rendered_ << " frames rendered (" << j["fps"].get<double>() << " fps), "
              << j["frames_received"].get<std::uint64_t>() << " contact frames received, latency p50 " << latency.p50
              << " us p99 " << latency.p99 << " us, " << output_->pngs_written() << " PNG in " << output_->out()
              << "\n";
    organ_->print_summary(std::cerr, j);
  }
}

void VisualApp::write_trace(nlohmann::json& j) const {
  j["frame_trace_rows"] = trace_.size();
  j["frame_trace_dropped"] = trace_dropped_;
  if (options_.headless || options_.out.empty()) return;
  const std::string path = options_.out + "/frame_trace.csv";
  std::error_code ec;
  std::filesystem::create_directories(options_.out, ec);
  std::ofstream f(path);
  if (!f) {
    std::cerr << "visual_node: cannot write " << path << "\n";
    return;
  }
  f << "t_s,lod,work_ms,interval_ms,fps,load_on,scale\n";
  char line[176];
  for (const TraceRow& r : trace_) {
    std::snprintf(line, sizeof line, "%.6f,%d,%.4f,%.4f,%.3f,%d,%.4f\n", r.t_s, r.lod, r.work_ms, r.interval_ms, r.fps,
                  r.load_on ? 1 : 0, r.scale);
    f << line;
  }
  j["frame_trace"] = path;
}

}  // namespace surgsim
