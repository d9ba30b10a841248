#include "organs/intestine_organ.h"

#include <ostream>
#include <string>

#include <algorithm>
#include <cmath>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "haptic_dds.h"
#include "publisher.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::contact;
using namespace surgsim::scene;

namespace surgsim {

IntestineOrgan::IntestineOrgan(const Scene& scene, std::uint64_t ticks)
    : model_(scene.intestine.params),
      state_(model_),
      probe_radius_(scene.intestine.probe_radius),
      instruments_(static_cast<int>(std::clamp<std::size_t>(scene.tools.size(), 1, intestine::kMaxProbes))),
      step_us_(static_cast<std::size_t>(ticks) + 16) {
  static_assert(intestine::kMaxProbes == kMaxInstruments, "one intestine probe per instrument");
  if (model_.node_count() > static_cast<int>(msg::kMaxBodyPoints)) {
    throw_error(scene.file, ": the intestine has ", model_.node_count(), " masses, a BodyState carries at most ",
                msg::kMaxBodyPoints);
  }
  for (int i = 0; i < intestine::kMaxProbes; ++i) {
    const auto si = static_cast<std::size_t>(i);
    force_limits_[si] = si < scene.tools.size() ? scene.tools[si].force_limit : model_.params().probe_force_limit;
    if (si < scene.tools.size()) names_.push_back(scene.tools[si].name);
  }
}

void IntestineOrgan::create_writers(dds::Participant& participant, std::uint64_t scene_hash) {
  writer_ = participant.writer(participant.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()),
                               dds::kStreamWriter);
  sample_.organ(static_cast<std::uint32_t>(organ_index_));  // the key: this organ's instance
  sample_.scene_hash(scene_hash);
  // The only allocations of the sample: write() changes values only.
  sample_.positions().resize(static_cast<std::size_t>(state_.point_count()));
  sample_.instruments().resize(static_cast<std::size_t>(instruments_));
}

void IntestineOrgan::add_obstacle(const intestine::Obstacle* obstacle, const std::string& name) {
  if (obstacle == nullptr) throw_error("intestine: obstacle '", name, "' is null");
  if (obstacle_count() >= intestine::kMaxObstacles) {
    throw_error("intestine: more than ", intestine::kMaxObstacles, " organs for the bowel to rest on ('", name,
                "' is one too many): a field has at most that many rigid organs");
  }
  obstacles_[static_cast<std::size_t>(obstacle_count())] = obstacle;
  obstacle_names_.push_back(name);
}

