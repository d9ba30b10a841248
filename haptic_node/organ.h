// The haptic node's one organ interface: what the loop needs from an organ, whatever its model. The liver
// (precomputed FEM contacts, organs/liver_organ.h) and the intestine (mass-spring body, organs/intestine_organ.h) are
// its two implementations; make_haptic_organ() is the only place that looks at the scene's model.
//
// Phases: the factory and the constructors allocate (mesh, tensors, bucket grid, body state, step-time storage);
// create_writers() allocates its DDS entities and samples once; step(), contact_entry() and fill_outputs() allocate
// nothing and never throw (loop thread); write() allocates nothing (publisher thread, publisher.h); stats and
// summaries are for shutdown.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "scene/scene.h"
#include "compliance/superposition.h"
#include "contact/contact_types.h"
#include "tool/tool.h"

namespace surgsim {

namespace dds {
class Participant;
}
struct TickRecord;

/// One contact entry of a ContactFrame (what the visual node needs to deform the organ).
struct ContactEntry {
  int node = 0;                                       // the organ's node
  int instrument = 0;                                 // whose contact holds the node (the first, when shared)
  int organ = 0;                                      // the organ's index in the scene (0 in a one-organ scene)
  Eigen::Vector3d lambda = Eigen::Vector3d::Zero();   // N, contact force on the node
  Eigen::Vector3d u_tilde = Eigen::Vector3d::Zero();  // m, corrected constraint displacement (liver multirate:
                                                      // the node's imposed displacement this tick)
};

/// Contact entries a tick carries at most: the solve's capacity (compliance::kMaxContacts, its one definition; the
/// IDL's msg::kMaxContacts is the wire's, and haptic_dds.cpp checks they agree).
inline constexpr int kMaxContactEntries = compliance::kMaxContacts;

/// A 3-vector as a tick record holds it: trivially copyable (the hand-off to the publisher thread moves records
/// word by word, concurrency/seqlock_ring.h; Eigen's vectors are not trivially copyable), converted to and from
/// Eigen::Vector3d where it is filled and read.
struct RecordVec3 {
  double v[3] = {0, 0, 0};
  RecordVec3() = default;
  template <class Derived>
  RecordVec3(const Eigen::MatrixBase<Derived>& e) : v{e(0), e(1), e(2)} {}  // NOLINT: implicit by design
  operator Eigen::Vector3d() const { return {v[0], v[1], v[2]}; }           // NOLINT: implicit by design
  Eigen::Vector3d eigen() const { return {v[0], v[1], v[2]}; }
};

/// One contact entry as a tick record holds it (ContactEntry, trivially copyable).
struct ContactRecord {
  int node = 0;
  int instrument = 0;
  int organ = 0;
  RecordVec3 lambda;   // N
  RecordVec3 u_tilde;  // m
  ContactRecord() = default;
  ContactRecord(const ContactEntry& e)  // NOLINT: implicit by design
      : node(e.node), instrument(e.instrument), organ(e.organ), lambda(e.lambda), u_tilde(e.u_tilde) {}
};

/// What an organ publishes for one tick, copied out on the loop thread (fill_outputs) and written on the publisher
/// thread (write): fixed size, no allocation. `points` is storage the hand-off owns (3 * point_capacity doubles).
/// The contacts come last: the hand-off moves only the first contact_count of them.
struct OrganOutputs {
  int contact_count = 0;
  int point_count = 0;     // body positions filled (the intestine's masses)
  int point_capacity = 0;  // output_points() of the organ
  double* points = nullptr;
  std::array<ContactRecord, kMaxContactEntries> contacts;
};

/// One organ's identity as SceneInfo carries it (init only).
struct OrganIdentity {
  std::string name;     // the scene's organ name ("" for the organ of a single-organ scene: the scene's name then)
  std::string model;    // "liver", "intestine", "rigid"
  std::uint64_t mesh_hash = 0;
  std::uint64_t tensor_hash = 0;
  std::uint32_t node_count = 0;
  std::uint32_t surface_node_count = 0;
};

class HapticOrgan {
 public:
  virtual ~HapticOrgan() = default;

  /// The model this organ implements ("liver", "intestine"): the stats key model_built.
  virtual const char* model_name() const = 0;

  /// Run phase, noexcept, no allocation: one tick of dt (s) for `count` instruments (the scene's tools, in order,
  /// 1..kMaxInstruments). inputs[i].tool is instrument i's geometry, or null while its device input is lost (the
  /// organ drops that instrument's contacts and gives it zero force; the others go on; a dynamic body keeps moving).
  /// out[i] receives instrument i's force (from its own contacts, clamped to its own device limit) and flags.
  virtual void step(const contact::InstrumentInput* inputs, int count, double dt,
                    contact::ContactTick* out) noexcept = 0;
  /// One instrument: step(&{tool, jaw}, 1, dt, &out).
  void step(const tool::ToolGeometry* tool, double jaw, double dt, contact::ContactTick& out) noexcept {
    const contact::InstrumentInput in{tool, jaw};
    step(&in, 1, dt, &out);
  }

