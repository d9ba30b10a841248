// The intestine scene in the haptic node (DESIGN.md 4.3, issue 6): the mass-spring intestine and mesentery stepped
// every tick with the tool tip as the probe, the probe force for the device, and the body's positions published as
// BodyState for the visual node. A liver scene never builds one (make_haptic_organ makes it for model "intestine"
// only), and an intestine scene builds no mesh, tensors or bucket grid.
//
// Phases: the constructor and create_writer() allocate (model, state, step-time storage, the DDS writer and its
// sample sized once to the body's node count); step() and fill_outputs() (loop thread) and write() (publisher
// thread) allocate nothing; stats() is for shutdown.
#pragma once
#include <atomic>
#include <cstdint>
#include <nlohmann/json.hpp>

#include "surgsim_types.h"
#include "dds_support.h"
#include "intestine/intestine_model.h"
#include "liver_contacts.h"
#include "scene/scene.h"
#include "core/stats.h"
#include "tool/tool.h"

namespace surgsim {

class IntestineOrgan final : public HapticOrgan {
 public:
  /// Init (allocates; throws surgsim::Error on bad parameters): the model and state of scene.intestine, room for
  /// `ticks` step times.
  IntestineOrgan(const Scene& scene, std::uint64_t ticks);

  const char* model_name() const override { return "intestine"; }

  /// Init: the BodyState writer (stream profile: best effort, keep last 1) and its preallocated sample.
  void create_writers(dds::Participant& participant, std::uint64_t scene_hash) override;

  /// Run phase, noexcept, no allocation: one step of dt (s) with the probe at the tool tip (no probe when `tool` is
  /// null, e.g. while the device input is lost: the body keeps moving, the force is zero). Fills `out` as
  /// LiverContacts::step does: force (N, on the tool, before the device clamp), device_force (clamped to
  /// tool.force_limit, always finite), saturated, over_capacity (probe or self-contact capacity exceeded), nonfinite
  /// (the step was refused and the state restored: a fault), points_in_contact (elements the probe touches).
  void step(const ToolGeometry* tool, double jaw, double dt, ContactTick& out) noexcept override;
  int contacts(const ContactTick& out) const noexcept override { return out.points_in_contact; }

  /// The body's masses: the positions each tick hands to the publisher.
  int output_points() const override { return state_.point_count(); }
  /// Loop thread, noexcept, no allocation: copies the positions (at most out.point_capacity); no contact entries.
  void fill_outputs(OrganOutputs& out) const noexcept override;
  /// Publisher thread, no allocation: the positions of `record` as BodyState with its seq, sim time, pose and tip.
  /// Nothing when create_writers() was not called.
  void write(const TickRecord& record, std::uint64_t stamp_ns) noexcept override;

  /// SceneInfo: the body's masses, and the intestine's points among them.
  std::uint32_t node_count() const override { return static_cast<std::uint32_t>(model_.node_count()); }
  std::uint32_t surface_node_count() const override { return static_cast<std::uint32_t>(model_.columns()); }
  std::string describe() const override;
  /// Shutdown: "intestine": stats() in the JSON, and the step-time summary line.
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out) const override;

  const intestine::IntestineModel& model() const { return model_; }
  const intestine::IntestineState& state() const { return state_; }
  const intestine::StepReport& report() const { return report_; }
  std::uint64_t faults() const { return faults_; }

  /// Shutdown: step time percentiles (us), faults, contacts, published states, for the haptic stats JSON.
  nlohmann::json stats() const;

 private:
  intestine::IntestineModel model_;
  intestine::IntestineState state_;
  intestine::StepReport report_;
  double probe_radius_ = 0.01;  // m
  SampleRecorder step_us_;
  std::uint64_t steps_ = 0;
  std::uint64_t faults_ = 0;
  std::uint64_t status_counts_[4] = {0, 0, 0, 0};  // by intestine::StepStatus
  int self_contacts_max_ = 0;
  double self_contacts_sum_ = 0;
  int probe_contacts_max_ = 0;
  std::uint64_t probe_contact_ticks_ = 0;
  std::uint64_t probe_overflow_ticks_ = 0;
  std::uint64_t contacts_overflow_ticks_ = 0;
  std::uint64_t saturated_ticks_ = 0;
  double penetration_after_max_ = 0;  // m, largest self-collision penetration left after the response
  int active_pairs_max_ = 0;
  eprosima::fastdds::dds::DataWriter* writer_ = nullptr;
  msg::BodyState sample_;
  std::atomic<std::uint64_t> published_{0};  // written on the publisher thread
};

}  // namespace surgsim
