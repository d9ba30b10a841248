#include "organs/composite_organ.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>
#include <ostream>
#include <sstream>

#include "core/error.h"
#include "mesher/scene_mesh.h"
#include "organs/intestine_organ.h"
#include "organs/liver_organ.h"
#include "organs/rigid_organ.h"
#include "scene/scene.h"

namespace surgsim {

CompositeOrgan::CompositeOrgan(std::vector<Part> parts) : parts_(std::move(parts)) {
  if (parts_.empty() || parts_.size() > static_cast<std::size_t>(scene::kMaxOrgans)) {
    core::throw_error("CompositeOrgan: ", parts_.size(), " organs (1..", scene::kMaxOrgans, ")");
  }
  // Each part learns its index in the scene's organs list (its own topics carry it: BodyState.organ).
  for (std::size_t k = 0; k < parts_.size(); ++k) parts_[k].organ->set_organ_index(static_cast<int>(k));
  // Organs that touch: every bowel rests on every rigid organ and every liver of the field. On a liver (the first
  // bowel; a linear or corotational liver with the patch contact model) both ways: the bowel's points are rows of the
  // liver's own solve (LiverObstacle), which the liver's step gathers from the bowel's positions as they are then (this
  // tick's entry for a liver listed before the bowel, the positions after the bowel's step otherwise: either way the
  // bowel's next step starts from the positions the liver solved).
  for (Part& body : parts_) {
    auto* bowel = dynamic_cast<IntestineOrgan*>(body.organ.get());
    if (bowel == nullptr) continue;
    for (const Part& other : parts_) {
      if (const auto* rigid = dynamic_cast<const RigidOrgan*>(other.organ.get())) {
        bowel->add_obstacle(&rigid->obstacle(), other.name);
      } else if (auto* liver = dynamic_cast<LiverOrgan*>(other.organ.get())) {
        LiverObstacle& on_liver = liver->obstacle("organ '" + other.name + "'");
        // The first bowel on a liver is solved with it (two-way); a second one rests on its surface (one-way).
        if (!on_liver.coupled()) on_liver.couple(bowel->model(), bowel->state(), "organ '" + body.name + "'");
        bowel->add_obstacle(&on_liver, other.name);
      }
    }
  }
  // Every liver against every rigid organ (the wall, the ribs): the liver's surface nodes are pushed out of them in
  // its own solve.
  for (Part& organ : parts_) {
    auto* liver = dynamic_cast<LiverOrgan*>(organ.organ.get());
    if (liver == nullptr) continue;
    for (const Part& other : parts_)
      if (const auto* rigid = dynamic_cast<const RigidOrgan*>(other.organ.get()))
        liver->add_wall(rigid->surface(), rigid->stiffness(), other.name);
  }
  ticks_.resize(parts_.size());
  point_offsets_.assign(1, 0);
  for (const Part& p : parts_) point_offsets_.push_back(point_offsets_.back() + p.organ->output_points());
}

void CompositeOrgan::step(const contact::InstrumentInput* inputs, int count, double dt,
                          contact::ContactTick* out) noexcept {
  count = std::clamp(count, 0, tool::kMaxInstruments);
  for (std::size_t k = 0; k < parts_.size(); ++k) {
    for (int i = 0; i < count; ++i) ticks_[k][static_cast<std::size_t>(i)] = contact::ContactTick{};
    parts_[k].organ->step(inputs, count, dt, ticks_[k].data());
  }
  for (int i = 0; i < count; ++i) {
    contact::ContactTick sum;
    double largest = -1;
    for (std::size_t k = 0; k < parts_.size(); ++k) {
      const contact::ContactTick& t = ticks_[k][static_cast<std::size_t>(i)];
      // Each organ's force before its own clamp, when finite (an organ that refused a value gives zero).
      const Eigen::Vector3d f = t.force.allFinite() ? t.force : Eigen::Vector3d::Zero();
      sum.force += f;
      sum.over_capacity = sum.over_capacity || t.over_capacity;
      sum.nonfinite = sum.nonfinite || t.nonfinite || !t.force.allFinite();
      sum.grasp = sum.grasp || t.grasp;
      sum.points_in_contact += t.points_in_contact;
      const double n = f.norm();
      if (n > largest) {
        largest = n;
        sum.direction = t.direction;
      }
    }
    if (!sum.force.allFinite()) {
      sum.force.setZero();
      sum.nonfinite = true;
    }
    sum.device_force = sum.force;  // clamped once, by the force stage
    out[i] = sum;
  }
}

int CompositeOrgan::contacts() const noexcept {
  int n = 0;
  for (const Part& p : parts_) n += p.organ->contacts();
  return n;
}

int CompositeOrgan::instrument_contacts(int i) const noexcept {
  int n = 0;
  for (const Part& p : parts_) n += p.organ->instrument_contacts(i);
  return n;
}

int CompositeOrgan::contact_entries() const noexcept {
  int n = 0;
  for (const Part& p : parts_) n += std::max(p.organ->contact_entries(), 0);
  return std::min(n, kMaxContactEntries);
}

ContactEntry CompositeOrgan::contact_entry(int l) const noexcept {
  for (std::size_t k = 0; k < parts_.size(); ++k) {
    const int n = std::max(parts_[k].organ->contact_entries(), 0);
    if (l < n) {
      ContactEntry e = parts_[k].organ->contact_entry(l);
      e.organ = static_cast<int>(k);
      return e;
    }
    l -= n;
  }
  return {};
}

std::uint64_t CompositeOrgan::mesh_hash() const {
  std::vector<std::uint64_t> hashes;
  for (const Part& p : parts_) hashes.push_back(p.organ->mesh_hash());
  return mesher::combine_organ_hashes(hashes);
}

std::uint64_t CompositeOrgan::tensor_hash() const {
  std::vector<std::uint64_t> hashes;
  for (const Part& p : parts_) hashes.push_back(p.organ->tensor_hash());
  return mesher::combine_organ_hashes(hashes);
}

std::uint32_t CompositeOrgan::node_count() const {
  std::uint32_t n = 0;
  for (const Part& p : parts_) n += p.organ->node_count();
  return n;
}

std::uint32_t CompositeOrgan::surface_node_count() const {
  std::uint32_t n = 0;
  for (const Part& p : parts_) n += p.organ->surface_node_count();
  return n;
}

bool CompositeOrgan::nonlinear_law() const {
  return std::any_of(parts_.begin(), parts_.end(), [](const Part& p) { return p.organ->nonlinear_law(); });
}

std::vector<OrganIdentity> CompositeOrgan::identities() const {
  std::vector<OrganIdentity> out;
  for (const Part& p : parts_) {
    for (OrganIdentity id : p.organ->identities()) {
      id.name = p.name;
      out.push_back(std::move(id));
    }
  }
  return out;
}

void CompositeOrgan::fill_outputs(OrganOutputs& out) const noexcept {
  // Contact entries of every organ, tagged with the organ's index.
  const int n = contact_entries();
  out.contact_count = n;
  for (int l = 0; l < n; ++l) out.contacts[static_cast<std::size_t>(l)] = contact_entry(l);
  // Points: each organ fills its own share of the storage.
  int filled = 0;
  for (std::size_t k = 0; k < parts_.size(); ++k) {
    if (point_offsets_[k + 1] == point_offsets_[k]) continue;
    OrganOutputs share;
    share.point_capacity = std::max(0, std::min(out.point_capacity, point_offsets_[k + 1]) - point_offsets_[k]);
    share.points = out.points != nullptr ? out.points + 3 * static_cast<std::size_t>(point_offsets_[k]) : nullptr;
    if (share.point_capacity > 0 && share.points != nullptr) {
      // fill_outputs also writes the share's contact entries: a copy of OrganOutputs's array on the stack is a
      // few KB; acceptable on the loop thread (no allocation), and only for organs with points.
      parts_[k].organ->fill_outputs(share);
      filled = point_offsets_[k] + share.point_count;
    }
  }
  out.point_count = filled;
}

void CompositeOrgan::create_writers(dds::Participant& participant, std::uint64_t scene_hash) {
  for (Part& p : parts_) p.organ->create_writers(participant, scene_hash);
}

void CompositeOrgan::write(const TickRecord& record, std::uint64_t stamp_ns) noexcept {
  for (std::size_t k = 0; k < parts_.size(); ++k) {
    // The record as organ k filled it: the header and instruments, its points, its own contact entries.
    std::memcpy(static_cast<void*>(&scratch_), &record, offsetof(TickRecord, organ) + offsetof(OrganOutputs, contacts));
    const int begin = point_offsets_[k];
    scratch_.organ.points = record.organ.points != nullptr ? record.organ.points + 3 * static_cast<std::size_t>(begin)
                                                           : nullptr;
    scratch_.organ.point_capacity = point_offsets_[k + 1] - begin;
    scratch_.organ.point_count = std::clamp(record.organ.point_count - begin, 0, scratch_.organ.point_capacity);
    int c = 0;
    for (int l = 0; l < std::clamp(record.organ.contact_count, 0, kMaxContactEntries); ++l) {
      const ContactRecord& e = record.organ.contacts[static_cast<std::size_t>(l)];
      if (e.organ == static_cast<int>(k)) scratch_.organ.contacts[static_cast<std::size_t>(c++)] = e;
    }
    scratch_.organ.contact_count = c;
    parts_[k].organ->write(scratch_, stamp_ns);
  }
}

void CompositeOrgan::time_stages(bool on) {
  for (Part& p : parts_) p.organ->time_stages(on);
}

std::string CompositeOrgan::describe() const {
  std::ostringstream os;
  os << parts_.size() << " organs: ";
  for (const Part& p : parts_) os << p.name << " (" << p.organ->model_name() << ", " << p.organ->describe() << ") ";
  return os.str();
}

void CompositeOrgan::add_stats(nlohmann::json& stats) const {
  nlohmann::json organs = nlohmann::json::array();
  for (const Part& p : parts_) {
    nlohmann::json j;
    j["name"] = p.name;
    j["model"] = p.organ->model_name();
    j["node_count"] = p.organ->node_count();
    j["surface_node_count"] = p.organ->surface_node_count();
    j["mesh_hash"] = std::to_string(p.organ->mesh_hash());
    j["tensor_hash"] = std::to_string(p.organ->tensor_hash());
    p.organ->add_stats(j);
    organs.push_back(std::move(j));
  }
  stats["organs"] = std::move(organs);
}

void CompositeOrgan::print_summary(std::ostream& out) const {
  for (const Part& p : parts_) p.organ->print_summary(out);
}

}  // namespace surgsim