void IntestineOrgan::step(const InstrumentInput* inputs, int count, double dt, ContactTick* out) noexcept {
  // --- one probe per instrument at its tool tip; none for an instrument whose input is lost ---
  const int n = std::clamp(count, 0, intestine::kMaxProbes);
  for (int i = 0; i < n; ++i) {
    const auto si = static_cast<std::size_t>(i);
    intestine::Probe& probe = probes_[si];
    const ToolGeometry* tool = inputs != nullptr ? inputs[i].tool : nullptr;
    probe = intestine::Probe{};
    probe.force_limit = force_limits_[si];
    probe.radius = probe_radius_;
    if (tool != nullptr) {
      probe.active = true;
      probe.center = tool->tip;
    }
  }
  // --- the model: mass-spring (every probe included), stochastic detection, response ---
  const std::uint64_t t0 = monotonic_ns();
  intestine::step(model_, state_, probes_.data(), n, dt, report_, obstacles_.data(), obstacle_count());
  step_us_.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
  ++steps_;

  // --- each instrument's force: the step clamps it to the instrument's limit and zeroes it when it was refused ---
  const intestine::StepReport& r = report_;
  const bool ok = r.status == intestine::StepStatus::kOk;
  int touched = 0;
  bool overflow = false, saturated = false;
  for (int i = 0; i < count && out != nullptr; ++i) {
    ContactTick& o = out[i];
    o = ContactTick{};
    if (i >= n) continue;  // beyond kMaxProbes: no probe, no force
    const intestine::ProbeReport& pr = r.probes[static_cast<std::size_t>(i)];
    o.device_force = pr.force.allFinite() ? pr.force : Eigen::Vector3d::Zero();
    const double clamped = o.device_force.norm();
    o.force = pr.saturated && clamped > 0 && std::isfinite(pr.force_raw)
                  ? Eigen::Vector3d(o.device_force * (pr.force_raw / clamped))
                  : o.device_force;
    o.saturated = pr.saturated;
    o.over_capacity = pr.overflow > 0 || r.contacts_overflow > 0;
    o.nonfinite = !ok || pr.rejected;
    o.points_in_contact = pr.contacts;

    ProbeStats& ps = probe_stats_[static_cast<std::size_t>(i)];
    ps.contacts_max = std::max(ps.contacts_max, pr.contacts);
    if (pr.contacts > 0) ++ps.contact_ticks;
    if (pr.overflow > 0) ++ps.overflow_ticks;
    if (pr.saturated) ++ps.saturated_ticks;
    ps.force_max_n = std::max(ps.force_max_n, clamped);
    touched += pr.contacts;
    overflow = overflow || pr.overflow > 0;
    saturated = saturated || pr.saturated;
  }

  // --- statistics (fixed storage) ---
  const auto status = static_cast<std::size_t>(r.status);
  if (status < 4) ++status_counts_[status];
  if (!ok) ++faults_;
  self_contacts_max_ = std::max(self_contacts_max_, r.contacts);
  self_contacts_sum_ += r.contacts;
  probe_contacts_max_ = std::max(probe_contacts_max_, touched);
  if (touched > 0) ++probe_contact_ticks_;
  if (overflow) ++probe_overflow_ticks_;
  if (r.contacts_overflow > 0) ++contacts_overflow_ticks_;
  if (saturated) ++saturated_ticks_;
  penetration_after_max_ = std::max(penetration_after_max_, r.response.max_penetration_after);
  active_pairs_max_ = std::max(active_pairs_max_, r.detection.segment_pairs + r.detection.cell_pairs);
  for (int k = 0; k < r.obstacle_count; ++k) {
    const intestine::ObstacleReport& o = r.obstacles[static_cast<std::size_t>(k)];
    ObstacleStats& os = obstacle_stats_[static_cast<std::size_t>(k)];
    os.contacts_max = std::max(os.contacts_max, o.contacts);
    if (o.contacts > 0) ++os.contact_ticks;
    os.max_depth_m = std::max(os.max_depth_m, o.max_depth);
    if (o.force.allFinite()) os.force_max_n = std::max(os.force_max_n, o.force.norm());
  }
  if (r.obstacle_overflow > 0) ++obstacle_overflow_ticks_;
}

int IntestineOrgan::contacts() const noexcept {
  int sum = 0;
  for (int i = 0; i < report_.probe_count; ++i) sum += report_.probes[static_cast<std::size_t>(i)].contacts;
  return sum;
}

int IntestineOrgan::instrument_contacts(int i) const noexcept {
  return i >= 0 && i < report_.probe_count ? report_.probes[static_cast<std::size_t>(i)].contacts : 0;
}

void IntestineOrgan::fill_outputs(OrganOutputs& out) const noexcept {
  out.contact_count = 0;
  const int n = std::min(state_.point_count(), out.point_capacity);
  if (out.points == nullptr || n <= 0) {
    out.point_count = 0;
    return;
  }
  std::copy(state_.positions(), state_.positions() + 3 * static_cast<std::size_t>(n), out.points);
  out.point_count = n;
}

void IntestineOrgan::write(const TickRecord& r, std::uint64_t stamp_ns) noexcept {
  if (writer_ == nullptr) return;
  sample_.seq(r.seq);
  sample_.sim_time(r.sim_time);
  // Sized at create_writers(): only the values change.
  fill_instruments(r, sample_.instruments());
  auto& out = sample_.positions();
  const std::size_t n = std::min(out.size(), static_cast<std::size_t>(std::max(r.organ.point_count, 0)));
  const double* x = r.organ.points;
  for (std::size_t i = 0; i < n; ++i) {
    out[i].x(x[3 * i]);
    out[i].y(x[3 * i + 1]);
    out[i].z(x[3 * i + 2]);
  }
  sample_.stamp_ns(stamp_ns);
  writer_->write(&sample_);
  published_.fetch_add(1, std::memory_order_relaxed);
}

