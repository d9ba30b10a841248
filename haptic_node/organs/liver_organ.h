// The liver in the haptic node (Cotin 1998; docs/DESIGN.md, sections 'Liver: precomputed linear elasticity' and
// 'Collision (liver)'): the scene's tetrahedral mesh, the "haptic" block of the precomputed tensors (from the cache
// both nodes share), the quasi non-linear law and the contact model (ToolContacts: bucket grid, unilateral contacts and
// grasps, mutual-influence correction, device clamp). With liver.deformation multirate (large deformation) it also owns
// the scene's liver as a neo-Hookean organ tracked on a thread of its own (nonlinear/multirate_contacts.h), whose
// snapshots give the contact forces, and publishes the tracker's surface as BodyState (the wire protocol: one sample
// per new surface, at most the scene's visual rate; positions[k] = rest + displacement of surface node k; sim_time of
// the targets it was computed for; the instruments of that tick), written by the publisher thread, never the loop.
#pragma once
#include <array>
#include <atomic>
#include <memory>
#include <thread>

#include "concurrency/hand_off.h"
#include "liver/liver_model.h"
#include "nonlinear/nonlinear_law.h"
#include "compliance/precompute.h"
#include "mesh/mesh.h"
#include "intestine/intestine_model.h"
#include "organ.h"
#include "rigid/rigid_surface.h"
#include "contact/tool_contacts.h"
#include "nonlinear/multirate_contacts.h"
#include "publisher.h"
#include "surgsim_types.h"
#include "dds_support.h"

namespace surgsim {

class LiverOrgan;

/// The liver's surface as an obstacle for the field's bowel (the bowel rests on the liver), both ways once couple()d:
/// - Two-way (the coupled bowel): before each liver step, gather() finds the bowel's nodes whose spheres reach the
///   liver's current surface (the nearest point of the REST surface, its outward normal, the gap there less what the
///   current solution already moved it) and hands them to the liver's solve as body points (contact::BodyPoint): the
///   liver solves them in ONE system with the instruments' rows, each a unilateral penalty of the bowel's
///   obstacle_stiffness in series with the liver's own compliance. Then nearest(node, ...) answers the bowel's step
///   with that solve's push: a hit whose overlap is push / stiffness along the same normal, so the bowel's implicit
///   step starts from the push the liver took (action and reaction equal) and linearizes it with its own stiffness.
///   No lag between the two organs: a lagged exchange (the bowel on last tick's dent) diverges, since the liver's
///   compliance times the penalty is a loop gain of tens. The dent is in the liver's contact solution, so the
///   visual node draws it from the ContactFrame as it draws an instrument's.
/// - One-way (any other body, and a coupled node the solve had no room for): the nearest point of the rest surface
///   moved to where the liver's current contact solution has it, and the deformed triangle's normal.
/// Answers nothing after a change of the liver's topology (a cut: the rest surface it was built on is gone).
class LiverObstacle final : public intestine::Obstacle {
 public:
  /// Init (allocates; throws surgsim::core::Error naming `where` when the liver's surface is not a consistently
  /// oriented triangle surface).
  LiverObstacle(const LiverOrgan& liver, const std::string& where);
  /// Init (allocates): `model` and `state` (which must outlive this) rest on the liver two-way from now on. One body
  /// only: throws surgsim::core::Error naming `where` for a second.
  void couple(const intestine::IntestineModel& model, const intestine::IntestineState& state, const std::string& where);
  bool coupled() const { return body_model_ != nullptr; }
  /// Loop thread, before the liver's step, no allocation: the coupled body's points for this step into out[0..room)
  /// (the first of the liver's body points: point j is out[j]); returns their count. Points past `room` stay one-way
  /// (counted: overflow()).
  int gather(const contact::ToolContacts& contacts, contact::BodyPoint* out, int room) noexcept;
  bool nearest(const Eigen::Vector3d& p, double max_distance, intestine::ObstacleHit& hit) const noexcept override;
  bool nearest(int node, const Eigen::Vector3d& p, double max_distance,
               intestine::ObstacleHit& hit) const noexcept override;
  /// Body points left one-way (no room in the solve) since construction.
  long overflow() const { return overflow_; }

