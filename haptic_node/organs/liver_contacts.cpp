#include "organs/liver_contacts.h"

#include <Eigen/Geometry>
#include <cmath>

#include "core/error.h"
#include "liver/nonlinear_law.h"

namespace surgsim {

namespace {
const TensorBlock& haptic_block(const Tensors& t) {
  const TensorBlock* b = t.find("haptic");
  if (b == nullptr) throw_error("tensors without a 'haptic' block: rebuild the tensor cache");
  return *b;
}
}  // namespace

LiverContacts::LiverContacts(const TetMesh& mesh, const SurfaceMesh& surface, const Tensors& tensors,
                             const ToolSpec& tool, const NonlinearLaw* law)
    : mesh_(mesh),
      tensors_(tensors),
      haptic_(haptic_block(tensors)),
      tool_(tool),
      law_(law),
      grid_(mesh, surface),
      superposition_(tensors, "haptic", tool.contact_capacity) {}

void LiverContacts::reset() noexcept {
  for (auto& p : points_) p = PointContact{};
  have_previous_ = false;
  solution_ = ContactSolution{};
}

Eigen::Vector3d LiverContacts::deformed(int node) const noexcept {
  Eigen::Vector3d x = mesh_.nodes.row(node).transpose();
  Eigen::Vector3d u;
  if (solution_.count > 0 && superposition_.displacement(node, solution_, u)) x += u;
  return x;
}

void LiverContacts::deformed_cb(const void* self, int node, Eigen::Vector3d& out) {
  out = static_cast<const LiverContacts*>(self)->deformed(node);
}

Eigen::Vector3d LiverContacts::corrected(int l) const noexcept {
  const int node = solution_.nodes[static_cast<std::size_t>(l)];
  const int r = haptic_.row_of_node[static_cast<std::size_t>(node)];
  const int c = tensors_.column_of_node[static_cast<std::size_t>(node)];
  if (r < 0 || c < 0) return Eigen::Vector3d::Zero();
  return haptic_.block3(r, c) * solution_.lambda[static_cast<std::size_t>(l)];
}

void LiverContacts::step(const ToolGeometry& geometry, double jaw, ContactTick& out) noexcept {
  out = ContactTick{};
  status_ = ContactStatus::kOk;
  const int n_points = geometry.point_count;

  // A non-finite tool pose never reaches the physics: drop contacts, zero force, report.
  bool finite = std::isfinite(jaw);
  for (int i = 0; i < n_points; ++i) finite = finite && geometry.points[static_cast<std::size_t>(i)].allFinite();
  if (!finite) {
    reset();
    out.nonfinite = true;
    return;
  }

  // --- detection and contact update, per tool point (tip first) ---
  for (int i = 0; i < n_points; ++i) {
    const auto si = static_cast<std::size_t>(i);
    const Eigen::Vector3d& p = geometry.points[si];
    const Eigen::Vector3d& p_prev = have_previous_ ? previous_[si] : p;
    PointContact& c = points_[si];

    // New contact: the path since the last tick crosses the DEFORMED surface (continuous, so no tunnelling).
    if (!c.active) {
      const SurfaceHit hit = grid_.segment_query(p_prev, p, &LiverContacts::deformed_cb, this);
      if (hit.hit) {
        c.active = true;
        c.grasp = false;
        c.triangle = hit.triangle;
        c.nodes = hit.nodes;
        c.bary = hit.bary;
        c.anchor = Eigen::Vector3d::Zero();
        for (int v = 0; v < 3; ++v) c.anchor += hit.bary[v] * mesh_.nodes.row(hit.nodes[v]).transpose();
        const Eigen::Vector3d a = mesh_.nodes.row(hit.nodes[0]).transpose();
        const Eigen::Vector3d b = mesh_.nodes.row(hit.nodes[1]).transpose();
        const Eigen::Vector3d d = mesh_.nodes.row(hit.nodes[2]).transpose();
        c.normal = (b - a).cross(d - a).normalized();
      }
    }
    if (!c.active) continue;

    if (c.grasp) {
      // A grasp keeps its anchor (bilateral) until the jaw opens again.
      if (jaw > kGraspOpenJaw) c.grasp = false;
    }
    if (!c.grasp) {
      // Unilateral, frictionless: the anchor follows the closest point of the rest surface on the side the contact
      // pressed (a tip pushed deeper than half the organ must not re-anchor on the opposite face and let go).
      const SurfaceProjection proj = grid_.project_rest(p, 3, &c.normal);
      if (proj.found) {
        c.triangle = proj.triangle;
        c.nodes = proj.nodes;
        c.bary = proj.bary;
        c.anchor = proj.point;
        c.normal = proj.normal;
      }
      // Released when the point is back outside the rest surface.
      if ((p - c.anchor).dot(c.normal) >= 0) {
        c.active = false;
        continue;
      }
      // The tip's jaws closing on the tissue turn the contact into a grasp.
      if (i == 0 && jaw <= kGraspCloseJaw) c.grasp = true;
    }
  }
  previous_ = geometry.points;
  have_previous_ = true;

  // --- constraints: each contact's displacement spread over its triangle, alpha_v = k_v / sum k^2 ---
  int m = 0;
  Eigen::Vector3d dir_sum = Eigen::Vector3d::Zero();
  const int capacity = superposition_.capacity();
  for (int i = 0; i < n_points; ++i) {
    const PointContact& c = points_[static_cast<std::size_t>(i)];
    if (!c.active) continue;
    const Eigen::Vector3d d = geometry.points[static_cast<std::size_t>(i)] - c.anchor;
    // Two points dragging the same triangle would have their displacements averaged by the merge of duplicate
    // nodes. This happens when a fast stab carries the tip and the shaft points behind it through the surface in one
    // tick; a slow stab never activates the trailing points (they stay inside the tip's dent). The deepest point
    // holds the triangle (ties: the first), so the force does not depend on the speed of the tool.
    bool shadowed = false;
    for (int j = 0; j < n_points && !shadowed; ++j) {
      const PointContact& o = points_[static_cast<std::size_t>(j)];
      if (j == i || !o.active || o.triangle != c.triangle) continue;
      const double depth_i = -d.dot(c.normal);
      const double depth_j = -(geometry.points[static_cast<std::size_t>(j)] - o.anchor).dot(o.normal);
      shadowed = depth_j > depth_i || (depth_j == depth_i && j < i);
    }
    if (shadowed) continue;
    const Eigen::Vector3d alpha = barycentric_weights(c.bary);
    int added = 0;
    for (int v = 0; v < 3; ++v) {
      const int node = c.nodes[static_cast<std::size_t>(v)];
      if (tensors_.column_of_node[static_cast<std::size_t>(node)] < 0) continue;  // fixed node: not constrained
      if (m == capacity) {
        out.over_capacity = true;
        break;
      }
      requests_[static_cast<std::size_t>(m++)] = Contact{node, alpha[v] * d};
      ++added;
    }
    if (added > 0) {
      ++out.points_in_contact;
      dir_sum += d;
      out.grasp = out.grasp || c.grasp;
    }
  }

  // --- lambda = G_CC^-1 u*, force on the tool = -sum lambda ---
  if (m == 0) {
    solution_ = ContactSolution{};
    return;
  }
  status_ = superposition_.solve(requests_.data(), m, solution_);
  const ContactStatus status = status_;
  if (status != ContactStatus::kOk) {
    if (status == ContactStatus::kOverCapacity) out.over_capacity = true;
    if (status == ContactStatus::kNonFinite) out.nonfinite = true;
    solution_ = ContactSolution{};
    return;
  }
  Eigen::Vector3d force = solution_.tool_force;
  const double dn = dir_sum.norm();
  out.direction = dn > 0 ? Eigen::Vector3d(dir_sum / dn) : Eigen::Vector3d::Zero();
  if (!force.allFinite()) {
    out.nonfinite = true;
    solution_ = ContactSolution{};
    return;
  }
  // --- quasi non-linear law: Q on the force component along the mean imposed displacement ---
  if (law_ != nullptr && dn > 0 && !law_->apply_force(force, out.direction, force)) out.nonfinite = true;
  if (!force.allFinite()) {
    out.nonfinite = true;
    solution_ = ContactSolution{};
    return;
  }
  out.force = force;

  // --- device clamp: never more than the device limit ---
  const double norm = force.norm();
  if (norm > tool_.force_limit) {
    out.saturated = true;
    force *= tool_.force_limit / norm;
  }
  out.device_force = force;
}

}  // namespace surgsim
