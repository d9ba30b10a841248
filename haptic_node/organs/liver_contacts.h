// Tool-organ contacts for the liver (paper sections 4-5, DESIGN.md 4.1-4.2): continuous detection of each tool point
// against the deformed surface (bucket grid), unilateral contacts that slide without friction and release when the
// point leaves the rest surface, grasps (jaw closed) that hold their anchor and can pull, barycentric distribution of
// each contact displacement over its triangle, lambda = G_CC^-1 u* through the precomputed tensors, the quasi
// non-linear force law, the device clamp. step() allocates nothing and never returns a non-finite force.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>

#include "liver/bucket_grid.h"
#include "mesh/mesh.h"
#include "scene/scene.h"
#include "liver/superposition.h"
#include "tool/tool.h"
#include "organ.h"

namespace surgsim {

class NonlinearLaw;

/// One tool point's contact (fixed capacity, plain data).
struct PointContact {
  bool active = false;
  bool grasp = false;
  int triangle = -1;
  std::array<int, 3> nodes{{-1, -1, -1}};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // m, point of the REST surface the tool point drags
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(); // outward unit normal of the rest triangle
};


class LiverContacts {
 public:
  static constexpr double kGraspCloseJaw = 0.05;  // rad: at or below, a touching jaw grasps
  static constexpr double kGraspOpenJaw = 0.15;   // rad: above, a grasp lets go (hysteresis)

  /// Init (allocates). `tensors` must hold the "haptic" block; all references must outlive this object.
  LiverContacts(const TetMesh& mesh, const SurfaceMesh& surface, const Tensors& tensors, const ToolSpec& tool,
                const NonlinearLaw* law = nullptr);

  /// One haptic tick for the tool at `geometry` with jaw opening `jaw` (rad). noexcept, no allocation.
  void step(const ToolGeometry& geometry, double jaw, ContactTick& out) noexcept;
  /// Drops every contact (e.g. input lost) and forgets the previous tool position.
  void reset() noexcept;

  const ContactSolution& solution() const { return solution_; }
  /// The constrained solve's status in the last step() (kOk when it had nothing to solve).
  ContactStatus status() const { return status_; }
  const PointContact& point(int i) const { return points_[static_cast<std::size_t>(i)]; }
  const BucketGrid& grid() const { return grid_; }
  /// Corrected constraint u~_l = G_{k_l k_l} lambda_l of solution node l (m).
  Eigen::Vector3d corrected(int l) const noexcept;
  /// Deformed position of a surface node under the current solution (rest for nodes without a column).
  Eigen::Vector3d deformed(int node) const noexcept;

 private:
  static void deformed_cb(const void* self, int node, Eigen::Vector3d& out);

  const TetMesh& mesh_;
  const Tensors& tensors_;
  const TensorBlock& haptic_;
  ToolSpec tool_;
  const NonlinearLaw* law_;
  BucketGrid grid_;
  Superposition superposition_;
  ContactSolution solution_;
  ContactStatus status_ = ContactStatus::kOk;
  std::array<PointContact, kMaxShaftPoints> points_{};
  std::array<Eigen::Vector3d, kMaxShaftPoints> previous_{};
  bool have_previous_ = false;
  std::array<Contact, 3 * kMaxShaftPoints> requests_{};
};

}  // namespace surgsim
