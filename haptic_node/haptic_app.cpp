#include "haptic_app.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "Surgsim.h"
#include "SurgsimPubSubTypes.h"
#include "core/clock.h"
#include "dds_support.h"
#include "core/error.h"
#include "rt_loop.h"
#include "mesher/scene_mesh.h"
#include "liver/liver_setup.h"
#include "liver/tensor_cache.h"
#include "os/thread_priority.h"
#include "tool/tool.h"

namespace surgsim {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::SampleInfo;

namespace {

msg::Vec3 to_msg(const Eigen::Vector3d& v) {
  msg::Vec3 m;
  m.x(v.x());
  m.y(v.y());
  m.z(v.z());
  return m;
}

msg::ToolPose to_msg(const Pose5& p) {
  msg::ToolPose m;
  m.pitch(p.pitch);
  m.yaw(p.yaw);
  m.insertion(p.insertion);
  m.roll(p.roll);
  m.jaw(p.jaw);
  return m;
}

// Round-trip latency from VisualStatus echoes (runs on the DDS listener thread).
class VisualStatusListener : public DataReaderListener {
 public:
  explicit VisualStatusListener(std::size_t capacity) : rtt_us_(capacity) {}
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&status_, &info) == eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data || status_.echoed_stamp_ns() == 0) continue;
      const std::uint64_t now = monotonic_ns();
      std::lock_guard<std::mutex> lock(mutex_);
      if (status_.echoed_stamp_ns() == last_echo_) continue;  // the same frame echoed again
      last_echo_ = status_.echoed_stamp_ns();
      rtt_us_.add(static_cast<double>(now - status_.echoed_stamp_ns()) * 1e-3);
      ++received_;
    }
  }
  Percentiles summary() {
    std::lock_guard<std::mutex> lock(mutex_);
    return rtt_us_.summary();
  }
  std::uint64_t received() {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }

 private:
  std::mutex mutex_;
  msg::VisualStatus status_;
  SampleRecorder rtt_us_;
  std::uint64_t last_echo_ = 0;
  std::uint64_t received_ = 0;
};

// Newest device command. The loop reads it with try_lock, so it never waits on the DDS thread.
class ToolCommandListener : public DataReaderListener {
 public:
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&incoming_, &info) == eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      const auto& p = incoming_.pose();
      pose_ = Pose5{p.pitch(), p.yaw(), p.insertion(), p.roll(), p.jaw()};
      receive_ns_ = monotonic_ns();
      ++received_;
    }
  }
  /// Non-blocking: false when the slot is busy (the caller keeps its previous value).
  bool try_get(Pose5& pose, std::uint64_t& receive_ns, std::uint64_t& received) {
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    pose = pose_;
    receive_ns = receive_ns_;
    received = received_;
    return true;
  }

 private:
  std::mutex mutex_;
  msg::ToolCommand incoming_;
  Pose5 pose_;
  std::uint64_t receive_ns_ = 0;
  std::uint64_t received_ = 0;
};

}  // namespace

struct HapticApp::Dds {
  explicit Dds(const dds::DdsOptions& o) : visual_status(1 << 16), participant(o) {}
  // Listeners first: members are destroyed in reverse order, so the participant (and its readers, whose callbacks
  // use the listeners) goes before them.
  VisualStatusListener visual_status;
  ToolCommandListener tool_commands;
  dds::Participant participant;
  Pose5 last_command;
  std::uint64_t last_command_ns = 0;
  std::uint64_t commands_received = 0;
  DataWriter* contact_writer = nullptr;
  DataWriter* force_writer = nullptr;
  DataWriter* scene_writer = nullptr;
  DataReader* status_reader = nullptr;
  // Samples allocated once; the loop only overwrites their fields.
  msg::ContactFrame frame;
  msg::ForceFeedback force;
};

