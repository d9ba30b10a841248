// Several organs in one haptic node (a scene with an `organs:` list): every organ is stepped each tick with every
// instrument, each instrument's force is the sum of what each organ gives it, and that sum is left unclamped for the
// force stage (force_stage.h), which clamps it once at the device limit. Clamping each organ's force and then the sum
// would change the sum's direction (a 10 N push against a 9 N pull gives 1 N, not 8 - 8 = 0).
//
// Phases as organ.h: the constructor takes organs already built; step(), fill_outputs() (loop thread) and write()
// (publisher thread) allocate nothing.
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "organ.h"
#include "publisher.h"

namespace surgsim {

class CompositeOrgan final : public HapticOrgan {
 public:
  struct Part {
    std::string name;  // the scene's organ name
    std::unique_ptr<HapticOrgan> organ;
  };
  /// Init: takes the organs (1..scene::kMaxOrgans, in the scene's order: contact entries carry that index).
  explicit CompositeOrgan(std::vector<Part> parts);

  const char* model_name() const override { return "organs"; }
  /// Run phase: each organ's step with every instrument, then per instrument: force and device_force the sum of the
  /// organs' (unclamped) forces, zero when a sum is not finite; flags and contact points the union / sum; direction
  /// the direction of the organ giving the largest force.
  using HapticOrgan::step;
  void step(const contact::InstrumentInput* inputs, int count, double dt, contact::ContactTick* out) noexcept override;
  int contacts() const noexcept override;
  int instrument_contacts(int i) const noexcept override;
  /// Every organ's entries in the organs' order, each with its organ index (at most kMaxContactEntries in all).
  int contact_entries() const noexcept override;
  ContactEntry contact_entry(int l) const noexcept override;
  /// Combined over the organs (order-sensitive).
  std::uint64_t mesh_hash() const override;
  std::uint64_t tensor_hash() const override;
  std::uint32_t node_count() const override;
  std::uint32_t surface_node_count() const override;
  bool nonlinear_law() const override;
  std::vector<OrganIdentity> identities() const override;
  /// Every organ's points, concatenated in the organs' order.
  int output_points() const override { return point_offsets_.back(); }
  void fill_outputs(OrganOutputs& out) const noexcept override;
  void create_writers(dds::Participant& participant, std::uint64_t scene_hash) override;
  /// Each organ writes its own topics from its share of the record's points.
  void write(const TickRecord& record, std::uint64_t stamp_ns) noexcept override;
  void time_stages(bool on) override;
  std::string describe() const override;
  /// "organs": [{name, model, ...each organ's own entries}] in the stats JSON.
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out) const override;

  int organ_count() const { return static_cast<int>(parts_.size()); }
  const HapticOrgan& organ(int k) const { return *parts_[static_cast<std::size_t>(k)].organ; }
  const std::string& organ_name(int k) const { return parts_[static_cast<std::size_t>(k)].name; }
  /// Organ k's own result for instrument i in the last step (tests, stats).
  const contact::ContactTick& organ_tick(int k, int i) const {
    return ticks_[static_cast<std::size_t>(k)][static_cast<std::size_t>(i)];
  }

 private:
  std::vector<Part> parts_;
  std::vector<std::array<contact::ContactTick, tool::kMaxInstruments>> ticks_;  // per organ, per instrument
  std::vector<int> point_offsets_;  // organ k's points start at point_offsets_[k]; back() is the total
  TickRecord scratch_;              // publisher thread: the record as organ k sees it (its points only)
};

}  // namespace surgsim
