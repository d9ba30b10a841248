#include "nonlinear/multirate_contacts.h"

#include <dlfcn.h>
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <utility>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;

namespace surgsim::nonlinear {

MultirateOptions MultirateContacts::node_options() {
  MultirateOptions o;
  o.iterations_per_cycle = 1;
  o.corrections_per_cycle = 10;
  o.max_step = 0.005;
  return o;
}

MultirateContacts::MultirateContacts(const TetMesh& mesh, const Material& material, const FixedSet& fixed,
                                     std::vector<int> surface_nodes, const std::string& where,
                                     const MultirateOptions& options)
    : model_(std::make_unique<ElasticModel>(build_elastic_model(mesh, material, fixed, where))),
      solver_(std::make_unique<HyperelasticSolver>(*model_)),
      surface_nodes_(std::move(surface_nodes)),
      tracker_(std::make_unique<NonlinearTracker>(*solver_, surface_nodes_, options)) {
  const auto nv = static_cast<std::size_t>(mesh.nodes.rows());
  last_u_.assign(nv, Eigen::Vector3d::Zero());
  velocity_.assign(nv, Eigen::Vector3d::Zero());
  last_tick_.assign(nv, 0);
  held_at_.assign(nv, 0);
  for (int i = 0; i < 3; ++i)
    surfaces_.slot(i).u = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(surface_nodes_.size()));
  for (auto& t : cycle_tick_) t.store(0, std::memory_order_relaxed);
}

MultirateContacts::~MultirateContacts() { stop(); }

void MultirateContacts::set_numeric_threads(int n) {
  if (n < 1) throw_error("multirate tracker: ", n, " numeric threads; give 1 or more");
  numeric_threads_ = n;
}

void MultirateContacts::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  thread_ = std::thread([this] { run(); });
}

void MultirateContacts::stop() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

namespace {
// The tracker's factorizations and solves on `n` threads: CHOLMOD's OpenMP regions started from this thread (a
// per-thread setting) and OpenBLAS (process-wide; the haptic node calls no BLAS after init). Default 1: beside the
// visual node on 2 CPUs a 2-thread factorization waited for the renderer (cycle p50 91-99 ms against 65-66 ms; README,
// haptic_node --tracker-threads). A no-op without them (another BLAS).
void numerics_on_threads(int n) noexcept {
  for (const char* name : {"omp_set_num_threads", "openblas_set_num_threads"})
    if (auto set = reinterpret_cast<void (*)(int)>(dlsym(RTLD_DEFAULT, name))) set(n);
}
}  // namespace

void MultirateContacts::run() noexcept {
  // Normal scheduling whatever the starting thread had (a thread inherits its creator's policy): the tracker must
  // never compete with the loop or the DDS threads.
  sched_param normal{};
  normal.sched_priority = 0;
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &normal);
  numerics_on_threads(numeric_threads_);
  while (!stop_.load(std::memory_order_relaxed)) {
    bool cycled = false;
    try {
      cycled = cycle_if_needed();
    } catch (const std::exception&) {
      // A refused target set (it cannot happen with the loop's solutions: distinct in-range nodes, finite) or an
      // allocation failure: counted, and the tracker starts again from rest.
      failures_.fetch_add(1, std::memory_order_relaxed);
      tracker_->reset();
      have_cycled_ = false;
    }
    if (!cycled) std::this_thread::sleep_for(kIdleSleep);
  }
}

bool MultirateContacts::cycle_once() { return cycle_if_needed(); }

bool MultirateContacts::begin_cycle() {
  targets_.take();
  const bool needed = !idle(targets_.front().targets);
  if (!needed) idle_.fetch_add(1, std::memory_order_relaxed);
  return needed;
}

bool MultirateContacts::finish_cycle(double cycle_s) { return cycle_if_needed(false, cycle_s); }

namespace {
bool same_targets(const ContactTargets& a, const ContactTargets& b) {
  if (a.count != b.count) return false;
  for (int k = 0; k < a.count; ++k) {
    const auto sk = static_cast<std::size_t>(k);
    if (a.nodes[sk] != b.nodes[sk] || (a.u[sk] - b.u[sk]).norm() > 1e-9) return false;
  }
  return true;
}
}  // namespace

bool MultirateContacts::idle(const ContactTargets& targets) const {
  // The same targets as a cycle that converged (a held tool), or no contact with the organ already at rest.
  return have_cycled_ && last_converged_ && same_targets(targets, cycled_);
}

