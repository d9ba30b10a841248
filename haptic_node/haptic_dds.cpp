#include "haptic_dds.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <mutex>
#include <thread>

#include "surgsim_types.h"
#include "core/clock.h"
#include "publisher.h"

using namespace surgsim::core;
using namespace surgsim::tool;

namespace surgsim {

static_assert(kFlagHeld == msg::kFlagHeld, "publisher.h and idl/Surgsim.idl disagree on the held-force flag");

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

// Newest device command of each instrument (the ToolCommand key). The loop reads it with try_lock, so it never waits
// on the DDS thread.
class ToolCommandListener : public DataReaderListener {
 public:
  void set_instruments(int n) { instruments_ = std::clamp(n, 1, kMaxInstruments); }
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&incoming_, &info) == eprosima::fastrtps::types::ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      std::lock_guard<std::mutex> lock(mutex_);
      const std::uint32_t i = incoming_.instrument();
      if (i >= static_cast<std::uint32_t>(instruments_)) {
        ++stray_;
        continue;
      }
      Slot& s = slots_[i];
      const auto& p = incoming_.pose();
      s.pose = Pose5{p.pitch(), p.yaw(), p.insertion(), p.roll(), p.jaw()};
      s.receive_ns = monotonic_ns();
      ++s.received;
    }
  }
  /// Non-blocking: false when the slot is busy (the caller keeps its previous value).
  bool try_get(int i, Pose5& pose, std::uint64_t& receive_ns, std::uint64_t& received) {
    if (i < 0 || i >= instruments_) return false;
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock()) return false;
    const Slot& s = slots_[static_cast<std::size_t>(i)];
    pose = s.pose;
    receive_ns = s.receive_ns;
    received = s.received;
    return true;
  }
  std::uint64_t stray() {
    std::lock_guard<std::mutex> lock(mutex_);
    return stray_;
  }

 private:
  struct Slot {
    Pose5 pose;
    std::uint64_t receive_ns = 0;
    std::uint64_t received = 0;
  };
  std::mutex mutex_;
  msg::ToolCommand incoming_;
  int instruments_ = 1;
  std::array<Slot, kMaxInstruments> slots_{};
  std::uint64_t stray_ = 0;
};

}  // namespace

struct HapticDds::Impl {
  explicit Impl(const dds::DdsOptions& o) : visual_status(1 << 16), participant(o) {}
  // Listeners first: members are destroyed in reverse order, so the participant (and its readers, whose callbacks
  // use the listeners) goes before them.
  VisualStatusListener visual_status;
  ToolCommandListener tool_commands;
  dds::Participant participant;
  DataWriter* contact_writer = nullptr;
  DataWriter* force_writer = nullptr;
  DataWriter* scene_writer = nullptr;
  DataReader* status_reader = nullptr;
  // Samples allocated once; the loop only overwrites their fields.
  msg::ContactFrame frame;
  msg::ForceFeedback force;
  int instruments = 1;
};

HapticDds::HapticDds(const dds::DdsOptions& options, bool live, std::uint64_t scene_hash, int instruments)
    : impl_(std::make_unique<Impl>(options)) {
  Impl& d = *impl_;
  d.tool_commands.set_instruments(instruments);
  d.instruments = std::clamp(instruments, 1, kMaxInstruments);
  auto& p = d.participant;
  d.contact_writer = p.writer(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kContactWriter);
  d.force_writer = p.writer(p.topic(dds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), dds::kStreamWriter);
  d.scene_writer = p.writer(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedWriter);
  if (live) {
    p.reader(p.topic(dds::kToolCommandTopic, new msg::ToolCommandPubSubType()), dds::kStreamReader, &d.tool_commands);
  }
  d.status_reader = p.reader(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()), dds::kStreamReader,
                             &d.visual_status);
  d.frame.contacts().reserve(msg::kMaxContacts);
  d.frame.instruments().resize(static_cast<std::size_t>(d.instruments));  // sized once: the loop never resizes it
  d.frame.scene_hash(scene_hash);
}

HapticDds::~HapticDds() = default;

dds::Participant& HapticDds::participant() { return impl_->participant; }

namespace {
// A string cut to the IDL's bound (a longer one would not serialize; names are for people, the hashes identify).
std::string bounded(const std::string& s, std::size_t bound) { return s.size() <= bound ? s : s.substr(0, bound); }
}  // namespace

