// The multirate non-linear liver in the haptic node (scene key liver.deformation: multirate): the scene's
// liver as a neo-Hookean organ (fem/hyperelastic.h: same mesh, material and fixed set as the tensors) tracked by a
// NonlinearTracker (nonlinear/multirate.h) on a thread of its own, and the 1 kHz side that turns the tracker's
// snapshots into the contact forces of the tick.
//
// Loop -> tracker: every tick hand_over() writes the tick's contact solution (its nodes and their displacements: the
// linear solve's) as the tracker's targets into a TripleBuffer (no allocation), with the tick's sim time and each
// node's velocity (for the prediction below). Tracker -> loop: the tracker's own snapshot buffer.
// apply(): the forces of the tick from the newest snapshot's local model, lambda = f_c + S du, per node:
//   - a node of the solution that the snapshot holds: f_c of that node + S du over the nodes both sets hold (du =
//     u_now - u_snapshot, clamped to max_extrapolation per node, as local_contact_forces);
//   - a node the snapshot does not hold (it just entered the contact): the linear solve's lambda;
//   - a node of the snapshot no longer in contact: dropped (its force and its column of S).
// So a patch whose edge nodes enter and leave while the tool slides does not fall back to the linear model as a
// whole: the nodes that change are at the patch edge, where the Wendland weights and hence the reactions go to 0,
// and the force changes by about their reaction only. The tick is counted nonlinear (the sets are equal), partial
// (some nodes matched) or linear fallback (no valid snapshot, no node matched, a non-finite result, or a trust weight
// of 0: then every lambda is the linear one, plus the fading bump below). No allocation; O(m^2) with
// m <= kMaxContacts.
// Trust region: with the largest |du| of the common nodes above kTrustFraction of max_extrapolation, the local
// model's lambdas are blended with the linear solve's, the linear weight growing linearly to 1 at max_extrapolation;
// the weight moves by at most kBlendRate a tick (20 ticks from one model to the other, also when a contact's first
// snapshot arrives), then linear fallback. The tracker lags a tool faster than it (and a released grasp's hold fades
// in 50 ms): the force then goes over to the linear model, which follows the motion, over 20 ticks instead of
// jumping when the contact ends (a grasp released after a 60 degree lift dropped 3 N in one tick without it).
// Every hand-over is rate-limited: the correction of the linear reaction sum the tick delivers, C = w D with
// D = sum over the held nodes of (f_c + S du - linear lambda), moves with the tool, but a change of model (a new
// snapshot; another set of nodes held, as a node leaves the patch or the contact set jumps away from the snapshot's;
// the local model gone: no node matched, a non-finite value; or back) would step it. On such a tick the step is
// kept as a bump, C + bump = last tick's correction, and the bump fades out linearly in 1 / kBlendRate ticks, spread
// over the tick's nodes in proportion to their linear lambdas. At the live cycle times (65-130 ms, the local model
// extrapolated several mm) a new snapshot or a node leaving a sliding patch stepped the force by up to 12 % of it
// without this. A tick without contact resets the weight and the bump: the next contact starts on the linear model
// and the local model takes over in 20 ticks again, even when the snapshot of before still holds its nodes (a tool
// lifted off for less than a tracker cycle).
//
// The tracker thread (start()): normal scheduling (it sets SCHED_OTHER itself), CHOLMOD's OpenMP and OpenBLAS on one
// thread, started by the caller's thread so it inherits that thread's CPU set (the haptic node builds its organ after
// --cpu N moved every thread but the loop off CPU N). Each cycle reads the
// newest targets, predicts them by the last cycle's time (each node moved along its velocity; off with
// set_prediction(false)), runs one tracker cycle and publishes the tracker's surface displacement (for the organ's
// BodyState) through another TripleBuffer. It sleeps kIdleSleep instead of cycling when nothing is left to do: the
// targets have not changed since a cycle that converged, or there is no contact and the organ is back at rest.
// Tests drive it without the thread: cycle_once() runs one such cycle on the calling thread; begin_cycle() and
// finish_cycle() replay the thread's cycles on the loop's ticks (targets taken when a cycle starts, its snapshot
// visible when it ends, the next cycle predicting by the replayed cycle time as the live thread does by the measured
// one), so a test runs at the live cycle times deterministically.
#pragma once
#include <Eigen/Core>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "core/stats.h"
#include "compliance/corotation.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "fem/hyperelastic.h"
#include "nonlinear/multirate.h"
#include "compliance/superposition.h"
#include "mesh/mesh.h"