nlohmann::json IntestineOrgan::stats() const {
  nlohmann::json j;
  j["nodes"] = model_.node_count();
  j["columns"] = model_.columns();
  j["rows"] = model_.rows();
  j["steps"] = steps_;
  j["step_us"] = to_json(step_us_.summary());
  j["faults"] = faults_;
  j["faults_bad_input"] = status_counts_[static_cast<int>(intestine::StepStatus::kBadInput)];
  j["faults_nonfinite"] = status_counts_[static_cast<int>(intestine::StepStatus::kNonFinite)];
  j["faults_solver"] = status_counts_[static_cast<int>(intestine::StepStatus::kSolverFailed)];
  j["self_contacts_max"] = self_contacts_max_;
  j["self_contacts_mean"] = steps_ > 0 ? self_contacts_sum_ / static_cast<double>(steps_) : 0.0;
  j["contacts_overflow_ticks"] = contacts_overflow_ticks_;
  j["active_pairs_max"] = active_pairs_max_;
  j["penetration_after_max_m"] = penetration_after_max_;
  j["probe_contacts_max"] = probe_contacts_max_;
  j["probe_contact_ticks"] = probe_contact_ticks_;
  j["probe_overflow_ticks"] = probe_overflow_ticks_;
  j["saturated_ticks"] = saturated_ticks_;
  nlohmann::json probes = nlohmann::json::array();
  for (int i = 0; i < instruments_; ++i) {
    const ProbeStats& ps = probe_stats_[static_cast<std::size_t>(i)];
    probes.push_back({{"instrument", i},
                      {"name", i < static_cast<int>(names_.size()) ? names_[static_cast<std::size_t>(i)] : ""},
                      {"contacts_max", ps.contacts_max},
                      {"contact_ticks", ps.contact_ticks},
                      {"overflow_ticks", ps.overflow_ticks},
                      {"saturated_ticks", ps.saturated_ticks},
                      {"force_max_n", ps.force_max_n}});
  }
  j["probes"] = probes;
  nlohmann::json obstacles = nlohmann::json::array();
  for (int k = 0; k < obstacle_count(); ++k) {
    const ObstacleStats& os = obstacle_stats_[static_cast<std::size_t>(k)];
    obstacles.push_back({{"organ", obstacle_names_[static_cast<std::size_t>(k)]},
                         {"contacts_max", os.contacts_max},
                         {"contact_ticks", os.contact_ticks},
                         {"max_penetration_mm", os.max_depth_m * 1e3},
                         {"force_max_n", os.force_max_n}});
  }
  j["obstacles"] = obstacles;
  j["obstacle_overflow_ticks"] = obstacle_overflow_ticks_;
  j["body_states_published"] = published_.load(std::memory_order_relaxed);
  j["energy_j"] = intestine::energy(model_, state_);
  j["positions_finite"] = state_.x.allFinite();
  return j;
}

std::string IntestineOrgan::describe() const {
  return std::to_string(model_.rows()) + " x " + std::to_string(model_.columns()) +
         " masses (intestine and mesentery, mass-spring); ";
}

void IntestineOrgan::add_stats(nlohmann::json& j) const { j["intestine"] = stats(); }

void IntestineOrgan::print_summary(std::ostream& out) const {
  const nlohmann::json in = stats();
  out << "haptic_node: intestine step p50 " << in["step_us"]["p50"].get<double>() << " us p99 "
      << in["step_us"]["p99"].get<double>() << " us, " << in["faults"].get<std::uint64_t>() << " faults, "
      << "self-contacts max " << in["self_contacts_max"].get<int>() << ", probe contacts max "
      << in["probe_contacts_max"].get<int>() << ", " << in["body_states_published"].get<std::uint64_t>()
      << " body states published\n";
}

}  // namespace surgsim