HapticApp::HapticApp(const HapticOptions& options) : options_(options), tick_us_(1), wake_late_us_(1) {
  // --- init: scene, mesh, trajectory ---
  scene_ = load_scene(resolve_scene_path(options_.scene));
  rate_hz_ = options_.rate_hz > 0 ? options_.rate_hz : scene_.haptic.rate_hz;
  if (!(rate_hz_ >= 1 && rate_hz_ <= 20000)) throw_error("--rate ", rate_hz_, " Hz is out of range [1, 20000]");
  dt_ = 1.0 / rate_hz_;
  const std::string cache = options_.cache_dir.empty() ? default_cache_dir() : options_.cache_dir;
  if (scene_.model != "intestine") {  // the intestine builds its own body: no tetrahedral mesh (hash 0)
    mesh_ = load_scene_mesh(scene_, cache, options_.quiet ? nullptr : &std::cerr);
    surface_ = boundary_surface(mesh_);
    mesh_hash_ = mesh_hash(mesh_);
  }
  scene_hash_ = scene_.hash() ^ (mesh_hash_ * 0x9E3779B97F4A7C15ull);

  // --- init: tool input ---
  if (options_.input != "replay" && options_.input != "device") {
    throw_error("--input '", options_.input, "' is not an input (use replay or device)");
  }
  live_ = options_.input == "device";
  std::string replay;
  if (!live_) {
    replay = options_.replay.empty() ? scene_.trajectory : options_.replay;
    if (replay.empty()) throw_error(scene_.file, ": no trajectory to replay (give --replay FILE or set 'trajectory')");
    trajectory_ = Trajectory::load(replay);
    held_pose_ = trajectory_.at(0);
  }
  double duration = options_.duration;
  if (duration < 0) duration = live_ ? 3600.0 : trajectory_.duration() + 0.5;
  total_ticks_ = static_cast<std::uint64_t>(std::llround(duration * rate_hz_));
  if (total_ticks_ == 0) total_ticks_ = 1;

  // --- init: the organ model this scene names (a liver scene builds tensors, contacts and the bucket grid) ---
  if (scene_.model == "liver") {
    const LiverTensorSetup setup = liver_tensor_setup(scene_.material, scene_.fixed, mesh_, cache, scene_.file);
    tensors_ = load_liver_tensors(setup, mesh_, scene_.material, {"haptic"}, options_.quiet ? nullptr : &std::cerr,
                                  nullptr, scene_.file);
    tensor_hash_ = setup.key.combined();
    law_ = std::make_unique<NonlinearLaw>(load_nonlinear_law(scene_.nonlinear, scene_.material));
    contacts_ = std::make_unique<LiverContacts>(mesh_, surface_, tensors_, scene_.tool,
                                                law_->identity() ? nullptr : law_.get());
  } else if (scene_.model == "intestine") {
    // The mass-spring intestine and mesentery only: no mesh, tensors or bucket grid (DESIGN.md 6).
    intestine_ = std::make_unique<IntestineRunner>(scene_, total_ticks_);
  } else {
    throw_error(scene_.file, ": key 'model': '", scene_.model, "' is not built into this haptic node yet");
  }

  // --- init: outputs ---
  if (!options_.record.empty()) {
    recorder_.open(options_.record);
    record_writer_ = std::make_unique<AsyncLineWriter>(recorder_.file(), options_.speed <= 0);
  }
  if (!options_.log.empty()) {
    log_ = std::fopen(options_.log.c_str(), "w");
    if (log_ == nullptr) throw_error(options_.log, ": cannot create the --log file");
    std::setvbuf(log_, nullptr, _IOFBF, 1 << 16);
    std::fprintf(log_, "tick,t,fx,fy,fz,contacts\n");
    std::fflush(log_);
    log_writer_ = std::make_unique<AsyncLineWriter>(log_, options_.speed <= 0);
  }
  tick_us_ = SampleRecorder(total_ticks_ + 16);
  wake_late_us_ = SampleRecorder(total_ticks_ + 16);

  // --- init: DDS entities (QoS from the XML profiles) ---
  // Their threads start at SCHED_FIFO below the loop's priority (thread_priority.h): a device command or a visual
  // status is taken the moment it arrives, and never delays the loop.
  // Never at or above the loop: with a normally scheduled loop (--rt-priority 0) or --speed max, they stay normal too.
  const int dds_priority_value = options_.speed > 0 && options_.rt_priority > 1
                                     ? std::min(options_.dds_rt_priority, options_.rt_priority - 1) : 0;
  std::optional<ScopedFifo> dds_priority(std::in_place, dds_priority_value);
  dds_threads_note_ = dds_priority->note();
  dds::DdsOptions dopt;
  dopt.domain = options_.domain >= 0 ? options_.domain : dds::default_domain();
  dopt.profiles_file = options_.dds_profiles.empty() ? config_dir() + "/dds/profiles.xml" : options_.dds_profiles;
  dopt.participant_profile = options_.dds_participant;
  dopt.name = "surgsim_haptic";
  dds_ = std::make_unique<Dds>(dopt);
  auto& p = dds_->participant;
  dds_->contact_writer = p.writer(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kContactWriter);
  dds_->force_writer = p.writer(p.topic(dds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), dds::kStreamWriter);
  dds_->scene_writer = p.writer(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedWriter);
  if (live_) {
    p.reader(p.topic(dds::kToolCommandTopic, new msg::ToolCommandPubSubType()), dds::kStreamReader,
             &dds_->tool_commands);
  }
  dds_->status_reader = p.reader(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()),
                                 dds::kStreamReader, &dds_->visual_status);
  dds_->frame.contacts().reserve(msg::kMaxContacts);
  if (!options_.quiet)
    std::cerr << "haptic_node: DDS " << p.profile() << ": " << p.description() << "; DDS threads " << dds_threads_note_
              << "\n";
  dds_->frame.scene_hash(scene_hash_);
  if (intestine_ != nullptr) intestine_->create_writer(p, scene_hash_);  // BodyState, every tick
  dds_priority.reset();

  // SceneInfo is latched (transient local): a visual node that joins later still gets it.
  msg::SceneInfo info;
  info.scene_name(scene_.name);
  info.scene_hash(scene_hash_);
  info.mesh_hash(mesh_hash_);
  info.material_hash(material_hash(scene_.material));
  info.tensor_hash(tensor_hash_);
  info.node_count(static_cast<std::uint32_t>(mesh_.nodes.rows()));
  info.surface_node_count(static_cast<std::uint32_t>(surface_.nodes.size()));
  if (intestine_ != nullptr) {  // the body's masses, and the intestine's points among them
    info.node_count(static_cast<std::uint32_t>(intestine_->model().node_count()));
    info.surface_node_count(static_cast<std::uint32_t>(intestine_->model().columns()));
  }
  info.haptic_rate_hz(rate_hz_);
  info.visual_rate_hz(scene_.visual.rate_hz);
  info.start_stamp_ns(monotonic_ns());
  dds_->scene_writer->write(&info);

  if (!options_.quiet) {
    std::cerr << "haptic_node: scene '" << scene_.name << "' (" << scene_.file << "), ";
    if (intestine_ != nullptr) {
      std::cerr << intestine_->model().rows() << " x " << intestine_->model().columns()
                << " masses (intestine and mesentery, mass-spring); ";
    } else {
      std::cerr << mesh_.nodes.rows() << " nodes, " << mesh_.tets.rows() << " tets, " << surface_.nodes.size()
                << " surface nodes; ";
    }
    std::cerr << rate_hz_ << " Hz for " << total_ticks_ << " ticks; "
              << (live_ ? std::string("live input from the device topic") : "replaying " + replay) << "\n";
  }
}

