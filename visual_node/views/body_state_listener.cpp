#include "views/body_state_listener.h"

namespace surgsim {

using eprosima::fastdds::dds::DataReader;
using eprosima::fastdds::dds::SampleInfo;
using eprosima::fastrtps::types::ReturnCode_t;

BodyStateListener::BodyStateListener(int organ) : organ_(static_cast<std::uint32_t>(organ)) {
  incoming_.positions().reserve(msg::kMaxBodyPoints);
  newest_.positions().reserve(msg::kMaxBodyPoints);
}

void BodyStateListener::on_data_available(DataReader* reader) {
  SampleInfo info;
  while (reader->take_next_sample(&incoming_, &info) == ReturnCode_t::RETCODE_OK) {
    if (!info.valid_data) continue;
    std::lock_guard<std::mutex> lock(mutex_);
    if (incoming_.organ() != organ_) {  // another organ's body (a scene with several organs)
      ++other_organs_;
      continue;
    }
    newest_ = incoming_;  // within the reserved capacity
    ++received_;
  }
}

int BodyStateListener::take(double* xyz, int tools, InstrumentPoses& instruments, BodyStateHeader& header,
                            std::uint64_t& received) {
  std::lock_guard<std::mutex> lock(mutex_);
  received = received_;
  if (received_ == taken_) return -1;
  taken_ = received_;
  const auto& p = newest_.positions();
  for (std::size_t i = 0; i < p.size(); ++i) {
    xyz[3 * i] = p[i].x();
    xyz[3 * i + 1] = p[i].y();
    xyz[3 * i + 2] = p[i].z();
  }
  take_instruments(newest_.instruments(), tools, instruments);
  header.seq = newest_.seq();
  header.stamp_ns = newest_.stamp_ns();
  header.scene_hash = newest_.scene_hash();
  header.sim_time = newest_.sim_time();
  return static_cast<int>(p.size());
}

std::uint64_t BodyStateListener::other_organs() {
  std::lock_guard<std::mutex> lock(mutex_);
  return other_organs_;
}

std::unique_ptr<BodyStateListener> subscribe_body_states(dds::Participant& participant, int organ) {
  auto listener = std::make_unique<BodyStateListener>(organ);
  participant.reader(participant.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()), dds::kStreamReader,
                     listener.get());
  return listener;
}

}  // namespace surgsim