 private:
  static constexpr double kDentReach = 0.02;  // m searched beyond the query's reach: the deepest dent it follows
  static constexpr double kEngage = 0.0005;   // m: a node within this of the current surface gets a row (released
                                              // by the solve when it would pull)
  const LiverOrgan& liver_;
  rigid::RigidSurface rest_;
  std::uint64_t generation_ = 0;
  const intestine::IntestineModel* body_model_ = nullptr;
  const intestine::IntestineState* body_state_ = nullptr;
  double body_stiffness_ = 0;       // N/m, the body's obstacle_stiffness
  static constexpr int kAway = -2;  // point_of_node_: clear of the surface in the last gather (-1: not looked at)
  std::vector<int> point_of_node_;  // per body node: its body point in the last gather, or kAway / -1
  long overflow_ = 0;
};

class LiverOrgan final : public HapticOrgan {
 public:
  /// Init (allocates; may precompute the tensors, with progress on `progress`). Throws surgsim::core::Error (multirate:
  /// also for a surface of more than msg::kMaxBodyPoints nodes). `tracker_thread` false (tests): a multirate scene's
  /// tracker is not started; the test cycles it with multirate()->cycle_once(). `tracker_threads`: the tracker's
  /// numeric threads (MultirateContacts::set_numeric_threads).
  /// `rotations_in_loop` (unpaced replays): a corotational liver refreshes its rotations in step(), every
  /// 1 / kRotationRefreshHz of simulated time, instead of on its thread: the same input gives the same forces.
  LiverOrgan(const scene::Scene& scene, const std::string& cache_dir, std::ostream* progress,
             bool tracker_thread = true, int tracker_threads = 1, bool rotations_in_loop = false);
  /// Stops the rotation thread (corotational) and the tracker thread (multirate).
  ~LiverOrgan() override;
  LiverOrgan(const LiverOrgan&) = delete;
  LiverOrgan& operator=(const LiverOrgan&) = delete;

  const char* model_name() const override { return "liver"; }
  using HapticOrgan::step;
  void step(const contact::InstrumentInput* inputs, int count, double dt, contact::ContactTick* out) noexcept override;
  int contacts() const noexcept override { return contacts_->solution().count; }
  int instrument_contacts(int i) const noexcept override { return contacts_->instrument_nodes(i); }
  int contact_entries() const noexcept override { return contacts_->solution().count; }
  const contact::ContactStageTimes* stage_times() const noexcept override { return &contacts_->stage_times(); }
  void time_stages(bool on) override {
    time_stages_ = on;
    contacts_->time_stages(on);
  }
  ContactEntry contact_entry(int l) const noexcept override;
  std::uint64_t mesh_hash() const override { return instance_->model().mesh_hash; }
  std::uint64_t tensor_hash() const override { return instance_->model().tensor_hash; }
  std::uint32_t node_count() const override { return static_cast<std::uint32_t>(mesh().nodes.rows()); }
  std::uint32_t surface_node_count() const override { return static_cast<std::uint32_t>(surface().nodes.size()); }
  bool nonlinear_law() const override { return !instance_->model().law.identity(); }
  std::string describe() const override;

  /// Multirate: the BodyState writer and its preallocated sample (nothing otherwise).
  void create_writers(dds::Participant& participant, std::uint64_t scene_hash) override;
  /// Multirate, publisher thread, no allocation: a BodyState of the newest tracker surface when there is a new one
  /// and the last was at least 1 / visual rate ago.
  void write(const TickRecord& record, std::uint64_t stamp_ns) noexcept override;
  /// Shutdown: "multirate" in the stats JSON and its summary line (multirate only; stops the tracker thread first).
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out) const override;

  const mesh::TetMesh& mesh() const { return instance_->model().mesh; }
  const mesh::SurfaceMesh& surface() const { return instance_->model().surface; }
  /// The model the loop steps (its topology generation: model().generation).
  const liver::LiverModel& model() const { return instance_->model(); }

  /// Off the loop thread (allocates): a new instance on `next` (e.g. the model after a cut) is built and handed to
  /// the loop, which swaps it in at the start of its next step() without allocating or freeing; the instance it
  /// replaces is freed here at the next call, by collect_retired() or by the destructor. The new instance starts
  /// without contacts: a tool inside the organ is found again in that first tick (as after an input loss). Throws
  /// surgsim::core::Error for a corotational or multirate liver (their threads are bound to the current instance)
  /// and while the previous model has not been taken yet.
  void post_model(std::shared_ptr<const liver::LiverModel> next);
  /// Off the loop thread: frees the instance the last swap replaced; true if there was one.
  bool collect_retired();
  /// Whether a posted model waits for the loop's next step().
  bool model_pending() const { return incoming_.full(); }
  /// Multirate (null otherwise).
  nonlinear::MultirateContacts* multirate() const { return multirate_.get(); }
  std::uint64_t body_states_published() const { return body_published_.load(std::memory_order_relaxed); }
  const contact::ToolContacts& liver_contacts() const { return *contacts_; }
  /// Init: the liver as an obstacle for the field's other bodies (built on the first call; CompositeOrgan gives it to
  /// the bowel). `where` names the organ in errors.
  LiverObstacle& obstacle(const std::string& where);
  /// Init: a rigid organ's surface (which must outlive this) the liver may not pass: each surface node of the liver
  /// within kWallEngage of it (at its current position) is one more unilateral row of the liver's solve, pushed out
  /// along the wall's normal with the penalty `stiffness` (N/m) in series (contact::BodyPoint on the node alone), in
  /// the same system as the instruments' rows and the bowel's. `name` in the stats ("walls"). The free surface nodes
  /// within the scene's liver.wall_reach of the surface at rest are looked at. Each tick, a bound on every such
  /// node's displacement, sum over the solution's nodes of max_n |G(n, c)| |lambda_c| (O(contacts)), leaves out the
  /// nodes whose rest distance less kWallEngage is beyond it; of the others, those displaced at least that far are
  /// queried against the surface (none other can be nearer).
  void add_wall(const rigid::RigidSurface& surface, double stiffness, const std::string& name);
  static constexpr double kWallEngage = 0.0005;  // m
  static constexpr double kWallCatch = 0.005;    // m: a node this far past the surface is still pushed back out
  int wall_count() const { return static_cast<int>(walls_.size()); }

