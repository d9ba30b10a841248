#include "views/composite_view.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <ostream>

#include "core/error.h"
#include "mesher/scene_mesh.h"

namespace surgsim {

CompositeView::CompositeView(std::vector<Part> parts) : parts_(std::move(parts)) {
  if (parts_.empty()) core::throw_error("CompositeView: no organ");
  frames_.resize(parts_.size());
  for (std::size_t k = 0; k < parts_.size(); ++k) order_.push_back(static_cast<int>(k));
  for (msg::ContactFrame& f : frames_) {
    f.contacts().reserve(msg::kMaxContacts);
    f.instruments().reserve(msg::kMaxInstruments);
  }
}

std::uint64_t CompositeView::mesh_hash() const {
  std::vector<std::uint64_t> hashes;
  for (const Part& p : parts_) hashes.push_back(p.view->mesh_hash());
  return mesher::combine_organ_hashes(hashes);
}

std::uint64_t CompositeView::tensor_hash() const {
  std::vector<std::uint64_t> hashes;
  for (const Part& p : parts_) hashes.push_back(p.view->tensor_hash());
  return mesher::combine_organ_hashes(hashes);
}

long CompositeView::surface_triangles() const {
  long n = 0;
  for (const Part& p : parts_) n += p.view->surface_triangles();
  return n;
}

void CompositeView::attach(const Renderer& renderer) {
  for (Part& p : parts_) p.view->attach(renderer);
}

void CompositeView::subscribe(dds::Participant& participant) {
  for (Part& p : parts_) p.view->subscribe(participant);
}

void CompositeView::print_init(std::ostream& out) const {
  for (const Part& p : parts_) {
    out << "visual_node: organ '" << p.name << "': " << p.view->surface_triangles() << " surface triangles\n";
    p.view->print_init(out);
  }
}

double CompositeView::update(const msg::ContactFrame* frame, bool fresh) noexcept {
  double total = -1;
  for (std::size_t k = 0; k < parts_.size(); ++k) {
    const msg::ContactFrame* mine = nullptr;
    if (frame != nullptr) {
      msg::ContactFrame& f = frames_[k];
      if (fresh) {
        // The header and instruments as sent, the entries of organ k only (they keep their organ, k: view k draws
        // organ k, OrganViewOptions::organ_index).
        f.seq(frame->seq());
        f.stamp_ns(frame->stamp_ns());
        f.scene_hash(frame->scene_hash());
        f.sim_time(frame->sim_time());
        f.flags(frame->flags());
        f.instruments().assign(frame->instruments().begin(), frame->instruments().end());
        f.contacts().clear();
        for (const auto& e : frame->contacts()) {
          if (e.organ() != k) continue;
          f.contacts().push_back(e);
        }
      }
      mine = &f;
    }
    const double us = parts_[k].view->update(mine, fresh);
    if (us >= 0) total = std::max(total, 0.0) + us;
  }
  return total;
}

void CompositeView::draw(Renderer& renderer) const {
  for (const int k : order_) parts_[static_cast<std::size_t>(k)].view->draw(renderer);
}

void CompositeView::order_for(const Eigen::Vector3d& eye) {
  std::vector<double> depth(parts_.size());
  for (std::size_t k = 0; k < parts_.size(); ++k) depth[k] = parts_[k].view->draw_depth(eye);
  std::stable_sort(order_.begin(), order_.end(), [&](int a, int b) {
    return depth[static_cast<std::size_t>(a)] < depth[static_cast<std::size_t>(b)];
  });
}

void CompositeView::draw_markers(Renderer& renderer) const {
  for (const Part& p : parts_) p.view->draw_markers(renderer);
}

void CompositeView::frame_done(double work_seconds) noexcept {
  for (Part& p : parts_) p.view->frame_done(work_seconds);
}

std::uint32_t CompositeView::lod() const {
  std::uint32_t lod = 0;
  for (const Part& p : parts_) lod = std::max(lod, p.view->lod());
  return lod;
}

int CompositeView::contacts_shown() const {
  int n = 0;
  for (const Part& p : parts_) n += p.view->contacts_shown();
  return n;
}

double CompositeView::max_displacement() const {
  double d = 0;
  for (const Part& p : parts_) d = std::max(d, p.view->max_displacement());
  return d;
}

bool CompositeView::write_vtk(const std::string& path) const {
  // One file per organ that has a surface: <path without .vtk>-<organ>.vtk.
  const std::string stem = path.size() > 4 && path.compare(path.size() - 4, 4, ".vtk") == 0
                               ? path.substr(0, path.size() - 4)
                               : path;
  bool any = false;
  for (const Part& p : parts_) any = p.view->write_vtk(stem + "-" + p.name + ".vtk") || any;
  return any;
}

std::uint64_t CompositeView::deform_errors() const {
  std::uint64_t n = 0;
  for (const Part& p : parts_) n += p.view->deform_errors();
  return n;
}

void CompositeView::add_stats(nlohmann::json& stats) const {
  nlohmann::json organs = nlohmann::json::array();
  for (const Part& p : parts_) {
    nlohmann::json j;
    j["name"] = p.name;
    p.view->add_stats(j);
    j["model"] = j.value("model_built", std::string());
    j.erase("model_built");
    organs.push_back(std::move(j));
  }
  stats["model_built"] = "organs";
  stats["organs"] = std::move(organs);
}

void CompositeView::print_summary(std::ostream& out, const nlohmann::json& stats) const {
  const nlohmann::json* organs = stats.contains("organs") ? &stats["organs"] : nullptr;
  for (std::size_t k = 0; k < parts_.size(); ++k) {
    if (organs != nullptr && k < organs->size()) parts_[k].view->print_summary(out, (*organs)[k]);
  }
}

}  // namespace surgsim
