// Several organs in the visual node (a scene with an `organs:` list): one view per organ (views/liver_view.h,
// views/intestine_view.h, views/rigid_view.h), updated and drawn together in one picture. Each view sees the contact
// frames as a one-organ scene would: a copy of the frame holding only its own organ's contact entries (ContactEntry
// organ = its index in the scene, which each view is built with: OrganViewOptions::organ_index, also the BodyState
// key it reads), made into storage sized at init, so a frame allocates nothing.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "organ_view.h"
#include "surgsim_types.h"

namespace surgsim {

class CompositeView final : public OrganView {
 public:
  struct Part {
    std::string name;
    std::unique_ptr<OrganView> view;
  };
  explicit CompositeView(std::vector<Part> parts);

  /// The same combination of the organs' hashes as the haptic node's CompositeOrgan.
  std::uint64_t mesh_hash() const override;
  std::uint64_t tensor_hash() const override;
  long surface_triangles() const override;
  void attach(const Renderer& renderer) override;
  void subscribe(dds::Participant& participant) override;
  void print_init(std::ostream& out) const override;
  double update(const msg::ContactFrame* frame, bool fresh) noexcept override;
  /// Every organ, in the order order_for() set (the scene's until then).
  void draw(Renderer& renderer) const override;
  /// Init: the organs drawn by their draw_depth from `eye` (the camera's), smallest first; the scene's order for ties.
  void order_for(const Eigen::Vector3d& eye);
  const std::vector<int>& draw_order() const { return order_; }
  /// The instruments of the organ views that carry their own (the intestine's BodyState), else null.
  const InstrumentPoses* instruments() const override { return nullptr; }
  void draw_markers(Renderer& renderer) const override;
  void frame_done(double work_seconds) noexcept override;
  std::uint32_t lod() const override;
  int contacts_shown() const override;
  double max_displacement() const override;
  bool write_vtk(const std::string& path) const override;
  std::uint64_t deform_errors() const override;
  /// "model_built": "organs" and "organs": [{name, ...each view's own keys}].
  void add_stats(nlohmann::json& stats) const override;
  void print_summary(std::ostream& out, const nlohmann::json& stats) const override;

  int organ_count() const { return static_cast<int>(parts_.size()); }
  const OrganView& organ(int k) const { return *parts_[static_cast<std::size_t>(k)].view; }
  OrganView& organ(int k) { return *parts_[static_cast<std::size_t>(k)].view; }
  const std::string& organ_name(int k) const { return parts_[static_cast<std::size_t>(k)].name; }

 private:
  std::vector<Part> parts_;
  std::vector<msg::ContactFrame> frames_;  // per organ: the last frame with that organ's entries only
  std::vector<int> order_;                 // the organs in the order drawn
};

}  // namespace surgsim