HapticApp::~HapticApp() {
  // The writer threads drain into the files, so they stop before the files close.
  record_writer_.reset();
  log_writer_.reset();
  if (log_ != nullptr) std::fclose(log_);
}

bool HapticApp::input_pose(double t, Pose5& pose) {
  if (!live_) {
    pose = trajectory_.at(t);
    return true;
  }
  dds_->tool_commands.try_get(dds_->last_command, dds_->last_command_ns, dds_->commands_received);
  const bool fresh = dds_->commands_received > 0 &&
                     static_cast<double>(monotonic_ns() - dds_->last_command_ns) * 1e-9 <= options_.input_timeout;
  pose = fresh ? dds_->last_command : held_pose_;
  return fresh;
}

void HapticApp::tick(std::uint64_t k) {
  const double t = static_cast<double>(k) * dt_;

  // --- input: a lost device drops every contact, zeroes the force and holds the tool where it was ---
  Pose5 pose;
  const bool input_ok = input_pose(t, pose);
  ContactTick result;
  std::uint32_t flags = 0;
  const ToolGeometry tool = tool_geometry(scene_.tool, pose);
  if (input_ok) {
    held_pose_ = pose;
    if (record_writer_ != nullptr) {
      if (char* line = record_writer_->begin_line()) {
        const int n = recorder_.format(line, record_writer_->slot_bytes(), t, pose);
        if (n > 0) record_writer_->commit_line(static_cast<std::size_t>(n));
      }
    }
    if (intestine_ != nullptr) {
      intestine_->step(&tool, dt_, result);  // the tool tip is the probe
    } else {
      contacts_->step(tool, pose.jaw, result);
    }
  } else {
    ++input_lost_ticks_;
    flags |= msg::kFlagInputLost;
    if (intestine_ != nullptr) {
      intestine_->step(nullptr, dt_, result);  // the body keeps moving, without the probe
    } else {
      contacts_->reset();
    }
  }
  const ContactSolution& solution = contacts_ != nullptr ? contacts_->solution() : no_contacts_;
  if (result.nonfinite) {
    ++nonfinite_rejected_;
    flags |= msg::kFlagNonFiniteHeld;
  }
  if (result.over_capacity) {
    ++over_capacity_events_;
    flags |= msg::kFlagOverCapacity;
  }
  if (result.saturated) {
    ++saturated_ticks_;
    flags |= msg::kFlagSaturated;
  }
  if (result.grasp) flags |= msg::kFlagGrasp;

  // --- publish: contact frame (visual node) and force (device) ---
  auto& frame = dds_->frame;
  frame.seq(k);
  frame.sim_time(t);
  frame.pose(to_msg(pose));
  frame.tip(to_msg(tool.tip));
  auto& entries = frame.contacts();
  entries.resize(static_cast<std::size_t>(solution.count));  // within the reserved capacity: no allocation
  for (int l = 0; l < solution.count; ++l) {
    auto& e = entries[static_cast<std::size_t>(l)];
    e.node(static_cast<std::uint32_t>(solution.nodes[static_cast<std::size_t>(l)]));
    e.lambda(to_msg(solution.lambda[static_cast<std::size_t>(l)]));
    e.u_tilde(to_msg(contacts_->corrected(l)));
  }
  frame.direction(to_msg(result.direction));
  frame.force(to_msg(result.force));
  frame.contact_points(static_cast<std::uint32_t>(result.points_in_contact));
  frame.flags(flags);
  frame.stamp_ns(monotonic_ns());
  dds_->contact_writer->write(&frame);

  auto& ff = dds_->force;
  ff.seq(k);
  ff.stamp_ns(frame.stamp_ns());
  ff.force(to_msg(result.device_force));
  ff.saturated(result.saturated);
  ff.flags(flags);
  dds_->force_writer->write(&ff);
  if (intestine_ != nullptr) intestine_->publish(frame);  // BodyState: the body's positions this tick

  // --- log and statistics (contacts: liver contact nodes, or intestine elements the probe touches) ---
  const Eigen::Vector3d& f = result.device_force;
  const int contacts = intestine_ != nullptr ? result.points_in_contact : solution.count;
  if (log_writer_ != nullptr) {
    if (char* line = log_writer_->begin_line()) {
      const int n = std::snprintf(line, log_writer_->slot_bytes(), "%llu,%.9f,%.17g,%.17g,%.17g,%d\n",
                                  static_cast<unsigned long long>(k), t, f.x(), f.y(), f.z(), contacts);
      if (n > 0) log_writer_->commit_line(static_cast<std::size_t>(n));
    }
  }
  if (contacts > contacts_max_) contacts_max_ = contacts;
  if (contacts > 0) ++contact_ticks_;
  force_max_n_ = std::max(force_max_n_, f.norm());
}