namespace surgsim::nonlinear {

/// What the loop hands the tracker each tick (fixed size).
struct LoopTargets {
  ContactTargets targets;                                            // the tick's contact nodes and displacements (m)
  std::array<Eigen::Vector3d, compliance::kMaxContacts> velocity{};  // m/s, each node's displacement rate (filtered)
  double sim_time = 0;                                               // s, the tick's haptic sim time
  std::uint64_t tick = 0;                                            // the tick's index (the node's record seq)
};

/// The tracker's surface for the organ's BodyState (tracker thread -> publisher thread).
struct TrackerSurface {
  bool valid = false;
  std::uint64_t cycle = 0;  // the tracker cycle whose state it is
  double sim_time = 0;      // s, sim time of the targets that cycle was computed for
  std::uint64_t tick = 0;   // their tick
  Eigen::VectorXd u;        // 3 x #surface nodes, m
};

/// Where a tick's forces came from (apply()).
enum class MultirateUse : std::uint8_t { kNoContact = 0, kNonlinear, kPartial, kLinearFallback };

class MultirateContacts {
 public:
  static constexpr std::chrono::microseconds kIdleSleep{1500};
  static constexpr double kVelocityFilter = 0.1;   // per tick: an exponential filter of about 10 ticks
  static constexpr double kMaxPrediction = 0.005;  // m: the prediction moves a target by at most this
  static constexpr double kMinPrediction = 1e-6;   // m: and not at all when it would move it by less
  static constexpr double kTrustFraction = 0.5;    // of max_extrapolation: the local model's full weight up to it
  static constexpr double kBlendRate = 0.05;       // per tick: the local model's weight changes by at most this

  /// The node's tracker options: those of large_deformation_bench's moving-tool figures (one Newton iteration and up
  /// to 10 modified-Newton corrections per cycle, at most 5 mm per predictor; the rest MultirateOptions' defaults).
  static MultirateOptions node_options();

  /// Init (allocates): the neo-Hookean model of `mesh` with `material` and `fixed` (the tensors' own), a tracker
  /// whose snapshots carry the displacement of `surface_nodes` (SurfaceMesh::nodes order). `mesh` must outlive
  /// this object. Throws surgsim::core::Error (prefixed with `where`, the scene file) on a bad model.
  MultirateContacts(const mesh::TetMesh& mesh, const fem::Material& material, const fem::FixedSet& fixed,
                    std::vector<int> surface_nodes, const std::string& where,
                    const MultirateOptions& options = node_options());
  ~MultirateContacts();
  MultirateContacts(const MultirateContacts&) = delete;
  MultirateContacts& operator=(const MultirateContacts&) = delete;

  /// Threads of CHOLMOD's OpenMP and of OpenBLAS for the tracker's factorizations and solves (>= 1; default 1), set
  /// by the tracker thread when it starts. Before start(). Throws surgsim::core::Error for n < 1.
  void set_numeric_threads(int n);
  int numeric_threads() const { return numeric_threads_; }
  /// Starts the tracker thread (once). stop() joins it; the destructor calls stop().
  void start();
  void stop();
  /// Tests: one tracker cycle on the calling thread, as the thread would run it (with its idle rule: returns false
  /// without cycling when it would sleep). Not while the thread runs.
  bool cycle_once();
  /// Tests: the tracker thread's cycle replayed on the loop's ticks, in two halves. begin_cycle() takes the newest
  /// targets, as a cycle does when it starts, and returns false when the thread would sleep instead (the idle rule:
  /// try again a tick later). finish_cycle(cycle_s) runs that cycle on the targets taken (its snapshot is the one the
  /// loop's next apply() uses, as at the end of a cycle that took cycle_s) and keeps cycle_s as the cycle's time: the
  /// horizon the next cycle predicts by, which the live thread measures. Not while the thread runs.
  bool begin_cycle();
  bool finish_cycle(double cycle_s);
  /// Predict the targets by the last cycle's measured time (default on), or with `fixed_horizon_s` > 0 by that
  /// (deterministic: tests). Before start() / between cycle_once() calls.
  void set_prediction(bool on, double fixed_horizon_s = 0) {
    predict_ = on;
    fixed_horizon_s_ = fixed_horizon_s;
  }

  // --- loop thread, noexcept, no allocation ---
  /// The forces of this tick: replaces solution.lambda (and tool_force) of the nodes the newest snapshot covers by
  /// its local model (file comment). Call it before this tick's hand_over().
  MultirateUse apply(compliance::ContactSolution& solution) noexcept;
  /// Hands this tick's solution (nodes, displacements; count 0 without contact) to the tracker as its targets.
  void hand_over(const compliance::ContactSolution& solution, double dt) noexcept;

  // --- publisher thread ---
  /// The newest surface the tracker published since the last call (true), readable through surface().
  bool take_surface() noexcept { return surfaces_.take(); }
  const TrackerSurface& surface() const { return surfaces_.front(); }

