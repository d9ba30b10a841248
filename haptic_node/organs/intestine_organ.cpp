#include "organs/intestine_organ.h"

#include <ostream>
#include <string>

#include <algorithm>
#include <cmath>

#include "surgsim_types.h"
#include "core/clock.h"
#include "core/error.h"
#include "publisher.h"

namespace surgsim {

IntestineOrgan::IntestineOrgan(const Scene& scene, std::uint64_t ticks)
    : model_(scene.intestine.params),
      state_(model_),
      probe_radius_(scene.intestine.probe_radius),
      step_us_(static_cast<std::size_t>(ticks) + 16) {
  if (model_.node_count() > static_cast<int>(msg::kMaxBodyPoints)) {
    throw_error(scene.file, ": the intestine has ", model_.node_count(), " masses, a BodyState carries at most ",
                msg::kMaxBodyPoints);
  }
}

void IntestineOrgan::create_writers(dds::Participant& participant, std::uint64_t scene_hash) {
  writer_ = participant.writer(participant.topic(dds::kBodyStateTopic, new msg::BodyStatePubSubType()),
                               dds::kStreamWriter);
  sample_.scene_hash(scene_hash);
  sample_.positions().resize(static_cast<std::size_t>(state_.point_count()));  // the only allocation of the sample
}

void IntestineOrgan::step(const ToolGeometry* tool, double /*jaw*/, double dt, ContactTick& out) noexcept {
  intestine::Probe probe;
  if (tool != nullptr) {
    probe.active = true;
    probe.center = tool->tip;
    probe.radius = probe_radius_;
  }
  // --- the model: mass-spring (probe included), stochastic detection, response ---
  const std::uint64_t t0 = monotonic_ns();
  intestine::step(model_, state_, probe, dt, report_);
  step_us_.add(static_cast<double>(monotonic_ns() - t0) * 1e-3);
  ++steps_;

  // --- the force on the tool: the step clamps it to tool.force_limit and zeroes it when the step was refused ---
  const intestine::StepReport& r = report_;
  const bool ok = r.status == intestine::StepStatus::kOk;
  out = ContactTick{};
  out.device_force = r.probe_force.allFinite() ? r.probe_force : Eigen::Vector3d::Zero();
  const double clamped = out.device_force.norm();
  out.force = r.probe_saturated && clamped > 0 && std::isfinite(r.probe_force_raw)
                  ? Eigen::Vector3d(out.device_force * (r.probe_force_raw / clamped))
                  : out.device_force;
  out.saturated = r.probe_saturated;
  out.over_capacity = r.probe_overflow > 0 || r.contacts_overflow > 0;
  out.nonfinite = !ok || r.probe_rejected;
  out.points_in_contact = r.probe_contacts;

  // --- statistics (fixed storage) ---
  const auto status = static_cast<std::size_t>(r.status);
  if (status < 4) ++status_counts_[status];
  if (!ok) ++faults_;
  self_contacts_max_ = std::max(self_contacts_max_, r.contacts);
  self_contacts_sum_ += r.contacts;
  probe_contacts_max_ = std::max(probe_contacts_max_, r.probe_contacts);
  if (r.probe_contacts > 0) ++probe_contact_ticks_;
  if (r.probe_overflow > 0) ++probe_overflow_ticks_;
  if (r.contacts_overflow > 0) ++contacts_overflow_ticks_;
  if (r.probe_saturated) ++saturated_ticks_;
  penetration_after_max_ = std::max(penetration_after_max_, r.response.max_penetration_after);
  active_pairs_max_ = std::max(active_pairs_max_, r.detection.segment_pairs + r.detection.cell_pairs);
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
  auto& pose = sample_.pose();
  pose.pitch(r.pose.pitch);
  pose.yaw(r.pose.yaw);
  pose.insertion(r.pose.insertion);
  pose.roll(r.pose.roll);
  pose.jaw(r.pose.jaw);
  sample_.tip().x(r.tip.x());
  sample_.tip().y(r.tip.y());
  sample_.tip().z(r.tip.z());
  // Sized at create_writers(): only the values change.
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