bool MultirateContacts::cycle_if_needed(bool take, double replay_cycle_s) {
  if (take) targets_.take();
  const LoopTargets& in = targets_.front();
  if (idle(in.targets)) {
    idle_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  cycled_ = in.targets;
  predicted_ = in.targets;
  // The prediction: the snapshot becomes visible about one cycle later, so ask for where each node will be then
  // (its velocity times the last cycle's time, at most kMaxPrediction).
  const double horizon = fixed_horizon_s_ > 0 ? fixed_horizon_s_ : last_cycle_s_;
  bool predicted = false;
  if (predict_ && horizon > 0) {
    for (int k = 0; k < predicted_.count; ++k) {
      const auto sk = static_cast<std::size_t>(k);
      Eigen::Vector3d d = in.velocity[sk] * horizon;
      const double len = d.norm();
      if (!(len <= kMaxPrediction)) d *= std::isfinite(len) ? kMaxPrediction / len : 0.0;
      if (len >= kMinPrediction) {  // a held tool's decaying velocity moves nothing
        predicted_.u[sk] += d;
        predicted = true;
      }
    }
  }
  const std::uint64_t cycle = tracker_->cycles() + 1;
  cycle_tick_[static_cast<std::size_t>(cycle % kCycleTicks)].store(in.tick, std::memory_order_relaxed);
  const TrackerCycle cy = tracker_->cycle(predicted_);
  have_cycled_ = true;
  // Converged at the targets themselves (not at predicted ones): only then may the tracker sleep on them.
  last_converged_ = cy.converged && cy.published && !predicted;
  last_cycle_s_ = replay_cycle_s > 0 ? replay_cycle_s : cy.total_ms * 1e-3;
  cycle_ms_.add(cy.total_ms);
  cycles_.fetch_add(1, std::memory_order_relaxed);
  if (!cy.failure.empty()) failures_.fetch_add(1, std::memory_order_relaxed);
  if (cy.published) {
    published_.fetch_add(1, std::memory_order_relaxed);
    // The surface of the published state for the BodyState (the publisher thread takes it).
    TrackerSurface& s = surfaces_.back();
    const Eigen::VectorXd& u = tracker_->state();
    for (std::size_t i = 0; i < surface_nodes_.size(); ++i)
      s.u.segment<3>(3 * static_cast<Eigen::Index>(i)) = u.segment<3>(3 * surface_nodes_[i]);
    s.valid = s.u.allFinite();
    s.cycle = cycle;
    s.sim_time = in.sim_time;
    s.tick = in.tick;
    surfaces_.publish();
  }
  return true;
}

void MultirateContacts::hand_over(const ContactSolution& solution, double dt) noexcept {
  ++tick_;
  dt_ = dt;
  LoopTargets& out = targets_.back();
  const int m = std::clamp(solution.count, 0, kMaxContacts);
  if (m == 0) end_contact();
  out.targets.count = m;
  out.sim_time = static_cast<double>(tick_ - 1) * dt;
  out.tick = tick_ - 1;
  for (int l = 0; l < m; ++l) {
    const auto sl = static_cast<std::size_t>(l);
    const int node = solution.nodes[sl];
    const auto sn = static_cast<std::size_t>(node);
    const Eigen::Vector3d& u = solution.displacement[sl];
    out.targets.nodes[sl] = node;
    out.targets.u[sl] = u;
    // The node's velocity: filtered differences of consecutive ticks in contact; 0 for a node new to the contact.
    if (last_tick_[sn] == tick_ - 1 && tick_ > 1 && dt > 0) {
      velocity_[sn] += kVelocityFilter * ((u - last_u_[sn]) / dt - velocity_[sn]);
    } else {
      velocity_[sn].setZero();
    }
    if (!velocity_[sn].allFinite()) velocity_[sn].setZero();
    last_u_[sn] = u;
    last_tick_[sn] = tick_;
    out.velocity[sl] = velocity_[sn];
  }
  targets_.publish();
}

void MultirateContacts::end_contact() noexcept {
  weight_ = 0;
  delivered_.setZero();
  bump_.setZero();
  bump_step_ = 0;
  had_local_ = false;
  held_count_ = 0;
}

MultirateUse MultirateContacts::apply(ContactSolution& solution) noexcept {
  const int m = std::clamp(solution.count, 0, kMaxContacts);
  if (m == 0) {
    end_contact();
    ++ticks_[0];
    return MultirateUse::kNoContact;
  }
  ++apply_tick_;
  NonlinearTracker& tracker = *tracker_;
  tracker.snapshots().take();
  const TrackerSnapshot& s = tracker.snapshots().front();
  // The local model at the nodes the snapshot holds (f_c + S du over the common nodes, du clamped); the others keep
  // the linear solve's lambda.
  const double max_d = tracker.options().max_extrapolation;
  double largest = 0;
  const int matched = snapshot_forces(s, solution.nodes.data(), solution.displacement.data(), m, max_d, lambda_.data(),
                                      held_.data(), largest);
  // Its correction of the linear solve's reaction sum; not finite: as if no node matched.
  Eigen::Vector3d correction = Eigen::Vector3d::Zero();
  for (int l = 0; l < m; ++l) {
    const auto sl = static_cast<std::size_t>(l);
    if (held_[sl]) correction += lambda_[sl] - solution.lambda[sl];
  }
  const bool local = matched > 0 && correction.allFinite();
  // Trust: a local model evaluated far from its state (a tool faster than the tracker, a released grasp fading in
  // 50 ms) hands over to the linear solve continuously: full weight up to half the extrapolation limit, none at it.
  // The weight moves by at most kBlendRate a tick, so the hand-over (and the take-over from the linear model when a
  // contact's first snapshot arrives) lasts 1 / kBlendRate ticks at least; until it reaches 0 the clamped local model
  // is still used, with a shrinking weight. Without a local model the weight falls at the same rate.
  if (local) {
    const double target = std::clamp((max_d - largest) / (max_d - kTrustFraction * max_d), 0.0, 1.0);
    weight_ = std::clamp(target, weight_ - kBlendRate, weight_ + kBlendRate);
  } else {
    weight_ = std::max(0.0, weight_ - kBlendRate);
  }
  const double w = local ? weight_ : 0.0;
  const Eigen::Vector3d model = w * correction;
  // A change of model (a new snapshot, another set of nodes held, the local model gone or back) would step the
  // correction: the step is carried as the bump and fades out at kBlendRate of it a tick.
  bool changed = local != had_local_ || (local && (s.cycle != model_cycle_ || matched != held_count_));
  for (int l = 0; l < m; ++l) {
    const auto sl = static_cast<std::size_t>(l);
    if (!held_[sl]) continue;
    const auto node = static_cast<std::size_t>(solution.nodes[sl]);
    changed = changed || held_at_[node] + 1 != apply_tick_;
    held_at_[node] = apply_tick_;
  }
  had_local_ = local;
  model_cycle_ = s.cycle;
  held_count_ = local ? matched : 0;
  if (changed) {
    bump_ = delivered_ - model;
    bump_step_ = kBlendRate * bump_.norm();
  } else {
    const double n = bump_.norm();
    bump_ = n > bump_step_ ? Eigen::Vector3d(bump_ * ((n - bump_step_) / n)) : Eigen::Vector3d::Zero();
  }
  delivered_ = model + bump_;
  if (!delivered_.allFinite()) end_contact();  // cannot happen (finite parts); never a non-finite force
  const bool bumped = !bump_.isZero(0);

  if (local && w > 0) {
    for (int l = 0; l < m; ++l) {
      const auto sl = static_cast<std::size_t>(l);
      solution.lambda[sl] =
          held_[sl] ? Eigen::Vector3d(w * lambda_[sl] + (1 - w) * solution.lambda[sl]) : solution.lambda[sl];
    }
  }
  if (bumped) {
    // The bump on this tick's nodes in proportion to their linear lambdas (evenly if those are 0).
    double sum = 0;
    for (int l = 0; l < m; ++l) sum += solution.lambda[static_cast<std::size_t>(l)].norm();
    const bool even = !(sum > 0) || !std::isfinite(sum);
    for (int l = 0; l < m; ++l) {
      const auto sl = static_cast<std::size_t>(l);
      solution.lambda[sl] += (even ? 1.0 / m : solution.lambda[sl].norm() / sum) * bump_;
    }
  }
  if ((local && w > 0) || bumped) {
    Eigen::Vector3d total = Eigen::Vector3d::Zero();
    for (int l = 0; l < m; ++l) total += solution.lambda[static_cast<std::size_t>(l)];
    solution.tool_force = -total;
    if (bumped || w < 1) ++blended_;
  }
  if (!(local && w > 0)) {
    ++ticks_[3];
    return MultirateUse::kLinearFallback;
  }

  // --- statistics: the snapshot's age (sim time since its targets) and the extrapolation ---
  // This tick's index is tick_ (hand_over() follows apply()).
  const std::uint64_t t_snap =
      cycle_tick_[static_cast<std::size_t>(s.cycle % kCycleTicks)].load(std::memory_order_relaxed);
  age_ms_.add(1e3 * dt_ * static_cast<double>(tick_ >= t_snap ? tick_ - t_snap : 0));
  // Staleness: since the snapshot's targets, or since the last tick the contact nodes were where it has them (a held
  // tool's converged snapshot is exact however old; the release after a hold is stale from the release on).
  if (s.cycle != stale_cycle_) {
    stale_cycle_ = s.cycle;
    exact_tick_ = t_snap;
  }
  if (largest <= kMinPrediction) {
    exact_tick_ = tick_;
  } else {
    const std::uint64_t since = std::max(t_snap, exact_tick_);
    stale_ms_.add(1e3 * dt_ * static_cast<double>(tick_ >= since ? tick_ - since : 0));
  }
  extrapolation_mm_.add(1e3 * largest);
  const bool all = matched == m && matched == s.count;
  ++ticks_[all ? 1 : 2];
  return all ? MultirateUse::kNonlinear : MultirateUse::kPartial;
}

}  // namespace surgsim::nonlinear
