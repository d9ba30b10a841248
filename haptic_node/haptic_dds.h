// The haptic node's DDS entities (docs/DESIGN.md, section 'Topics'): the participant, the ContactFrame, ForceFeedback
// and SceneInfo writers, the ToolCommand reader (live input) and the VisualStatus reader (round-trip echoes), with
// their samples allocated once. Init allocates; write_force(), write_frame() (the publisher thread, publisher.h: never
// the loop) and latest_command() (the loop) allocate nothing (the listeners run on DDS threads; the loop only try-locks
// the newest command, it never waits on them).
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/stats.h"
#include "dds_support.h"
#include "organ.h"
#include "publisher.h"
#include "tool/trajectory.h"

namespace surgsim {

namespace msg {
namespace v3 {
class SceneInfo;
class InstrumentState;
}  // namespace v3
using namespace v3;  // NOLINT: the wire version in use (idl/surgsim_types.h)
}

/// Publisher thread, no allocation: a tick's instruments into a ContactFrame's or BodyState's `instruments` (sized to
/// the scene's instruments once, at init; only min(size, record.instrument_count) entries are written).
void fill_instruments(const TickRecord& record, std::vector<msg::InstrumentState>& states) noexcept;

/// Init: SceneInfo.organs from the organ's identities (HapticOrgan::identities(), the scene's order): one OrganInfo
/// each, an empty name standing for `scene_name` (the organ of a one-organ scene); names cut to the IDL's bounds.
void fill_scene_organs(const std::vector<OrganIdentity>& organs, const std::string& scene_name, msg::SceneInfo& info);

class HapticDds final : public TickSink {
 public:
  /// Creates the participant and every endpoint; `live` adds the ToolCommand reader.
  HapticDds(const dds::DdsOptions& options, bool live, std::uint64_t scene_hash, int instruments = 1);
  ~HapticDds();
  HapticDds(const HapticDds&) = delete;
  HapticDds& operator=(const HapticDds&) = delete;

  dds::Participant& participant();
  /// Latched (transient local): a visual node that joins later still gets it.
  void publish_scene_info(const msg::SceneInfo& info);
  /// Waits up to `seconds` until a reader (a visual node) matches the ContactFrame writer, or `stop` is set.
  void wait_for_reader(double seconds, const std::atomic<bool>& stop);

  /// Run phase, no allocation: instrument i's newest device command (ToolCommand.instrument == i), its arrival time
  /// (monotonic ns) and how many have arrived for it; keeps the previous ones when the listener holds the slot this
  /// instant. Commands for an instrument the scene does not have are counted (stray_commands()) and dropped.
  void latest_command(int instrument, tool::Pose5& pose, std::uint64_t& receive_ns, std::uint64_t& received) noexcept;
  std::uint64_t stray_commands() const;

  /// Init: the organ whose own topics write_frame() writes after the ContactFrame (its write()).
  void attach_organ(HapticOrgan* organ) { organ_ = organ; }

  /// Publisher thread, no allocation: a ForceFeedback (for the device).
  void write_force(int instrument, std::uint64_t seq, std::uint64_t stamp_ns, const Eigen::Vector3d& force,
                   bool saturated, std::uint32_t flags) noexcept override;
  /// Publisher thread, no allocation: a tick's ContactFrame (for the visual node), then the organ's own topics.
  void write_frame(const TickRecord& record, std::uint64_t stamp_ns) noexcept override;

  /// Shutdown: round trips measured from VisualStatus echoes (us), echoes received, the participant profile.
  core::Percentiles round_trip() const;
  std::uint64_t visual_status_received() const;
  std::string profile() const;
  std::string description() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  HapticOrgan* organ_ = nullptr;
};

}  // namespace surgsim