  /// Contacts the log and the stats count this tick, all instruments (liver: contact nodes; intestine: elements the
  /// probes touch), and those of instrument i.
  virtual int contacts() const noexcept = 0;
  virtual int instrument_contacts(int i) const noexcept = 0;
  /// Contact entries the ContactFrame carries this tick (at most msg::kMaxContacts), and entry l of them.
  virtual int contact_entries() const noexcept { return 0; }
  virtual ContactEntry contact_entry(int l) const noexcept { return {}; }
  /// The time each stage of the last step's contact solve took (contact::ContactStage order), or null for an organ
  /// without them (the intestine): the --tick-trace columns.
  virtual const contact::ContactStageTimes* stage_times() const noexcept { return nullptr; }
  /// Init: whether the contact step times its stages (only for --tick-trace: the timing reads the clock 6 times a
  /// tick).
  virtual void time_stages(bool on) {}

  /// Identity both nodes compare (SceneInfo): hash of the tetrahedral mesh (0 without one) and of the tensors.
  virtual std::uint64_t mesh_hash() const { return 0; }
  virtual std::uint64_t tensor_hash() const { return 0; }
  /// SceneInfo sizes: all nodes (or masses), and the surface nodes (or the intestine's points).
  virtual std::uint32_t node_count() const = 0;
  virtual std::uint32_t surface_node_count() const = 0;
  /// True when a quasi non-linear force law bends the linear force (stats nonlinear_law).
  virtual bool nonlinear_law() const { return false; }

  /// Init: every organ this one is made of, in the scene's order (one: itself, unnamed; CompositeOrgan: each part).
  virtual std::vector<OrganIdentity> identities() const {
    return {OrganIdentity{"", model_name(), mesh_hash(), tensor_hash(), node_count(), surface_node_count()}};
  }
  /// Init, before create_writers(): this organ's index in the scene's organs list (CompositeOrgan tells each part;
  /// 0 for the organ of a one-organ scene). The organ's own topics carry it (BodyState.organ, the key).
  virtual void set_organ_index(int index) { organ_index_ = index; }
  int organ_index() const { return organ_index_; }

  /// Positions the organ publishes per tick (sizes OrganOutputs::points once, at init).
  virtual int output_points() const { return 0; }
  /// Loop thread, noexcept, no allocation: copies this tick's publishable state into `out` (the contact entries;
  /// the body positions, at most out.point_capacity). The default copies contact_entries() / contact_entry().
  virtual void fill_outputs(OrganOutputs& out) const noexcept {
    const int n = contact_entries();
    out.contact_count = n < kMaxContactEntries ? (n > 0 ? n : 0) : kMaxContactEntries;
    for (int l = 0; l < out.contact_count; ++l) out.contacts[static_cast<std::size_t>(l)] = contact_entry(l);
    out.point_count = 0;
  }

  /// Init: the organ's own topics (the intestine's BodyState). Publisher thread, no allocation: writes them from
  /// `record` (a tick's outputs, filled by fill_outputs on the loop thread), stamped `stamp_ns`.
  virtual void create_writers(dds::Participant& participant, std::uint64_t scene_hash) {}
  virtual void write(const TickRecord& record, std::uint64_t stamp_ns) noexcept {}

  /// One line for the start banner: "1382 nodes, 5523 tets, 646 surface nodes; ".
  virtual std::string describe() const = 0;
  /// Shutdown: the organ's own entries in the stats JSON, and its summary line (nothing when it has none).
  virtual void add_stats(nlohmann::json& stats) const {}
  virtual void print_summary(std::ostream& out) const {}

 protected:
  int organ_index_ = 0;  // set_organ_index()
};

/// How the node builds its organ beyond the scene (command-line settings that change no physics).
struct OrganBuildOptions {
  int tracker_threads = 1;  // the multirate liver's tracker: CHOLMOD's OpenMP and OpenBLAS threads (haptic_node
                            // --tracker-threads)
  bool unpaced = false;     // --speed max: the corotational liver refreshes its rotations on the loop, every 5 ms of
                            // simulated time, instead of on a 200 Hz thread, so that a replay is reproducible
};

/// Builds the organ the scene names. `cache_dir` holds generated meshes and tensors, `ticks` the run's length (for
/// per-tick storage), `progress` receives mesh and precompute progress (null: silent). Throws surgsim::core::Error
/// naming the scene file for a model this node does not build.
std::unique_ptr<HapticOrgan> make_haptic_organ(const scene::Scene& scene, const std::string& cache_dir,
                                               std::uint64_t ticks, std::ostream* progress,
                                               const OrganBuildOptions& build = OrganBuildOptions());

}  // namespace surgsim