  // --- counters (the loop's are exact once the loop stopped; the tracker's once stop() returned) ---
  std::uint64_t ticks_nonlinear() const { return ticks_[1]; }
  std::uint64_t ticks_partial() const { return ticks_[2]; }
  std::uint64_t ticks_linear_fallback() const { return ticks_[3]; }
  /// Ticks whose local model was blended with the linear solve (trust region), or that carried the fading bump of a
  /// change of model (also linear fallback ticks).
  std::uint64_t ticks_blended() const { return blended_; }
  std::uint64_t tracker_cycles() const { return cycles_.load(std::memory_order_relaxed); }
  std::uint64_t snapshots_published() const { return published_.load(std::memory_order_relaxed); }
  std::uint64_t tracker_failures() const { return failures_.load(std::memory_order_relaxed); }
  std::uint64_t idle_sleeps() const { return idle_.load(std::memory_order_relaxed); }
  /// Shutdown (allocate): cycle wall time (ms) and snapshot age at use (ms, sim time of the tick minus that of the
  /// snapshot's targets) percentiles, and the extrapolation |u_now - u_snapshot| (mm, largest node of a tick).
  double cycle_ms(double q) const { return cycle_ms_.percentile(q); }
  double age_ms(double q) const { return age_ms_.percentile(q); }
  /// Over the ticks whose contact nodes are not where the snapshot has them: the time since its targets or since the
  /// last tick they were (ms; a held tool's converged snapshot ages without being stale).
  double stale_ms(double q) const { return stale_ms_.percentile(q); }
  double extrapolation_mm(double q) const { return extrapolation_mm_.percentile(q); }
  /// The snapshot apply() used last (loop thread; tests).
  const TrackerSnapshot& snapshot() const { return tracker_->snapshots().front(); }

 private:
  void run() noexcept;
  /// One cycle towards the newest targets (or, with `take` false, those taken last) unless idle; the cycle's wall time
  /// goes to the ring, and the next cycle predicts by it, or by `replay_cycle_s` when that is > 0.
  bool cycle_if_needed(bool take = true, double replay_cycle_s = 0);
  /// The idle rule: the same targets as a cycle that converged at them.
  bool idle(const ContactTargets& targets) const;
  /// No contact: the local model's weight and the bump go (the next contact starts on the linear model).
  void end_contact() noexcept;

  std::unique_ptr<fem::ElasticModel> model_;
  std::unique_ptr<fem::HyperelasticSolver> solver_;
  std::vector<int> surface_nodes_;
  std::unique_ptr<NonlinearTracker> tracker_;
  // loop -> tracker
  concurrency::TripleBuffer<LoopTargets> targets_;
  // tracker -> publisher
  concurrency::TripleBuffer<TrackerSurface> surfaces_;
  // The tick of the targets of tracker cycle c, at [c % kCycleTicks] (written before the cycle publishes: the
  // snapshot buffer's release orders it for the loop).
  static constexpr std::size_t kCycleTicks = 256;
  std::array<std::atomic<std::uint64_t>, kCycleTicks> cycle_tick_{};

  // --- loop thread ---
  std::array<Eigen::Vector3d, compliance::kMaxContacts> lambda_{};  // this tick's local model, then the blended lambdas
  std::array<bool, compliance::kMaxContacts> held_{};               // per solution node: the snapshot holds it
  std::vector<Eigen::Vector3d> last_u_;    // #V: each node's displacement at the tick last_tick_
  std::vector<Eigen::Vector3d> velocity_;  // #V: m/s, filtered
  std::vector<std::uint64_t> last_tick_;   // #V: the tick a node was last in contact (+1; 0: never)
  std::uint64_t tick_ = 0;                 // ticks handed over
  double dt_ = 0;                          // s, the last tick's
  std::array<std::uint64_t, 4> ticks_{};   // by MultirateUse
  std::uint64_t blended_ = 0;
  double weight_ = 0;  // the local model's weight (trust region, rate-limited)
  // The hand-over (N, corrections of the reaction sum, the organ's side): delivered_ the last tick's correction of
  // the linear solve's reaction sum (the weighted local model plus the bump), bump_ what a change of model would have
  // stepped it by, fading by bump_step_ a tick.
  Eigen::Vector3d delivered_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d bump_ = Eigen::Vector3d::Zero();
  double bump_step_ = 0;
  bool had_local_ = false;              // the last tick in contact had a local model
  std::uint64_t model_cycle_ = 0;       // the cycle of its snapshot
  int held_count_ = 0;                  // the nodes it held
  std::uint64_t apply_tick_ = 0;        // apply() calls with contact
  std::vector<std::uint64_t> held_at_;  // #V: the apply_tick_ a node was last held by the local model
  core::SampleRecorder age_ms_{1 << 16, core::SampleRecorder::Keep::kNewest};
  core::SampleRecorder stale_ms_{1 << 16, core::SampleRecorder::Keep::kNewest};
  std::uint64_t stale_cycle_ = 0, exact_tick_ = 0;
  core::SampleRecorder extrapolation_mm_{1 << 16, core::SampleRecorder::Keep::kNewest};

  // --- tracker thread ---
  int numeric_threads_ = 1;
  bool predict_ = true;
  double fixed_horizon_s_ = 0;
  ContactTargets cycled_;  // the targets of the last cycle (before prediction)
  bool have_cycled_ = false;
  bool last_converged_ = false;
  double last_cycle_s_ = 0;
  ContactTargets predicted_;
  core::SampleRecorder cycle_ms_{1 << 14, core::SampleRecorder::Keep::kNewest};
  std::atomic<std::uint64_t> cycles_{0}, published_{0}, failures_{0}, idle_{0};
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace surgsim::nonlinear