 private:
  std::vector<tool::ToolSpec> tools_;
  compliance::LiverDeformation deformation_ = compliance::LiverDeformation::kLinear;
  std::unique_ptr<nonlinear::MultirateContacts>
      multirate_;                                   // multirate only (before contacts_: it outlives the pointer there)
  std::unique_ptr<liver::LiverInstance> instance_;  // the model and the contact state the loop steps
  contact::ToolContacts* contacts_ = nullptr;       // &instance_->contacts()
  // Model swaps: a new instance from post_model() to the loop, the replaced one back to be freed off the loop.
  concurrency::HandOff<liver::LiverInstance> incoming_;
  concurrency::HandOff<liver::LiverInstance> retired_;
  // liver.deformation corotational: every surface node's rotation refreshed off the loop thread.
  static constexpr double kRotationRefreshHz = 200;
  std::atomic<bool> stop_rotations_{false};
  bool rotations_in_loop_ = false;
  bool time_stages_ = false;   // time_stages(): given to every instance post_model() builds
  double rotation_clock_ = 0;  // s of simulated time since the last refresh (rotations_in_loop_)
  std::thread rotation_thread_;
  // Multirate BodyState (publisher thread).
  struct InstrumentsAt {  // the instruments of one tick
    std::uint64_t seq = ~0ull;
    int count = 0;
    std::array<InstrumentRecord, tool::kMaxInstruments> instruments{};
  };
  static constexpr std::size_t kInstrumentTicks = 512;  // ticks kept: more than a tracker cycle at 1 kHz
  std::vector<InstrumentsAt> instruments_at_;
  TickRecord scratch_;
  struct Wall {
    const rigid::RigidSurface* surface = nullptr;
    double stiffness = 0;
    std::string name;
    std::vector<int> nodes;      // the liver's free surface nodes within wall_reach_ of it at rest, nearest first
    std::vector<double> reach;   // each one's rest distance less kWallEngage: no row while |u| is below it
    double nearest_at_rest = 0;  // m, the nearest of them at rest
    int first = 0, count = 0;    // its body points in the last step
    std::uint64_t dropped = 0;   // rows left out: the liver's solve full (ToolContacts::kMaxBodyPoints)
    double max_penetration = 0;
    std::uint64_t contact_ticks = 0;
    int contacts_max = 0;
  };
  /// Loop thread: the walls' body points after the bowel's, from `begin`; returns the new count.
  int gather_walls(int begin) noexcept;
  /// Loop thread, after the step: each wall's deepest push.
  void account_walls() noexcept;
  std::vector<Wall> walls_;
  double wall_reach_ = 0;  // m, the scene's liver.wall_reach
  // Per node c of the mesh: the largest |G(n, c)| (Frobenius, m/N) over the walls' nodes n (0 where c takes no
  // load): the walls' displacement bound.
  std::vector<double> wall_compliance_;
  std::array<contact::BodyPoint, contact::ToolContacts::kMaxBodyPoints> bodies_{};
  std::unique_ptr<LiverObstacle> obstacle_;  // obstacle(): built on demand, in a field with a bowel (gathers its
                                             // coupled body's points before each step)
  std::uint64_t min_period_ns_ = 0;
  std::uint64_t last_body_ns_ = 0;
  std::uint64_t body_seq_ = 0;
  bool body_pending_ = false;
  eprosima::fastdds::dds::DataWriter* writer_ = nullptr;
  msg::BodyState sample_;
  std::atomic<std::uint64_t> body_published_{0};
};

}  // namespace surgsim
