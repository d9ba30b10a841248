#include "visual_dds.h"

#include <mutex>

#include "surgsim_types.h"
#include "core/clock.h"
#include "haptic_watch.h"

using namespace surgsim::core;

namespace surgsim {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

namespace {

// Keeps the newest ContactFrame of this node's scene and the one-way latency of each (same-host clocks). A frame
// whose scene_hash is not this node's is counted (with its hash) and never kept: it cannot be drawn.
class ContactFrameListener : public DataReaderListener {
 public:
  void set_scene_hash(std::uint64_t hash) { scene_hash_ = hash; }
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
      ++received_;
      last_receive_ns_ = now;
      if (incoming_.scene_hash() != scene_hash_) {
        ++wrong_scene_;
        last_wrong_hash_ = incoming_.scene_hash();
        continue;
      }
      newest_ = incoming_;
      ++accepted_;
    }
  }
  /// Copies the newest frame of this scene if it is newer than the last one taken; returns true then.
  bool newest(msg::ContactFrame& out, std::uint64_t& count) {
    std::lock_guard<std::mutex> lock(mutex_);
    count = received_;
    if (accepted_ == taken_) return false;
    taken_ = accepted_;
    out = newest_;
    return true;
  }
  std::uint64_t accepted() {
    std::lock_guard<std::mutex> lock(mutex_);
    return accepted_;
  }
  std::uint64_t wrong_scene(std::uint64_t& last_hash) {
    std::lock_guard<std::mutex> lock(mutex_);
    last_hash = last_wrong_hash_;
    return wrong_scene_;
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
  std::uint64_t scene_hash_ = 0;   // this node's scene identity (set before the reader exists)
  std::uint64_t received_ = 0;     // every valid frame
  std::uint64_t accepted_ = 0;     // frames of this scene
  std::uint64_t taken_ = 0;        // accepted_ at the last newest() that returned a frame
  std::uint64_t wrong_scene_ = 0;  // frames of another scene (never kept)
  std::uint64_t last_wrong_hash_ = 0;
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

}  // namespace

struct VisualDds::State {
  explicit State(const dds::DdsOptions& o) : participant(o) {}
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

VisualDds::VisualDds(const dds::DdsOptions& options, HapticWatch& watch, std::uint64_t scene_hash)
    : s_(std::make_unique<State>(options)) {
  auto& p = s_->participant;
  s_->frames.set_scene_hash(scene_hash);
  s_->scene_reader = p.reader(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedReader,
                              &s_->scene_info);
  s_->frames.set_watch(&watch);
  s_->frame_reader = p.reader(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()),
                              dds::kContactReader, &s_->frames);
  s_->status_writer = p.writer(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()), dds::kStreamWriter);
  s_->frames.set_echo(s_->status_writer);
}

VisualDds::~VisualDds() = default;

dds::Participant& VisualDds::participant() { return s_->participant; }

bool VisualDds::newest_frame(msg::ContactFrame& out, std::uint64_t& received) { return s_->frames.newest(out, received); }

std::uint64_t VisualDds::frames_received() { return s_->frames.received(); }

std::uint64_t VisualDds::frames_accepted() { return s_->frames.accepted(); }

std::uint64_t VisualDds::frames_wrong_scene(std::uint64_t& last_hash) { return s_->frames.wrong_scene(last_hash); }

std::uint64_t VisualDds::last_receive_ns() { return s_->frames.last_receive_ns(); }

Percentiles VisualDds::latency() { return s_->frames.latency(); }

bool VisualDds::scene_info(msg::SceneInfo& out) { return s_->scene_info.get(out); }

void VisualDds::publish_status(double fps, std::uint32_t lod, std::uint64_t last_seq_shown,
                               std::uint64_t frames_rendered) {
  auto& st = s_->status;
  st.stamp_ns(monotonic_ns());
  st.fps(fps);
  st.lod(lod);
  st.last_seq_shown(last_seq_shown);
  st.echoed_stamp_ns(0);  // round trips are echoed by the frame listener, on arrival
  st.frames_rendered(frames_rendered);
  s_->status_writer->write(&st);
}

}  // namespace surgsim