int HapticApp::run() {
  // Optionally wait until a visual node has matched our contact writer (so a demo does not lose its start).
  if (options_.wait_for_visual > 0) {
    const std::uint64_t until = monotonic_ns() + static_cast<std::uint64_t>(options_.wait_for_visual * 1e9);
    eprosima::fastdds::dds::PublicationMatchedStatus st;
    while (monotonic_ns() < until && !stop_requested_.load(std::memory_order_relaxed)) {
      dds_->contact_writer->get_publication_matched_status(st);
      if (st.current_count > 0) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }

  const RealtimeStatus rt = enter_realtime(options_.speed > 0 ? options_.rt_priority : 0, options_.lock_memory, options_.cpu);
  realtime_note_ = rt.note;
  if (!options_.quiet) std::cerr << "haptic_node: " << rt.note << "\n";

  // --- run: the loop (no allocation from here to the end of the loop) ---
  const bool paced = options_.speed > 0;
  const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 * dt_ / (paced ? options_.speed : 1.0)));
  PeriodicTimer timer(period_ns);
  timer.start();
  const std::uint64_t wall_start = monotonic_ns();
  loop_start_ns_ = wall_start;
  for (std::uint64_t k = 0; k < total_ticks_; ++k) {
    if (stop_requested_.load(std::memory_order_relaxed)) break;
    if (paced) wake_late_us_.add(static_cast<double>(timer.wait()) * 1e-3);
    const std::uint64_t t0 = monotonic_ns();
    tick(k);
    tick_us_.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
    ticks_done_ = k + 1;
  }
  wall_seconds_ = static_cast<double>(monotonic_ns() - wall_start) * 1e-9;
  deadline_misses_ = paced ? timer.misses() : 0;
  // --- shutdown starts here: the writer threads drain every line before the files close ---
  for (auto* w : {record_writer_.get(), log_writer_.get()}) {
    if (w != nullptr) w->finish();
  }
  record_writer_stats_ = record_writer_ ? record_writer_->dropped() + record_writer_->write_errors() : 0;
  log_writer_stats_ = log_writer_ ? log_writer_->dropped() + log_writer_->write_errors() : 0;
  record_writer_.reset();
  log_writer_.reset();
  recorder_.close();
  if (log_ != nullptr) std::fflush(log_);
  return 0;
}

