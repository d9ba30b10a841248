#include "web_dds.h"

#include <cstring>

#include "core/clock.h"
#include "frame_stream.h"
#include "surgsim_types.h"

using namespace surgsim::core;
using namespace surgsim::tool;

namespace surgsim::web {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::DataReaderListener;
using eprosima::fastdds::dds::DataWriter;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

namespace {

template <typename T>
void put(std::string& s, std::size_t at, T v) {
  std::memcpy(&s[at], &v, sizeof v);  // little-endian hosts (x86-64, arm64)
}

}  // namespace

struct WebDds::State : DataReaderListener {
  explicit State(const dds::DdsOptions& o) : participant(o) {}
  ~State() override = default;

  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    const std::string topic = reader->get_topicdescription()->get_name();
    if (topic == kFrameTopic) {
      while (reader->take_next_sample(&frame_in, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;
        auto m = std::make_shared<std::string>(kFrameHeaderBytes + frame_in.jpeg().size(), '\0');
        std::memcpy(m->data(), "SGF1", 4);
        put<std::uint32_t>(*m, 4, frame_in.width());
        put<std::uint32_t>(*m, 8, frame_in.height());
        put<std::uint32_t>(*m, 12, frame_in.quality());
        put<std::uint64_t>(*m, 16, frame_in.frame_number());
        put<std::uint64_t>(*m, 24, frame_in.render_stamp_ns());
        put<std::uint64_t>(*m, 32, frame_in.haptic_stamp_ns());
        if (!frame_in.jpeg().empty()) std::memcpy(&(*m)[kFrameHeaderBytes], frame_in.jpeg().data(), frame_in.jpeg().size());
        const std::uint64_t now = monotonic_ns();
        std::lock_guard<std::mutex> lock(mutex);
        if (now >= frame_in.render_stamp_ns()) arrival_us.add(static_cast<double>(now - frame_in.render_stamp_ns()) * 1e-3);
        frame = std::move(m);
        ++t.frames_received;
        t.frame_number = frame_in.frame_number();
        t.frame_render_stamp_ns = frame_in.render_stamp_ns();
        stamps[frame_in.frame_number() % stamps.size()] = {frame_in.frame_number(), frame_in.render_stamp_ns()};
        if (on_frame) on_frame();
      }
    } else if (topic == dds::kForceFeedbackTopic) {
      msg::ForceFeedback f;
      while (reader->take_next_sample(&f, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data || f.instrument() != instrument) continue;
        std::lock_guard<std::mutex> lock(mutex);
        t.force = {f.force().x(), f.force().y(), f.force().z()};
        t.force_flags = f.flags();
        t.force_stamp_ns = f.stamp_ns();
        ++t.force_received;
      }
    } else if (topic == dds::kContactFrameTopic) {
      while (reader->take_next_sample(&contact_in, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;
        std::lock_guard<std::mutex> lock(mutex);
        ++t.contact_frames;
        t.contact_seq = contact_in.seq();
        t.contacts = static_cast<std::uint32_t>(contact_in.contacts().size());
        t.sim_time = contact_in.sim_time();
        for (const msg::InstrumentState& st : contact_in.instruments()) {
          if (st.instrument() != instrument) continue;
          t.instrument_contacts = st.contact_points();
          t.pose = Pose5{st.pose().pitch(), st.pose().yaw(), st.pose().insertion(), st.pose().roll(), st.pose().jaw()};
        }
      }
    } else if (topic == dds::kVisualStatusTopic) {
      msg::VisualStatus v;
      while (reader->take_next_sample(&v, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;
        std::lock_guard<std::mutex> lock(mutex);
        if (v.echoed_stamp_ns() != 0 && v.stamp_ns() >= v.echoed_stamp_ns()) {
          t.haptic_visual_latency_us = static_cast<double>(v.stamp_ns() - v.echoed_stamp_ns()) * 1e-3;
        } else if (v.echoed_stamp_ns() == 0) {
          t.visual_fps = v.fps();
        }
      }
    } else if (topic == dds::kSceneInfoTopic) {
      msg::SceneInfo s;
      while (reader->take_next_sample(&s, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) continue;
        std::lock_guard<std::mutex> lock(mutex);
        t.have_scene = true;
        t.scene_name = s.scene_name();
        t.scene_hash = s.scene_hash();
        t.mesh_hash = s.mesh_hash();
        t.material_hash = s.material_hash();
        t.tensor_hash = s.tensor_hash();
        t.instrument_count = s.instrument_count();
        t.haptic_rate_hz = s.haptic_rate_hz();
        t.organs.clear();
        for (const msg::OrganInfo& o : s.organs()) {
          t.organs += std::string(t.organs.empty() ? "" : ", ") + o.name().to_string() + " (" + o.model().to_string() + ")";
        }
      }
    }
  }

  std::uint32_t instrument = 0;
  std::mutex mutex;
  Telemetry t;
  std::shared_ptr<const std::string> frame;
  std::function<void()> on_frame;  // guarded by mutex
  SampleRecorder arrival_us{1 << 18};
  std::array<std::pair<std::uint64_t, std::uint64_t>, 64> stamps{};  // (frame number, render stamp), ring
  msg::Frame frame_in;
  msg::ContactFrame contact_in;
  // The participant last: destroyed first, so no reader calls this listener once the members above are gone.
  dds::Participant participant;
  DataWriter* command_writer = nullptr;
  msg::ToolCommand command;
};

WebDds::WebDds(const dds::DdsOptions& options, std::uint32_t instrument) : s_(std::make_unique<State>(options)) {
  auto& p = s_->participant;
  s_->instrument = instrument;
  State* l = s_.get();
  p.reader(p.topic(dds::kSceneInfoTopic, new msg::SceneInfoPubSubType()), dds::kLatchedReader, l);
  p.reader(p.topic(kFrameTopic, new msg::FramePubSubType()), kFrameReaderProfile, l);
  p.reader(p.topic(dds::kForceFeedbackTopic, new msg::ForceFeedbackPubSubType()), dds::kStreamReader, l);
  p.reader(p.topic(dds::kContactFrameTopic, new msg::ContactFramePubSubType()), dds::kStreamReader, l);
  p.reader(p.topic(dds::kVisualStatusTopic, new msg::VisualStatusPubSubType()), dds::kStreamReader, l);
  s_->command_writer =
      p.writer(p.topic(dds::kToolCommandTopic, new msg::ToolCommandPubSubType()), dds::kStreamWriter);
}

WebDds::~WebDds() = default;

Telemetry WebDds::telemetry() {
  std::lock_guard<std::mutex> lock(s_->mutex);
  return s_->t;
}

void WebDds::set_frame_callback(std::function<void()> callback) {
  std::lock_guard<std::mutex> lock(s_->mutex);
  s_->on_frame = std::move(callback);
}

std::shared_ptr<const std::string> WebDds::frame_since(std::uint64_t last_number) {
  std::lock_guard<std::mutex> lock(s_->mutex);
  if (!s_->frame || s_->t.frame_number == last_number) return nullptr;
  return s_->frame;
}

Percentiles WebDds::frame_arrival_us() {
  std::lock_guard<std::mutex> lock(s_->mutex);
  return s_->arrival_us.summary();
}

std::uint64_t WebDds::render_stamp_of(std::uint64_t number) {
  std::lock_guard<std::mutex> lock(s_->mutex);
  const auto& e = s_->stamps[number % s_->stamps.size()];
  return e.first == number ? e.second : 0;
}

void WebDds::publish(const Pose5& pose, std::uint64_t seq) {
  msg::ToolCommand& c = s_->command;
  c.instrument(s_->instrument);
  c.seq(seq);
  c.stamp_ns(monotonic_ns());
  c.pose().pitch(pose.pitch);
  c.pose().yaw(pose.yaw);
  c.pose().insertion(pose.insertion);
  c.pose().roll(pose.roll);
  c.pose().jaw(pose.jaw);
  s_->command_writer->write(&c);
}

const dds::Participant& WebDds::participant() const { return s_->participant; }

}  // namespace surgsim::web
