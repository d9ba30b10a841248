// The intestine scene in the haptic node (docs/DESIGN.md, section 'Intestine: mass-spring + stochastic collisions'):
// the mass-spring intestine and mesentery stepped every tick with one probe per instrument (a sphere of
// scene.intestine.probe_radius at each tool tip, its force clamped to that instrument's force_limit), each probe's
// force for its own device, and the body's positions published as BodyState for the visual node with every instrument's
// state. All probes push the same body in one step, so one hand's press moves what the other touches. A liver scene
// never builds one (make_haptic_organ makes it for model "intestine" only), and an intestine scene builds no mesh,
// tensors or bucket grid.
//
// Phases: the constructor and create_writer() allocate (model, state, step-time storage, the DDS writer and its
// sample sized once to the body's node count); step() and fill_outputs() (loop thread) and write() (publisher
// thread) allocate nothing; stats() is for shutdown.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "surgsim_types.h"
#include "dds_support.h"
#include "intestine/intestine_model.h"
#include "organ.h"
#include "scene/scene.h"
#include "core/stats.h"
#include "tool/tool.h"

namespace surgsim {

class IntestineOrgan final : public HapticOrgan {
 public:
  /// Init (allocates; throws surgsim::core::Error on bad parameters): the model and state of scene.intestine, room for
  /// `ticks` step times.
  IntestineOrgan(const scene::Scene& scene, std::uint64_t ticks);

  const char* model_name() const override { return "intestine"; }

  /// Init: the BodyState writer (stream profile: best effort, keep last 1) and its preallocated sample.
  void create_writers(dds::Participant& participant, std::uint64_t scene_hash) override;

  /// Run phase, noexcept, no allocation: one step of dt (s) with probe i at instrument i's tool tip (i < count, at
  /// most kMaxInstruments; no probe for an instrument whose tool is null, e.g. its device input lost: the body keeps
  /// moving under the others, its force is zero). Fills out[i] as ToolContacts::step does: force (N, on instrument
  /// i, before its device clamp), device_force (clamped to scene.tools[i].force_limit, always finite), saturated,
  /// over_capacity (its probe's or the body's self-contact capacity exceeded), nonfinite (the step was refused and the
  /// state restored, every force zero: a fault; or its probe was not finite), points_in_contact (elements its probe
  /// touches). direction stays zero (no force law).
  using HapticOrgan::step;
  void step(const contact::InstrumentInput* inputs, int count, double dt, contact::ContactTick* out) noexcept override;
  /// Elements the probes touched in the last step: all of them, and instrument i's.
  int contacts() const noexcept override;
  int instrument_contacts(int i) const noexcept override;

  /// The body's masses: the positions each tick hands to the publisher.
  int output_points() const override { return state_.point_count(); }
  /// Loop thread, noexcept, no allocation: copies the positions (at most out.point_capacity); no contact entries.
  void fill_outputs(OrganOutputs& out) const noexcept override;
  /// Publisher thread, no allocation: the positions of `record` as BodyState with its seq, sim time and every
  /// instrument's state (index, pose, tip, direction, force, contact points, flags). Nothing when create_writers() was
  /// not called.
  void write(const TickRecord& record, std::uint64_t stamp_ns) noexcept override;

  /// SceneInfo: the body's masses, and the intestine's points among them.
  std::uint32_t node_count() const override { return static_cast<std::uint32_t>(model_.node_count()); }
  std::uint32_t surface_node_count() const override { return static_cast<std::uint32_t>(model_.columns()); }
  std::string describe() const override;
  /// Shutdown: "intestine": stats() in the JSON, and the step-time summary line.
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out) const override;

  /// Init: `obstacle` (named `name` in the stats; it must outlive this organ) is a surface the body rests on from now
  /// on (CompositeOrgan gives every rigid organ of the field). Throws surgsim::core::Error past kMaxObstacles.
  void add_obstacle(const intestine::Obstacle* obstacle, const std::string& name);
  int obstacle_count() const { return static_cast<int>(obstacle_names_.size()); }

  const intestine::IntestineModel& model() const { return model_; }
  const intestine::IntestineState& state() const { return state_; }
  const intestine::StepReport& report() const { return report_; }
  std::uint64_t faults() const { return faults_; }

  /// Shutdown: step time percentiles (us), faults, contacts (all probes, and per probe under "probes"), published
  /// states, for the haptic stats JSON.
  nlohmann::json stats() const;

 private:
  /// One obstacle's counters over the run (fixed storage).
  struct ObstacleStats {
    int contacts_max = 0;
    std::uint64_t contact_ticks = 0;
    double max_depth_m = 0;  // deepest overlap of a node's sphere with it
    double force_max_n = 0;  // largest push on the body
  };
  /// One probe's counters over the run (fixed storage).
  struct ProbeStats {
    int contacts_max = 0;
    std::uint64_t contact_ticks = 0;
    std::uint64_t overflow_ticks = 0;
    std::uint64_t saturated_ticks = 0;
    double force_max_n = 0;  // N, after its clamp
  };

  intestine::IntestineModel model_;
  intestine::IntestineState state_;
  intestine::StepReport report_;
  double probe_radius_ = 0.01;  // m
  int instruments_ = 1;         // the scene's tools (1..kMaxProbes): BodyState instruments, stats
  std::vector<std::string> names_;                       // the instruments' names, for the stats
  std::array<double, intestine::kMaxProbes> force_limits_{};  // N, each instrument's device limit
  std::array<intestine::Probe, intestine::kMaxProbes> probes_{};  // this tick's probes
  std::array<ProbeStats, intestine::kMaxProbes> probe_stats_{};
  std::array<const intestine::Obstacle*, intestine::kMaxObstacles> obstacles_{};
  std::vector<std::string> obstacle_names_;
  std::array<ObstacleStats, intestine::kMaxObstacles> obstacle_stats_{};
  std::uint64_t obstacle_overflow_ticks_ = 0;
  core::SampleRecorder step_us_;
  std::uint64_t steps_ = 0;
  std::uint64_t faults_ = 0;
  std::uint64_t status_counts_[4] = {0, 0, 0, 0};  // by intestine::StepStatus
  int self_contacts_max_ = 0;
  double self_contacts_sum_ = 0;
  int probe_contacts_max_ = 0;               // all probes together
  std::uint64_t probe_contact_ticks_ = 0;    // ticks some probe touched
  std::uint64_t probe_overflow_ticks_ = 0;   // ticks some probe overflowed
  std::uint64_t contacts_overflow_ticks_ = 0;
  std::uint64_t saturated_ticks_ = 0;        // ticks some probe saturated
  double penetration_after_max_ = 0;  // m, largest self-collision penetration left after the response
  int active_pairs_max_ = 0;
  eprosima::fastdds::dds::DataWriter* writer_ = nullptr;
  msg::BodyState sample_;
  std::atomic<std::uint64_t> published_{0};  // written on the publisher thread
};

}  // namespace surgsim
