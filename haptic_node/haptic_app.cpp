#include "haptic_app.h"

#include <cmath>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "Surgsim.h"
#include "SurgsimPubSubTypes.h"
#include "clock.h"
#include "dds_support.h"
#include "error.h"
#include "rt_loop.h"
#include "scene_mesh.h"
#include "tensor_cache.h"
#include "tool.h"

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

}  // namespace

struct HapticApp::Dds {
  explicit Dds(const dds::DdsOptions& o) : participant(o), visual_status(1 << 16) {}
  dds::Participant participant;
  VisualStatusListener visual_status;
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
  mesh_ = load_scene_mesh(scene_, cache, options_.quiet ? nullptr : &std::cerr);
  surface_ = boundary_surface(mesh_);
  mesh_hash_ = mesh_hash(mesh_);
  scene_hash_ = scene_.hash() ^ (mesh_hash_ * 0x9E3779B97F4A7C15ull);

  const std::string replay = options_.replay.empty() ? scene_.trajectory : options_.replay;
  if (replay.empty()) throw_error(scene_.file, ": no trajectory to replay (give --replay FILE or set 'trajectory')");
  trajectory_ = Trajectory::load(replay);

  double duration = options_.duration;
  if (duration < 0) duration = trajectory_.duration() + 0.5;
  total_ticks_ = static_cast<std::uint64_t>(std::llround(duration * rate_hz_));
  if (total_ticks_ == 0) total_ticks_ = 1;

  // --- init: outputs ---
  if (!options_.record.empty()) recorder_.open(options_.record);
  if (!options_.log.empty()) {
    log_ = std::fopen(options_.log.c_str(), "w");
    if (log_ == nullptr) throw_error(options_.log, ": cannot create the --log file");
    std::setvbuf(log_, nullptr, _IOFBF, 1 << 16);
    std::fprintf(log_, "tick,t,fx,fy,fz,contacts\n");
  }
  tick_us_ = SampleRecorder(total_ticks_ + 16);
  wake_late_us_ = SampleRecorder(total_ticks_ + 16);

  // --- init: DDS entities (QoS from the XML profiles) ---
  dds::DdsOptions dopt;
  dopt.domain = options_.domain >= 0 ? options_.domain : dds::default_domain();
  dopt.profiles_file = options_.dds_profiles.empty() ? config_dir() + "/dds/profiles.xml" : options_.dds_profiles;
  dopt.participant_profile = options_.dds_participant;
  dopt.name = "surgsim_haptic";
  dds_ = std::make_unique<Dds>(dopt);
  auto& p = dds_->participant;
  dds_->contact_writer = p.writer(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kStreamWriter);
  dds_->force_writer = p.writer(p.topic(dds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), dds::kStreamWriter);
  dds_->scene_writer = p.writer(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedWriter);
  dds_->status_reader = p.reader(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()),
                                 dds::kStreamReader, &dds_->visual_status);
  dds_->frame.contacts().reserve(msg::kMaxContacts);
  dds_->frame.scene_hash(scene_hash_);

  // SceneInfo is latched (transient local): a visual node that joins later still gets it.
  msg::SceneInfo info;
  info.scene_name(scene_.name);
  info.scene_hash(scene_hash_);
  info.mesh_hash(mesh_hash_);
  info.material_hash(material_hash(scene_.material));
  info.tensor_hash(0);
  info.node_count(static_cast<std::uint32_t>(mesh_.nodes.rows()));
  info.surface_node_count(static_cast<std::uint32_t>(surface_.nodes.size()));
  info.haptic_rate_hz(rate_hz_);
  info.visual_rate_hz(scene_.visual.rate_hz);
  info.start_stamp_ns(monotonic_ns());
  dds_->scene_writer->write(&info);

  if (!options_.quiet) {
    std::cerr << "haptic_node: scene '" << scene_.name << "' (" << scene_.file << "), " << mesh_.nodes.rows()
              << " nodes, " << mesh_.tets.rows() << " tets, " << surface_.nodes.size() << " surface nodes; "
              << rate_hz_ << " Hz for " << total_ticks_ << " ticks; replaying " << replay << "\n";
  }
}

HapticApp::~HapticApp() {
  if (log_ != nullptr) std::fclose(log_);
}

void HapticApp::tick(std::uint64_t k) {
  const double t = static_cast<double>(k) * dt_;
  const Pose5 pose = trajectory_.at(t);
  const ToolGeometry tool = tool_geometry(scene_.tool, pose);
  if (recorder_.is_open()) recorder_.append(t, pose);

  // Contact detection and force evaluation plug in here (issue 4); the walking skeleton publishes the tool only.
  const Eigen::Vector3d force = Eigen::Vector3d::Zero();
  const int contacts = 0;

  auto& frame = dds_->frame;
  frame.seq(k);
  frame.sim_time(t);
  frame.pose(to_msg(pose));
  frame.tip(to_msg(tool.tip));
  frame.contacts().clear();
  frame.force(to_msg(force));
  frame.flags(0);
  frame.stamp_ns(monotonic_ns());
  dds_->contact_writer->write(&frame);

  auto& ff = dds_->force;
  ff.seq(k);
  ff.stamp_ns(frame.stamp_ns());
  ff.force(to_msg(force));
  ff.saturated(false);
  ff.flags(0);
  dds_->force_writer->write(&ff);

  if (log_ != nullptr) std::fprintf(log_, "%llu,%.9f,%.9g,%.9g,%.9g,%d\n", static_cast<unsigned long long>(k), t,
                                    force.x(), force.y(), force.z(), contacts);
  if (contacts > contacts_max_) contacts_max_ = contacts;
  force_max_n_ = std::max(force_max_n_, force.norm());
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

  const RealtimeStatus rt = enter_realtime(options_.speed > 0 ? options_.rt_priority : 0, options_.lock_memory);
  realtime_note_ = rt.note;
  if (!options_.quiet) std::cerr << "haptic_node: " << rt.note << "\n";

  // --- run: the loop (no allocation from here to the end of the loop) ---
  const bool paced = options_.speed > 0;
  const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 * dt_ / (paced ? options_.speed : 1.0)));
  PeriodicTimer timer(period_ns);
  timer.start();
  const std::uint64_t wall_start = monotonic_ns();
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
  // --- shutdown starts here ---
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
  j["round_trip_us"] = to_json(rtt);
  j["visual_status_received"] = dds_->visual_status.received();
  j["realtime"] = realtime_note_;
  j["scene_hash"] = std::to_string(scene_hash_);
  j["record_write_errors"] = recorder_.write_errors();
  if (!options_.stats.empty()) write_json_file(options_.stats, j);
  if (!options_.quiet) {
    std::cerr << "haptic_node: " << ticks_done_ << " ticks at " << achieved << " Hz (target "
              << rate_hz_ * (options_.speed > 0 ? options_.speed : 0) << "), tick p50 " << tick.p50 << " us p99 "
              << tick.p99 << " us, " << deadline_misses_ << " missed deadlines, round trip p50 " << rtt.p50
              << " us (" << rtt.count << " echoes)\n";
  }
}

}  // namespace surgsim