void fill_scene_organs(const std::vector<OrganIdentity>& organs, const std::string& scene_name, msg::SceneInfo& info) {
  auto& out = info.organs();
  out.clear();
  for (const OrganIdentity& id : organs) {
    if (out.size() >= msg::kMaxOrgans) break;  // the scene refuses more (scene::kMaxOrgans, asserted equal above)
    msg::OrganInfo o;
    o.name(bounded(id.name.empty() ? scene_name : id.name, 64));
    o.model(bounded(id.model, 16));
    o.mesh_hash(id.mesh_hash);
    o.tensor_hash(id.tensor_hash);
    o.node_count(id.node_count);
    o.surface_node_count(id.surface_node_count);
    out.push_back(std::move(o));
  }
}

void HapticDds::publish_scene_info(const msg::SceneInfo& info) {
  msg::SceneInfo sample = info;
  impl_->scene_writer->write(&sample);
}

void HapticDds::wait_for_reader(double seconds, const std::atomic<bool>& stop) {
  const std::uint64_t until = monotonic_ns() + static_cast<std::uint64_t>(seconds * 1e9);
  eprosima::fastdds::dds::PublicationMatchedStatus st;
  while (monotonic_ns() < until && !stop.load(std::memory_order_relaxed)) {
    impl_->contact_writer->get_publication_matched_status(st);
    if (st.current_count > 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

void HapticDds::latest_command(int instrument, Pose5& pose, std::uint64_t& receive_ns,
                               std::uint64_t& received) noexcept {
  impl_->tool_commands.try_get(instrument, pose, receive_ns, received);
}

std::uint64_t HapticDds::stray_commands() const { return impl_->tool_commands.stray(); }

static_assert(kMaxContactEntries == static_cast<int>(msg::kMaxContacts), "organ.h and the IDL disagree");
static_assert(scene::kMaxOrgans == static_cast<int>(msg::kMaxOrgans), "scene/scene.h and the IDL disagree");
static_assert(kMaxInstruments == static_cast<int>(msg::kMaxInstruments), "tool/trajectory.h and the IDL disagree");

void fill_instruments(const TickRecord& r, std::vector<msg::InstrumentState>& states) noexcept {
  const std::size_t n =
      std::min(states.size(), static_cast<std::size_t>(std::clamp(r.instrument_count, 0, kMaxInstruments)));
  for (std::size_t i = 0; i < n; ++i) {
    const InstrumentRecord& ir = r.instruments[i];
    msg::InstrumentState& m = states[i];
    m.instrument(static_cast<std::uint32_t>(i));
    m.pose(to_msg(ir.pose));
    m.tip(to_msg(ir.tip));
    m.direction(to_msg(ir.direction));
    m.force(to_msg(ir.force));
    m.contact_points(ir.contact_points);
    m.flags(ir.flags);
  }
}

void HapticDds::write_force(int instrument, std::uint64_t seq, std::uint64_t stamp_ns, const Eigen::Vector3d& force,
                            bool saturated, std::uint32_t flags) noexcept {
  auto& ff = impl_->force;
  ff.instrument(static_cast<std::uint32_t>(instrument));
  ff.seq(seq);
  ff.stamp_ns(stamp_ns);
  ff.force(to_msg(force));
  ff.saturated(saturated);
  ff.flags(flags);
  impl_->force_writer->write(&ff);
}

void HapticDds::write_frame(const TickRecord& r, std::uint64_t stamp_ns) noexcept {
  auto& frame = impl_->frame;
  frame.seq(r.seq);
  frame.sim_time(r.sim_time);
  fill_instruments(r, frame.instruments());
  auto& entries = frame.contacts();
  const int count = std::min(std::max(r.organ.contact_count, 0), kMaxContactEntries);
  entries.resize(static_cast<std::size_t>(count));  // within the reserved capacity: no allocation
  for (int l = 0; l < count; ++l) {
    const ContactRecord& c = r.organ.contacts[static_cast<std::size_t>(l)];
    auto& e = entries[static_cast<std::size_t>(l)];
    e.node(static_cast<std::uint32_t>(c.node));
    e.instrument(static_cast<std::uint32_t>(c.instrument));
    e.organ(static_cast<std::uint32_t>(c.organ));
    e.lambda(to_msg(c.lambda));
    e.u_tilde(to_msg(c.u_tilde));
  }
  frame.flags(r.flags);
  frame.stamp_ns(stamp_ns);
  impl_->contact_writer->write(&frame);
  if (organ_ != nullptr) organ_->write(r, stamp_ns);  // the organ's own topics (the intestine's BodyState)
}

Percentiles HapticDds::round_trip() const { return impl_->visual_status.summary(); }
std::uint64_t HapticDds::visual_status_received() const { return impl_->visual_status.received(); }
std::string HapticDds::profile() const { return impl_->participant.profile(); }
std::string HapticDds::description() const { return impl_->participant.description(); }

}  // namespace surgsim
