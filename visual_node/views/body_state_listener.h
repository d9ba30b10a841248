// The newest BodyState from the haptic node (dds::kBodyStateTopic, stream QoS: best effort, keep last 1), shared by
// the views that draw one: the intestine's points (views/intestine_view.h) and the multirate liver's boundary surface
// (views/liver_view.h). The DDS listener thread copies each sample under a lock into storage reserved at
// init (kMaxBodyPoints positions); the frame loop copies the newest one out with take(). Nothing allocates after init.
// BodyState is keyed by organ (wire v3): a listener keeps the states of the one organ its view draws (its index in the
// scene's organs list, 0 in a one-organ scene) and counts the others'.
#pragma once
#include <cstdint>
#include <memory>
#include <mutex>

#include "dds_support.h"
#include "instruments.h"
#include "surgsim_types.h"

namespace surgsim {

/// What a BodyState says about itself besides its positions and instruments.
struct BodyStateHeader {
  std::uint64_t seq = 0;
  std::uint64_t stamp_ns = 0;    // the publisher's CLOCK_MONOTONIC at publication
  std::uint64_t scene_hash = 0;  // the haptic node's scene identity (scene and mesh)
  double sim_time = 0;           // s, haptic sim time of the state
};

class BodyStateListener : public eprosima::fastdds::dds::DataReaderListener {
 public:
  /// `organ`: the organ whose states are kept (BodyState.organ).
  explicit BodyStateListener(int organ = 0);
  /// DDS listener thread: keeps the newest valid sample of its organ.
  void on_data_available(eprosima::fastdds::dds::DataReader* reader) override;
  /// Frame loop, no allocation: when a state newer than the last one taken has arrived, copies its positions into
  /// `xyz` (x, y, z per point; room for kMaxBodyPoints points), its instruments (for a scene of `tools` instruments)
  /// and its header, and returns its point count; else -1. `received`: the states received so far.
  int take(double* xyz, int tools, InstrumentPoses& instruments, BodyStateHeader& header, std::uint64_t& received);
  /// States of other organs received (ignored).
  std::uint64_t other_organs();

 private:
  std::uint32_t organ_ = 0;
  std::mutex mutex_;
  msg::BodyState incoming_;
  msg::BodyState newest_;
  std::uint64_t received_ = 0;
  std::uint64_t taken_ = 0;
  std::uint64_t other_organs_ = 0;
};

/// Init: a listener of organ `organ`'s states and its reader on `participant`'s BodyState topic (stream profile).
std::unique_ptr<BodyStateListener> subscribe_body_states(dds::Participant& participant, int organ = 0);

}  // namespace surgsim