void HapticApp::shutdown() {
  const Percentiles tick = tick_us_.summary();
  const Percentiles late = wake_late_us_.summary();
  const Percentiles rtt = dds_->visual_status.summary();
  const double achieved = wall_seconds_ > 0 ? static_cast<double>(ticks_done_) / wall_seconds_ : 0.0;
  nlohmann::json j;
  j["node"] = "haptic";
  j["scene"] = scene_.name;
  j["rate_hz"] = rate_hz_;
  j["speed"] = options_.speed > 0 ? nlohmann::json(options_.speed) : nlohmann::json("max");
  j["ticks"] = ticks_done_;
  j["sim_seconds"] = static_cast<double>(ticks_done_) * dt_;
  j["wall_seconds"] = wall_seconds_;
  j["achieved_hz"] = achieved;
  j["tick_us"] = to_json(tick);
  j["wake_late_us"] = to_json(late);
  j["deadline_misses"] = deadline_misses_;
  j["contacts_max"] = contacts_max_;
  j["force_max_n"] = force_max_n_;
  j["nonfinite_rejected"] = nonfinite_rejected_;
  j["over_capacity_events"] = over_capacity_events_;
  j["saturated_ticks"] = saturated_ticks_;
  j["contact_ticks"] = contact_ticks_;
  j["input"] = live_ ? "device" : "replay";
  j["input_lost_ticks"] = input_lost_ticks_;
  j["commands_received"] = dds_->commands_received;
  j["tensor_hash"] = std::to_string(tensor_hash_);
  j["nonlinear_law"] = law_ != nullptr && !law_->identity();
  j["round_trip_us"] = to_json(rtt);
  j["visual_status_received"] = dds_->visual_status.received();
  j["realtime"] = realtime_note_;
  j["scene_hash"] = std::to_string(scene_hash_);
  j["record_write_errors"] = recorder_.write_errors();
  j["record_lines_lost"] = record_writer_stats_;
  j["log_lines_lost"] = log_writer_stats_;
  j["dds_participant"] = dds_->participant.profile();
  j["dds_threads"] = dds_threads_note_;
  j["loop_start_ns"] = loop_start_ns_;
  // Which organ model this run built (a liver run builds no intestine objects, an intestine run no liver ones).
  j["model_built"] = intestine_ != nullptr ? "intestine" : contacts_ != nullptr ? "liver" : "none";
  if (intestine_ != nullptr) j["intestine"] = intestine_->stats();
  if (!options_.stats.empty()) write_json_file(options_.stats, j);
  if (!options_.quiet) {
    std::cerr << "haptic_node: " << ticks_done_ << " ticks at " << achieved << " Hz (target "
              << rate_hz_ * (options_.speed > 0 ? options_.speed : 0) << "), tick p50 " << tick.p50 << " us p99 "
              << tick.p99 << " us, " << deadline_misses_ << " missed deadlines, contacts max " << contacts_max_
              << ", force max " << force_max_n_ << " N, round trip p50 " << rtt.p50
              << " us (" << rtt.count << " echoes)\n";
  }
  if (!options_.quiet && intestine_ != nullptr) {
    const nlohmann::json& in = j["intestine"];
    std::cerr << "haptic_node: intestine step p50 " << in["step_us"]["p50"].get<double>() << " us p99 "
              << in["step_us"]["p99"].get<double>() << " us, " << in["faults"].get<std::uint64_t>() << " faults, "
              << "self-contacts max " << in["self_contacts_max"].get<int>() << ", probe contacts max "
              << in["probe_contacts_max"].get<int>() << ", " << in["body_states_published"].get<std::uint64_t>()
              << " body states published\n";
  }
}

}  // namespace surgsim
