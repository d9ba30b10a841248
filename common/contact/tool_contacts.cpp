#include "contact/tool_contacts.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "core/clock.h"
#include "core/error.h"
#include "nonlinear/nonlinear_law.h"
#include "nonlinear/multirate_contacts.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::tool;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;

namespace surgsim::contact {

namespace {
const TensorBlock& haptic_block(const Tensors& t) {
  const TensorBlock* b = t.find("haptic");
  if (b == nullptr) throw_error("tensors without a 'haptic' block: rebuild the tensor cache");
  return *b;
}
}  // namespace

namespace {
const std::vector<ToolSpec>& checked_tools(const std::vector<ToolSpec>& tools) {
  if (tools.empty() || tools.size() > static_cast<std::size_t>(kMaxInstruments))
    throw_error("ToolContacts: ", tools.size(), " instruments (1..", kMaxInstruments, ")");
  return tools;
}
// The solve's node capacity: the instruments' capacities together, at most kMaxContacts.
int total_capacity(const std::vector<ToolSpec>& tools) {
  int sum = 0;
  for (const ToolSpec& t : tools) sum += std::max(t.contact_capacity, 1);
  return std::min(sum, kMaxContacts);
}
}  // namespace

ToolContacts::ToolContacts(const TetMesh& mesh, const SurfaceMesh& surface, const Tensors& tensors,
                           const std::vector<ToolSpec>& tools, const NonlinearLaw* law, LiverDeformation deformation)
    : mesh_(mesh),
      tensors_(tensors),
      haptic_(haptic_block(tensors)),
      tools_(checked_tools(tools)),
      model_(tools.front().contact_model),
      law_(law),
      grid_(mesh, surface),
      superposition_(tensors, "haptic", total_capacity(tools)),
      deformation_(deformation) {
  if (deformation_ == LiverDeformation::kCorotational) {
    if (model_ != ContactModel::kPatch)
      throw_error("ToolContacts: liver.deformation corotational needs tool.contact_model patch");
    rotations_ = std::make_unique<NodeRotations>(mesh, surface);
    worker_rotations_ = std::make_unique<NodeRotations>(mesh, surface);
    const auto nv = static_cast<Eigen::Index>(mesh.nodes.rows());
    solution_index_.assign(static_cast<std::size_t>(nv), -1);
    worker_u_.setZero(nv, 3);
    for (int i = 0; i < 3; ++i) {
      from_worker_.slot(i).u.setZero(nv, 3);
      from_worker_.slot(i).q.assign(static_cast<std::size_t>(nv), Eigen::Quaterniond::Identity());
    }
  }
  if (deformation_ == LiverDeformation::kMultirate && law_ != nullptr)
    throw_error(
        "ToolContacts: liver.deformation multirate takes no quasi non-linear law (the tracker is the "
        "non-linear model)");
  if (model_ != ContactModel::kPatch) return;
  const ToolSpec& tool_ = tools_.front();  // the tip radius of the patch surface: the first instrument's
  std::vector<std::uint8_t> free(static_cast<std::size_t>(mesh.nodes.rows()), 0);
  for (std::size_t n = 0; n < free.size(); ++n)
    free[n] = tensors.column_of_node[n] >= 0 && haptic_.row_of_node[n] >= 0 && tensors.fixed_mask[n] == 0 ? 1 : 0;
  radius_ = tool_.tip_radius;
  if (!(radius_ > 0) || !std::isfinite(radius_))
    throw_error("ToolContacts: tool.tip_radius ", radius_,
                " m: give the instrument tip's own radius (> 0, e.g. 0.0025)");
  tip_model_ = tool_.tip_model;
  surface_ = std::make_unique<ContactSurface>(mesh, surface, free, radius_);
  // Multirate: the near field stays linear and in series; the tracker makes the mesh's part non-linear.
  if (tip_model_ == TipModel::kFootprint) {
    if (!tensors.material)
      throw_error(
          "ToolContacts: the tensors carry no material (the tip's near field needs E and nu): load them with "
          "load_or_build_tensors or set Tensors::material");
    near_field_ = std::make_unique<NearField>(mesh, surface, *tensors.material, &tensors);
  }
  patch_solver_ = std::make_unique<PatchSolver>(tensors, "haptic");
  constraints_ = std::make_unique<PatchConstraints>();
}

void ToolContacts::rotate_union(const PatchConstraints& k) noexcept {
  from_worker_.take();
  const RotationField& bg = from_worker_.front();
  // Rest-frame displacements G R^T lambda of the previous tick: the solution's own nodes exactly, the others from
  // the background field.
  const auto disp = [&](int node) -> Eigen::Vector3d {
    const int l = solution_index_[static_cast<std::size_t>(node)];
    if (l >= 0 && l < solution_.count) return rest_displacement_[static_cast<std::size_t>(l)];
    return bg.valid ? Eigen::Vector3d(bg.u.row(node).transpose()) : Eigen::Vector3d::Zero();
  };
  for (int u = 0; u < k.node_count; ++u) {
    const int node = k.nodes[static_cast<std::size_t>(u)];
    // A node new to the contact starts from the background rotation (the loop's own may be old).
    if (bg.valid && solution_index_[static_cast<std::size_t>(node)] < 0)
      rotations_->set(node, bg.q[static_cast<std::size_t>(node)]);
    rotations_->update(node, disp);
    union_rotation_[static_cast<std::size_t>(u)] = rotations_->rotation(node);
  }
}

void ToolContacts::publish_solution() noexcept {
  for (int i = 0; i < indexed_count_; ++i)
    solution_index_[static_cast<std::size_t>(indexed_nodes_[static_cast<std::size_t>(i)])] = -1;
  indexed_count_ = solution_.count;
  RotationInput& in = to_worker_.back();
  in.count = solution_.count;
  for (int l = 0; l < solution_.count; ++l) {
    const auto sl = static_cast<std::size_t>(l);
    indexed_nodes_[sl] = solution_.nodes[sl];
    rest_displacement_[sl] = rotations_->rotation(solution_.nodes[sl]).transpose() * solution_.displacement[sl];
    solution_index_[static_cast<std::size_t>(solution_.nodes[sl])] = l;
    in.nodes[sl] = solution_.nodes[sl];
    in.lambda[sl] = solution_.lambda[sl];
  }
  to_worker_.publish();
}

void ToolContacts::refresh_rotations() noexcept {
  if (deformation_ != LiverDeformation::kCorotational) return;
  to_worker_.take();
  const RotationInput& in = to_worker_.front();
  NodeRotations& rot = *worker_rotations_;
  // Fixed-point step: the rest-frame response u~ = G R^T lambda from the current rotations, then the rotations from
  // u~ (compliance/corotation.h: not from the rotated response, which feeds back and runs away).
  for (int l = 0; l < in.count; ++l)
    worker_rest_lambda_[static_cast<std::size_t>(l)] =
        rot.rotation(in.nodes[static_cast<std::size_t>(l)]).transpose() * in.lambda[static_cast<std::size_t>(l)];
  worker_u_.setZero();
  for (int r = 0; r < haptic_.row_count(); ++r) {
    const int node = haptic_.row_nodes[static_cast<std::size_t>(r)];
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int l = 0; l < in.count; ++l) {
      const int c = tensors_.column_of_node[static_cast<std::size_t>(in.nodes[static_cast<std::size_t>(l)])];
      if (c >= 0) sum.noalias() += haptic_.block3(r, c) * worker_rest_lambda_[static_cast<std::size_t>(l)];
    }
    worker_u_.row(node) = sum.transpose();  // the rest-frame response: the rotations come from it
  }
  if (in.count == 0) {
    rot.reset();
  } else {
    const auto disp = [this](int k) -> Eigen::Vector3d { return worker_u_.row(k).transpose(); };
    for (int n = 0; n < rot.node_count(); ++n) rot.update(n, disp, 2 * NodeRotations::kTickIterations);
  }
  RotationField& out = from_worker_.back();
  out.u = worker_u_;
  for (int n = 0; n < rot.node_count(); ++n) out.q[static_cast<std::size_t>(n)] = rot.quaternion(n);
  out.valid = true;
  from_worker_.publish();
}

void ToolContacts::reset() noexcept {
  for (auto& p : points_) p = PointContact{};
  for (auto& p : patches_) p.count = 0;
  have_previous_.fill(false);
  solution_ = ContactSolution{};
  instrument_nodes_.fill(0);
}

void ToolContacts::reset_instrument(int t) noexcept {
  if (t < 0 || t >= kMaxInstruments) return;
  for (int i = 0; i < kMaxShaftPoints; ++i) {
    points_[static_cast<std::size_t>(t * kMaxShaftPoints + i)] = PointContact{};
    patches_[static_cast<std::size_t>(t * kMaxShaftPoints + i)].count = 0;
  }
  have_previous_[static_cast<std::size_t>(t)] = false;
}

void ToolContacts::set_bodies(const BodyPoint* points, int count) noexcept {
  count = points == nullptr ? 0 : std::max(count, 0);
  if (count > kMaxBodyPoints) body_overflow_ += count - kMaxBodyPoints;
  body_count_ = std::min(count, kMaxBodyPoints);
  for (int j = 0; j < body_count_; ++j) bodies_[static_cast<std::size_t>(j)] = points[j];
}

void ToolContacts::drop_solution() noexcept {
  solution_ = ContactSolution{};
  instrument_nodes_.fill(0);
}

void ToolContacts::count_instrument_nodes() noexcept {
  instrument_nodes_.fill(0);
  for (int l = 0; l < solution_.count; ++l) {
    const int t = node_instrument_[static_cast<std::size_t>(l)];
    if (t >= 0 && t < kMaxInstruments) ++instrument_nodes_[static_cast<std::size_t>(t)];
  }
}

bool ToolContacts::solution_displacement(int node, Eigen::Vector3d& u) const noexcept {
  // A node of the last linear patch solution has its displacement there (the same G lambda, computed once by the
  // solve); the others are read from the tensors. Corotational (warped) and multirate (lambda replaced) solutions, and
  // the triangle model's (imposed u*), read every node.
  if (model_ == ContactModel::kPatch && deformation_ != LiverDeformation::kCorotational && multirate_ == nullptr) {
    for (int l = 0; l < solution_.count; ++l)
      if (solution_.nodes[static_cast<std::size_t>(l)] == node) {
        u = solution_.displacement[static_cast<std::size_t>(l)];
        return true;
      }
  }
  return superposition_.displacement(node, solution_, u);
}

Eigen::Vector3d ToolContacts::deformed(int node) const noexcept {
  Eigen::Vector3d x = mesh_.nodes.row(node).transpose();
  Eigen::Vector3d u;
  if (solution_.count > 0 && solution_displacement(node, u)) x += u;
  return x;
}

void ToolContacts::deformed_cb(const void* self, int node, Eigen::Vector3d& out) {
  out = static_cast<const ToolContacts*>(self)->deformed(node);
}

Eigen::Vector3d ToolContacts::corrected(int l) const noexcept {
  const int node = solution_.nodes[static_cast<std::size_t>(l)];
  const int r = haptic_.row_of_node[static_cast<std::size_t>(node)];
  const int c = tensors_.column_of_node[static_cast<std::size_t>(node)];
  if (r < 0 || c < 0) return Eigen::Vector3d::Zero();
  return haptic_.block3(r, c) * solution_.lambda[static_cast<std::size_t>(l)];
}

namespace {
// Times the stages of one step into a ContactStageTimes when `on`: each lap() is the time since the previous one (or
// since the clock started). Stages without a lap keep 0. Off, it reads no clock.
class StageClock {
 public:
  StageClock(ContactStageTimes& times, bool on) noexcept
      : times_(times), on_(on), last_(on ? core::monotonic_ns() : 0) {
    if (on_) times_.ns.fill(0);
  }
  void lap(ContactStage stage) noexcept {
    if (!on_) return;
    const std::uint64_t now = core::monotonic_ns();
    times_.ns[static_cast<std::size_t>(stage)] =
        static_cast<std::uint32_t>(std::min<std::uint64_t>(now - last_, UINT32_MAX));
    last_ = now;
  }

 private:
  ContactStageTimes& times_;
  bool on_;
  std::uint64_t last_;
};
}  // namespace

void ToolContacts::step(const InstrumentInput* inputs, int count, ContactTick* out, double dt) noexcept {
  status_ = ContactStatus::kOk;
  count_ = std::clamp(count, 0, instruments());
  const double h = std::isfinite(dt) && dt > 0 && dt < 1 ? dt : kDefaultDt;
  for (int t = 0; t < count_; ++t) {
    const auto st = static_cast<std::size_t>(t);
    out[t] = ContactTick{};
    geometry_[st] = nullptr;
    const ToolGeometry* g = inputs[t].tool;
    if (g == nullptr) {  // input lost: this instrument's contacts go, the others stay
      reset_instrument(t);
      continue;
    }
    // A non-finite tool pose never reaches the physics: drop its contacts, zero its force, report.
    const int n_points = g->point_count;
    bool finite = std::isfinite(inputs[t].jaw) && n_points >= 0 && n_points <= kMaxShaftPoints;
    for (int i = 0; i < n_points && finite; ++i) finite = g->points[static_cast<std::size_t>(i)].allFinite();
    if (model_ == ContactModel::kPatch) finite = finite && g->trocar.allFinite();
    if (!finite) {
      reset_instrument(t);
      out[t].nonfinite = true;
      continue;
    }
    geometry_[st] = g;
    jaw_[st] = inputs[t].jaw;
  }
  for (int t = count_; t < instruments(); ++t) {  // instruments the caller did not give: as lost
    geometry_[static_cast<std::size_t>(t)] = nullptr;
    reset_instrument(t);
  }
  // This step's body points (set_bodies): unsolved until the patch model's solve gives them a row.
  body_results_ = body_count_;
  for (int j = 0; j < body_results_; ++j) {
    body_force_[static_cast<std::size_t>(j)] = BodyForce{};
    body_row_[static_cast<std::size_t>(j)] = -1;
  }
  body_load_.setZero();
  if (model_ == ContactModel::kPatch) {
    step_patch(h, out);
  } else {
    step_triangle(h, out);
  }
  body_count_ = 0;  // given for one step only
  count_instrument_nodes();
  if (deformation_ == LiverDeformation::kCorotational) publish_solution();
  // Multirate: this tick's solution (nodes, displacements; none without contact) becomes the tracker's targets.
  if (multirate_ != nullptr) multirate_->hand_over(solution_, h);
}

// The triangle model's tick in the same stages as the patch model's (it has no friction stage: that time stays 0).
void ToolContacts::step_triangle(double /*dt*/, ContactTick* out) noexcept {
  StageClock clock(stage_times_, time_stages_);
  // --- track points: detection and contact update, per instrument and tool point (tip first) ---
  for (int t = 0; t < count_; ++t) {
    const ToolGeometry* geometry = geometry_[static_cast<std::size_t>(t)];
    if (geometry == nullptr) continue;
    const double jaw = jaw_[static_cast<std::size_t>(t)];
    const bool have_previous = have_previous_[static_cast<std::size_t>(t)];
    for (int i = 0; i < geometry->point_count; ++i) {
      const auto si = static_cast<std::size_t>(t * kMaxShaftPoints + i);
      const Eigen::Vector3d& p = geometry->points[static_cast<std::size_t>(i)];
      const Eigen::Vector3d& p_prev = have_previous ? previous_[si] : p;
      PointContact& c = points_[si];

      // New contact: the path since the last tick crosses the DEFORMED surface (continuous, so no tunnelling).
      if (!c.active) {
        const SurfaceHit hit = grid_.segment_query(p_prev, p, &ToolContacts::deformed_cb, this);
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
        // Unilateral, frictionless: the anchor follows the closest point of the rest surface on the side the
        // contact pressed (a tip pushed deeper than half the organ must not re-anchor on the opposite face).
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
    for (int i = 0; i < geometry->point_count; ++i)
      previous_[static_cast<std::size_t>(t * kMaxShaftPoints + i)] = geometry->points[static_cast<std::size_t>(i)];
    have_previous_[static_cast<std::size_t>(t)] = true;
  }

  clock.lap(ContactStage::kTrackPoints);

  // --- build patches: each contact's displacement spread over its triangle, alpha_v = k_v / sum k^2 ---
  int m = 0;
  std::array<Eigen::Vector3d, kMaxInstruments> dir_sum;
  for (auto& d : dir_sum) d.setZero();
  std::array<int, kMaxInstruments> used{};  // nodes requested per instrument (its contact capacity)
  const int capacity = superposition_.capacity();
  for (int t = 0; t < count_; ++t) {
    const ToolGeometry* geometry = geometry_[static_cast<std::size_t>(t)];
    if (geometry == nullptr) continue;
    const int own_capacity = std::min(tools_[static_cast<std::size_t>(t)].contact_capacity, kMaxContacts);
    for (int i = 0; i < geometry->point_count; ++i) {
      const PointContact& c = points_[static_cast<std::size_t>(t * kMaxShaftPoints + i)];
      if (!c.active) continue;
      const Eigen::Vector3d d = geometry->points[static_cast<std::size_t>(i)] - c.anchor;
      // Two points dragging the same triangle would have their displacements averaged by the merge of duplicate
      // nodes. This happens when a fast stab carries the tip and the shaft points behind it through the surface in
      // one tick; a slow stab never activates the trailing points (they stay inside the tip's dent). The deepest
      // point holds the triangle (ties: the first, instruments in order), so the force does not depend on the speed.
      bool shadowed = false;
      for (int u = 0; u < count_ && !shadowed; ++u) {
        const ToolGeometry* gu = geometry_[static_cast<std::size_t>(u)];
        if (gu == nullptr) continue;
        for (int j = 0; j < gu->point_count && !shadowed; ++j) {
          const PointContact& o = points_[static_cast<std::size_t>(u * kMaxShaftPoints + j)];
          if ((u == t && j == i) || !o.active || o.triangle != c.triangle) continue;
          const double depth_i = -d.dot(c.normal);
          const double depth_j = -(gu->points[static_cast<std::size_t>(j)] - o.anchor).dot(o.normal);
          shadowed = depth_j > depth_i || (depth_j == depth_i && (u < t || (u == t && j < i)));
        }
      }
      if (shadowed) continue;
      const Eigen::Vector3d alpha = barycentric_weights(c.bary);
      int added = 0;
      for (int v = 0; v < 3; ++v) {
        const int node = c.nodes[static_cast<std::size_t>(v)];
        if (tensors_.column_of_node[static_cast<std::size_t>(node)] < 0) continue;  // fixed node: not constrained
        if (m == capacity || used[static_cast<std::size_t>(t)] == own_capacity) {
          out[t].over_capacity = true;
          break;
        }
        request_instrument_[static_cast<std::size_t>(m)] = t;
        requests_[static_cast<std::size_t>(m++)] = Contact{node, alpha[v] * d};
        ++used[static_cast<std::size_t>(t)];
        ++added;
      }
      if (added > 0) {
        ++out[t].points_in_contact;
        dir_sum[static_cast<std::size_t>(t)] += d;
        out[t].grasp = out[t].grasp || c.grasp;
      }
    }
  }

  clock.lap(ContactStage::kBuildPatches);

  // --- solve: lambda = G_CC^-1 u* for every instrument's constraints at once; each instrument's force = -sum of the
  // lambdas of its nodes ---
  if (m == 0) {
    drop_solution();
    return;
  }
  status_ = superposition_.solve(requests_.data(), m, solution_);
  clock.lap(ContactStage::kSolveActiveSet);
  const ContactStatus status = status_;
  if (status != ContactStatus::kOk) {
    for (int t = 0; t < count_; ++t) {
      if (geometry_[static_cast<std::size_t>(t)] == nullptr) continue;
      if (status == ContactStatus::kOverCapacity) out[t].over_capacity = true;
      if (status == ContactStatus::kNonFinite) out[t].nonfinite = true;
    }
    drop_solution();
    return;
  }
  // Multirate: the nodes' forces from the tracker's local model where its snapshot covers them.
  if (multirate_ != nullptr) multirate_->apply(solution_);
  // The solution's nodes are in first-seen request order: each belongs to the instrument that requested it first.
  // (One instrument: the same sum, in the same order, as the solve's tool_force.)
  std::array<Eigen::Vector3d, kMaxInstruments> force;
  for (auto& f : force) f.setZero();
  for (int l = 0; l < solution_.count; ++l) {
    int owner = 0;
    for (int r = 0; r < m; ++r) {
      if (requests_[static_cast<std::size_t>(r)].node == solution_.nodes[static_cast<std::size_t>(l)]) {
        owner = request_instrument_[static_cast<std::size_t>(r)];
        break;
      }
    }
    node_instrument_[static_cast<std::size_t>(l)] = owner;
    force[static_cast<std::size_t>(owner)] -= solution_.lambda[static_cast<std::size_t>(l)];
  }
  for (int t = 0; t < count_; ++t) {
    if (geometry_[static_cast<std::size_t>(t)] == nullptr) continue;
    finish(t, force[static_cast<std::size_t>(t)], dir_sum[static_cast<std::size_t>(t)], out[t]);
  }
  clock.lap(ContactStage::kDistributeForces);
}

void ToolContacts::finish(int t, Eigen::Vector3d force, const Eigen::Vector3d& dir_sum, ContactTick& out) noexcept {
  const double dn = dir_sum.norm();
  out.direction = dn > 0 ? Eigen::Vector3d(dir_sum / dn) : Eigen::Vector3d::Zero();
  if (!force.allFinite()) {
    out.nonfinite = true;
    drop_solution();
    return;
  }
  // --- quasi non-linear law: Q (the organ law: its surface field at this instrument's contact nodes) on the force
  // component along the mean imposed displacement ---
  if (law_ != nullptr && dn > 0) {
    std::array<int, kMaxContacts> nodes;
    std::array<Eigen::Vector3d, kMaxContacts> imposed;
    int m = 0;
    for (int l = 0; l < solution_.count; ++l) {
      if (node_instrument_[static_cast<std::size_t>(l)] != t) continue;
      nodes[static_cast<std::size_t>(m)] = solution_.nodes[static_cast<std::size_t>(l)];
      imposed[static_cast<std::size_t>(m++)] = solution_.displacement[static_cast<std::size_t>(l)];
    }
    if (!law_->apply_force(force, out.direction, nodes.data(), imposed.data(), m, force)) out.nonfinite = true;
  }
  if (!force.allFinite()) {
    out.nonfinite = true;
    drop_solution();
    return;
  }
  out.force = force;

  // --- device clamp: never more than this instrument's device limit ---
  const double limit = tools_[static_cast<std::size_t>(t)].force_limit;
  const double norm = force.norm();
  if (norm > limit) {
    out.saturated = true;
    force *= limit / norm;
  }
  out.device_force = force;
}

namespace {
// 0 -> 1, C1 (the onset ramp and the release fade).
double smooth01(double t) {
  t = std::clamp(t, 0.0, 1.0);
  return t * t * (3 - 2 * t);
}
// Two unit vectors completing n to an orthonormal basis.
void tangents(const Eigen::Vector3d& n, Eigen::Vector3d& t1, Eigen::Vector3d& t2) {
  const Eigen::Vector3d a = std::abs(n.x()) < 0.6 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  t1 = (a - a.dot(n) * n).normalized();
  t2 = n.cross(t1);
}
enum Kind : int { kNone = 0, kSlide = 1, kStick = 2, kGrasp = 3, kFading = 4 };
}  // namespace

// Follows tool point i's closest point of the rest surface, or finds it: through the segment it moved along since
// the last tick, or (resume: first tick after a reset) along the shaft from the trocar, then the closest point.
void ToolContacts::track(const ToolGeometry& geometry, int i, int g, bool resume) noexcept {
  const auto si = static_cast<std::size_t>(g);
  const Eigen::Vector3d& p = geometry.points[static_cast<std::size_t>(i)];
  PointContact& c = points_[si];
  const auto take = [&](const RestPoint& rp) {
    c.triangle = rp.triangle;
    for (int v = 0; v < 3; ++v) c.nodes[static_cast<std::size_t>(v)] = surface_->surface().tris(rp.triangle, v);
    c.bary = rp.bary;
    c.anchor = rp.point;
    c.normal = rp.normal;
    c.depth = (rp.point - p).dot(rp.normal);
  };
  if (c.tracked) {
    take(surface_->closest_local(p, c.triangle, &c.facing));
    if (!(c.depth > 0)) c.tracked = false;
    return;
  }
  c.resumed = false;
  // A point that was outside and has not moved cannot have crossed the rest surface: no query (a held instrument's
  // shaft points, every tick it is still).
  if (!resume && previous_[si] == p) return;
  const SurfaceHit hit = grid_.segment_query(resume ? geometry.trocar : previous_[si], p);
  RestPoint rp;
  if (hit.hit) rp = surface_->closest_local(p, hit.triangle);
  if (resume && (!rp.found || !((rp.point - p).dot(rp.normal) > 0))) {
    // The shaft crossed no surface before this point (or left it again): the closest rest point, any face.
    const SurfaceProjection proj = grid_.project_rest(p, 3);
    if (proj.found) rp = surface_->closest_local(p, proj.triangle);
  }
  if (!rp.found) return;
  if ((rp.point - p).dot(rp.normal) > 0) {
    take(rp);
    c.facing = rp.face_normal;
    c.tracked = true;
    c.resumed = resume;
  }
}

// The tool points of every instrument in one pass: point g = t * kMaxShaftPoints + i (instrument t, point i). An
// instrument without geometry this tick (lost, not finite) has no point here.
template <class F>
void ToolContacts::each_point(F&& f) {
  for (int t = 0; t < count_; ++t) {
    const ToolGeometry* geometry = geometry_[static_cast<std::size_t>(t)];
    if (geometry == nullptr) continue;
    for (int i = 0; i < geometry->point_count; ++i) f(t, i, t * kMaxShaftPoints + i, *geometry);
  }
}

Eigen::Vector3d ToolContacts::patch_force(int p_index) const noexcept {
  const PatchConstraints& k = *constraints_;
  Eigen::Vector3d f = Eigen::Vector3d::Zero();
  for (int r = 0; r < k.row_count; ++r)
    if (k.row_patch[static_cast<std::size_t>(r)] == p_index)
      f += mu_[static_cast<std::size_t>(r)] * k.row_direction[static_cast<std::size_t>(r)];
  return f;
}

void ToolContacts::disable_patch(int p_index) noexcept {
  const PatchConstraints& k = *constraints_;
  for (int r = 0; r < k.row_count; ++r)
    if (k.row_patch[static_cast<std::size_t>(r)] == p_index) enabled_[static_cast<std::size_t>(r)] = 0;
}

// The patch model's tick as its stages, each timed (stage_times()). A stage that does not run (nothing to solve, a
// failed solve) takes 0.
void ToolContacts::step_patch(double dt, ContactTick* out) noexcept {
  StageClock clock(stage_times_, time_stages_);
  track_points();
  clock.lap(ContactStage::kTrackPoints);
  build_patches(dt, out);
  clock.lap(ContactStage::kBuildPatches);
  const bool solved = solve_active_set(dt, out);
  clock.lap(ContactStage::kSolveActiveSet);
  if (!solved) return;
  apply_friction();
  clock.lap(ContactStage::kFriction);
  distribute_forces(dt, out);
  clock.lap(ContactStage::kDistributeForces);
}

// Stage 1: where each point is relative to the rest surface; grasps closing and opening.
void ToolContacts::track_points() noexcept {
  each_point([&](int t, int i, int g, const ToolGeometry& geometry) {
    const auto si = static_cast<std::size_t>(g);
    const double jaw = jaw_[static_cast<std::size_t>(t)];
    PointContact& c = points_[si];
    track(geometry, i, g, !have_previous_[static_cast<std::size_t>(t)]);
    if (c.grasp && jaw > kGraspOpenJaw) {
      c.grasp = false;
      if (c.tracked) {
        // Released inside the tissue: keep the tangential hold as a friction cone that shrinks to mu.
        c.sticking = true;
        c.stick_anchor = c.grasp_anchor;
        c.stick_triangle = c.grasp_triangle;
        const double fn = c.force.dot(c.normal);
        const double ft = (c.force - fn * c.normal).norm();
        c.cone_boost = fn > 0 ? ft / fn + 0.05 : 0.0;
        c.release_age = 0;
        c.release_offset = c.offset;
        c.active = true;
      } else {
        // Released out of the tissue: the hold fades over kReleaseFade.
        c.release_age = 0;
        c.release_offset = c.offset;
        c.active = false;
      }
    }
    if (!c.grasp && !c.tracked) {
      c.active = false;
      c.sticking = false;
      c.cone_boost = 0;
      if (c.release_age >= 0 && c.release_age >= kReleaseFade) c.release_age = -1;
    }
    if (c.tracked && c.release_age >= 0 && c.cone_boost == 0 && !c.active) c.release_age = -1;  // pressed again
    if (i == 0 && c.active && !c.grasp && jaw <= kGraspCloseJaw) {
      c.grasp = true;
      c.grasp_anchor = c.sticking ? c.stick_anchor : c.anchor;
      c.grasp_triangle = c.sticking ? c.stick_triangle : c.triangle;
      c.release_age = -1;
      c.cone_boost = 0;
    }
  });
  for (int t = 0; t < count_; ++t) {
    const ToolGeometry* geometry = geometry_[static_cast<std::size_t>(t)];
    if (geometry == nullptr) continue;
    for (int i = 0; i < geometry->point_count; ++i)
      previous_[static_cast<std::size_t>(t * kMaxShaftPoints + i)] = geometry->points[static_cast<std::size_t>(i)];
    have_previous_[static_cast<std::size_t>(t)] = true;
  }
}

// Stage 2: one patch per contact (or candidate), its rows and their imposed values.
void ToolContacts::build_patches(double dt, ContactTick* out) noexcept {
  const int capacity = superposition_.capacity();  // the union of all instruments' nodes
  PatchConstraints& k = *constraints_;
  k.clear();
  std::array<int, kMaxInstruments> dropped{};
  std::array<int, kMaxInstruments> used{};  // union nodes each instrument added (its own contact capacity)
  for (auto& v : patch_of_point_) v = -1;
  for (auto& v : kind_) v = kNone;
  each_point([&](int t, int i, int g, const ToolGeometry& geometry) {
    const auto si = static_cast<std::size_t>(g);
    const auto st = static_cast<std::size_t>(t);
    const double mu = tools_[st].friction;
    const int own_capacity = std::min(tools_[st].contact_capacity, kMaxContacts);
    PointContact& c = points_[si];
    PointPatch& pp = patches_[si];
    pp.count = 0;
    c.slipping = false;
    const Eigen::Vector3d& p = geometry.points[static_cast<std::size_t>(i)];
    int kind = kNone;
    if (c.grasp) {
      kind = kGrasp;
    } else if (c.release_age >= 0 && !c.tracked) {
      kind = kFading;
    } else if (c.tracked) {
      kind = (mu > 0 || c.cone_boost > 0) ? kStick : kSlide;
    }
    if (kind == kNone) return;
    // The patch: around the grasped or stuck material point, or the point's own closest rest point.
    int tri = c.triangle;
    Eigen::Vector3d centre = c.anchor;
    if (kind == kGrasp || kind == kFading) {
      tri = c.grasp_triangle;
      centre = c.grasp_anchor;
    } else if (kind == kStick) {
      if (!c.sticking) {  // a new sticking contact sticks where it is
        c.stick_anchor = c.anchor;
        c.stick_triangle = c.triangle;
      }
      tri = c.stick_triangle;
      centre = c.stick_anchor;
    }
    const RestPoint at = surface_->on_triangle(centre, tri);
    int fixed = 0, out_of_patch = 0;
    if (tip_model_ == TipModel::kFootprint && !((centre - pp.walk_centre).norm() < radius_)) {
      pp.walk.fill(-1);  // the hints are far away (or none): walk from the centre
      pp.walk_centre = centre;
    }
    pp.count = tip_model_ == TipModel::kFootprint
                   ? surface_->footprint(centre, tri, at.normal, radius_, kMaxContacts, pp.nodes.data(),
                                         pp.weights.data(), &out_of_patch, &fixed, pp.walk.data())
                   : surface_->patch(centre, tri, at.normal, kMaxContacts, pp.nodes.data(), pp.weights.data(),
                                     &out_of_patch, &fixed);
    pp.fixed = fixed;
    pp.dropped = out_of_patch;
    pp.centre = centre;
    if (pp.count == 0) return;  // only fixed nodes under the tip: nothing to constrain
    pp.normal = surface_->patch_normal(pp.nodes.data(), pp.weights.data(), pp.count);
    const Eigen::Vector3d& n = pp.normal;
    const double depth = (c.anchor - p).dot(n);
    c.depth = depth;
    if ((kind == kSlide || kind == kStick) && near_field_) {
      // A point less than the tip radius to the side of a deeper point of the same instrument (across that point's
      // normal: the shaft following the tip into the dimple it made) is in that point's hole, not a contact of its
      // own: the near field's dimple is not in the mesh's surface, so the gap below would count it as a penetration.
      // From the points' positions only (no history, not the anchors, which drift apart on a curved surface): a
      // resumed instrument gets the same contacts as one that pressed in.
      for (int j = 0; j < geometry.point_count; ++j) {
        const PointContact& o = points_[static_cast<std::size_t>(t * kMaxShaftPoints + j)];
        if (j == i || !o.tracked || o.grasp || !(o.depth > c.depth)) continue;
        const Eigen::Vector3d d = geometry.points[static_cast<std::size_t>(j)] - p;
        if ((d - d.dot(o.normal) * o.normal).norm() < radius_) return;
      }
    }
    if ((kind == kSlide || kind == kStick) && !c.active) {
      // A new contact: only when the point penetrates the patch as the current solution deforms it.
      double gap = depth;
      if (solution_.count > 0) {
        Eigen::Vector3d mean = Eigen::Vector3d::Zero(), u;
        for (int e = 0; e < pp.count; ++e)
          if (solution_displacement(pp.nodes[static_cast<std::size_t>(e)], u))
            mean += pp.weights[static_cast<std::size_t>(e)] * u;
        gap += n.dot(mean);
      }
      if (!(gap > 0)) return;
      c.onset_gap = c.resumed ? 0.0 : std::min(gap, depth);
      c.age = 0;
    }
    if (kind == kSlide || kind == kStick) c.age += dt;  // this tick counts: a new contact pushes at once
    // Into the union of nodes, within the tick's contact capacity (largest weights first; the rest renormalized).
    const int p_index = k.patch_count;
    int start = k.patch_start[static_cast<std::size_t>(p_index)];
    int kept = 0;
    double sum = 0;
    for (int e = 0; e < pp.count; ++e) {
      const int node = pp.nodes[static_cast<std::size_t>(e)];
      int u = 0;
      while (u < k.node_count && k.nodes[static_cast<std::size_t>(u)] != node) ++u;
      if (u == k.node_count) {
        if (k.node_count == capacity || used[st] == own_capacity) {
          ++dropped[st];
          continue;
        }
        union_instrument_[static_cast<std::size_t>(k.node_count)] = t;
        k.nodes[static_cast<std::size_t>(k.node_count++)] = node;
        ++used[st];
      }
      pp.nodes[static_cast<std::size_t>(kept)] = node;
      pp.weights[static_cast<std::size_t>(kept)] = pp.weights[static_cast<std::size_t>(e)];
      sum += pp.weights[static_cast<std::size_t>(kept)];
      k.entry_node[static_cast<std::size_t>(start + kept)] = u;
      ++kept;
    }
    pp.dropped += pp.count - kept;
    pp.count = kept;
    if (kept == 0) return;
    for (int e = 0; e < kept; ++e) {
      pp.weights[static_cast<std::size_t>(e)] /= sum;
      k.entry_weight[static_cast<std::size_t>(start + e)] = pp.weights[static_cast<std::size_t>(e)];
    }
    k.patch_start[static_cast<std::size_t>(p_index + 1)] = start + kept;
    k.patch_count = p_index + 1;
    // The tip's near field in series with the patch (footprint model): what the mesh cannot resolve under the tip.
    pp.near_normal = near_field_ ? near_field_->normal(pp.nodes.data(), pp.weights.data(), kept, radius_) : 0.0;
    k.near_normal[static_cast<std::size_t>(p_index)] = pp.near_normal;
    pp.near_tangent = near_field_ ? near_field_->tangential(pp.near_normal) : 0.0;
    k.near_tangent[static_cast<std::size_t>(p_index)] = pp.near_tangent;
    k.near_axis[static_cast<std::size_t>(p_index)] = n;
    patch_of_point_[si] = p_index;
    kind_[si] = kind;
    // Rows: the normal first, then two tangents for the 3-D constraints.
    Eigen::Vector3d t1, t2;
    tangents(n, t1, t2);
    Eigen::Vector3d offset;
    if (kind == kGrasp) {
      offset = p - centre;
    } else if (kind == kFading) {
      offset = (1 - smooth01(c.release_age / kReleaseFade)) * c.release_offset;
    } else {
      const double ramp = smooth01(c.age / kOnsetRamp);
      const double effective = depth - c.onset_gap * (1 - ramp);
      offset = -effective * n;
      if (kind == kStick) {
        const Eigen::Vector3d d = p - centre;
        offset += d - d.dot(n) * n;
      }
    }
    c.offset = offset;
    const int rows = kind == kSlide ? 1 : 3;
    const Eigen::Vector3d dirs[3] = {n, t1, t2};
    for (int r = 0; r < rows; ++r) {
      const auto kr = static_cast<std::size_t>(k.row_count);
      k.row_patch[kr] = p_index;
      k.row_direction[kr] = dirs[r];
      b_[kr] = dirs[r].dot(offset);
      enabled_[kr] = 1;
      ++k.row_count;
    }
  });
  for (int t = 0; t < count_; ++t) {
    if (dropped[static_cast<std::size_t>(t)] > 0) {
      out[t].over_capacity = true;
      dropped_nodes_ += dropped[static_cast<std::size_t>(t)];
    }
  }
  add_body_rows();
}

// Stage 2, continued: the bodies' points (set_bodies), each a patch of its triangle's contactable corners with the
// penalty's compliance in series and one unilateral row along its normal, while the union has room for its nodes.
void ToolContacts::add_body_rows() noexcept {
  if (multirate_ != nullptr) return;  // the tracker's forces replace the linear ones: no load could be solved
  PatchConstraints& k = *constraints_;
  const int capacity = kMaxContacts;  // the instruments' own capacities bound their share; the bodies take the rest
  constexpr int kNewNode = -2;        // a corner not yet in the union
  for (int j = 0; j < body_results_; ++j) {
    const BodyPoint& b = bodies_[static_cast<std::size_t>(j)];
    if (!(b.stiffness > 0) || !std::isfinite(b.stiffness) || !std::isfinite(b.gap) || !b.normal.allFinite() ||
        !b.bary.allFinite()) {
      continue;
    }
    // Its contactable corners, and the union nodes they need.
    std::array<int, 3> slot{{-1, -1, -1}};
    int corners = 0, fresh = 0;
    for (int c = 0; c < 3; ++c) {
      const int node = b.nodes[static_cast<std::size_t>(c)];
      if (!(b.bary[c] > 0) || contact_node_status(tensors_, haptic_, node) != ContactStatus::kOk) continue;
      int u = 0;
      while (u < k.node_count && k.nodes[static_cast<std::size_t>(u)] != node) ++u;
      slot[static_cast<std::size_t>(c)] = u < k.node_count ? u : kNewNode;
      if (u == k.node_count) ++fresh;
      ++corners;
    }
    if (corners == 0) continue;  // on the fixed set: the support carries it, the owner's own contact holds it
    if (k.node_count + fresh > capacity || k.patch_count == kMaxPatches || k.row_count == kMaxPatchRows) {
      ++body_overflow_;
      continue;
    }
    const int p_index = k.patch_count;
    const int start = k.patch_start[static_cast<std::size_t>(p_index)];
    int e = 0;
    for (int c = 0; c < 3; ++c) {
      int u = slot[static_cast<std::size_t>(c)];
      if (u == -1) continue;
      if (u == kNewNode) {  // a node new to the union (a triangle's corners are distinct)
        u = k.node_count++;
        union_instrument_[static_cast<std::size_t>(u)] = kBodyInstrument;
        k.nodes[static_cast<std::size_t>(u)] = b.nodes[static_cast<std::size_t>(c)];
      }
      k.entry_node[static_cast<std::size_t>(start + e)] = u;
      k.entry_weight[static_cast<std::size_t>(start + e)] = b.bary[c];
      ++e;
    }
    k.patch_start[static_cast<std::size_t>(p_index + 1)] = start + e;
    k.patch_count = p_index + 1;
    k.near_normal[static_cast<std::size_t>(p_index)] = 1 / b.stiffness;
    k.near_tangent[static_cast<std::size_t>(p_index)] = 0;
    k.near_axis[static_cast<std::size_t>(p_index)] = b.normal;
    const auto kr = static_cast<std::size_t>(k.row_count++);
    k.row_patch[kr] = p_index;
    k.row_direction[kr] = b.normal;
    b_[kr] = b.gap;
    enabled_[kr] = 1;
    body_row_[static_cast<std::size_t>(j)] = static_cast<int>(kr);
  }
}

// Stage 3: the solve, with an active set for the unilateral contacts (false: nothing to solve or the solve failed;
// the solution is dropped).
bool ToolContacts::solve_active_set(double dt, ContactTick* out) noexcept {
  PatchConstraints& k = *constraints_;
  each_point([&](int, int, int g, const ToolGeometry&) { points_[static_cast<std::size_t>(g)].force.setZero(); });
  if (k.row_count == 0) {
    each_point([&](int, int, int g, const ToolGeometry&) {
      PointContact& c = points_[static_cast<std::size_t>(g)];
      if (c.release_age >= 0) c.release_age += dt;
      if (!c.grasp) c.active = false;
    });
    drop_solution();
    return false;
  }
  const auto flag_all = [&](bool ContactTick::*flag) {
    for (int t = 0; t < count_; ++t)
      if (geometry_[static_cast<std::size_t>(t)] != nullptr) out[t].*flag = true;
  };
  if (deformation_ == LiverDeformation::kCorotational) {
    rotate_union(k);
    status_ = patch_solver_->prepare(k, union_rotation_.data());
  } else {
    status_ = patch_solver_->prepare(k);
  }
  if (status_ != ContactStatus::kOk) {
    if (status_ == ContactStatus::kNonFinite) flag_all(&ContactTick::nonfinite);
    drop_solution();
    return false;
  }
  bool solved = false;
  for (int iteration = 0; iteration <= k.patch_count + 1; ++iteration) {
    status_ = patch_solver_->factor(k, enabled_.data());
    if (status_ == ContactStatus::kNearSingular && patch_solver_->dependent_row() >= 0) {
      // A patch whose rows depend on earlier ones (two points on the same spot): the first (deeper-first order
      // does not matter: their constraints coincide) holds it.
      const int p_dep = k.row_patch[static_cast<std::size_t>(patch_solver_->dependent_row())];
      bool bilateral = false;
      for (int g = 0; g < kMaxPoints; ++g)
        if (patch_of_point_[static_cast<std::size_t>(g)] == p_dep)
          bilateral = kind_[static_cast<std::size_t>(g)] == kGrasp || kind_[static_cast<std::size_t>(g)] == kFading;
      if (bilateral) break;
      disable_patch(p_dep);
      continue;
    }
    if (status_ != ContactStatus::kOk) break;
    patch_solver_->solve(b_.data(), mu_.data());
    // Unilateral: a contact that would pull the tool in lets go (the most pulling one first).
    int worst = -1;
    double worst_fn = 0;
    for (int g = 0; g < kMaxPoints; ++g) {
      const auto si = static_cast<std::size_t>(g);
      if (kind_[si] != kSlide && kind_[si] != kStick) continue;
      const int pi = patch_of_point_[si];
      bool on = false;
      for (int r = 0; r < k.row_count; ++r)
        if (k.row_patch[static_cast<std::size_t>(r)] == pi && enabled_[static_cast<std::size_t>(r)]) on = true;
      if (!on) continue;
      const double fn = -patch_force(pi).dot(patches_[si].normal);  // push on the tool along n
      if (fn < worst_fn) {
        worst_fn = fn;
        worst = pi;
      }
    }
    // A body point whose row would pull it onto the organ is not touching: every such row lets go at once (penalty
    // rows in series with their own compliance: the next tick's gaps decide again).
    bool released = false;
    for (int j = 0; j < body_results_; ++j) {
      const int r = body_row_[static_cast<std::size_t>(j)];
      if (r >= 0 && enabled_[static_cast<std::size_t>(r)] && mu_[static_cast<std::size_t>(r)] > 0) {
        enabled_[static_cast<std::size_t>(r)] = 0;
        released = true;
      }
    }
    if (worst >= 0) {
      disable_patch(worst);
      continue;
    }
    if (released) continue;
    solved = true;
    break;
  }
  if (!solved) {
    if (status_ == ContactStatus::kOk) status_ = ContactStatus::kNearSingular;
    drop_solution();
    return false;
  }
  return true;
}

// Stage 4: Coulomb friction on the sticking patches.
void ToolContacts::apply_friction() noexcept {
  const PatchConstraints& k = *constraints_;
  // Coulomb: a sticking patch whose tangential force exceeds mu_eff F_n slides: its tangential offset shrinks until
  // |F_t| = mu_eff F_n (a few fixed-point steps on the factored system: the normal-tangential coupling is weak).
  for (int iteration = 0; iteration < 4; ++iteration) {
    bool changed = false;
    for (int g = 0; g < kMaxPoints; ++g) {
      const auto si = static_cast<std::size_t>(g);
      if (kind_[si] != kStick) continue;
      const double mu = tools_[static_cast<std::size_t>(g / kMaxShaftPoints)].friction;
      PointContact& c = points_[si];
      const int pi = patch_of_point_[si];
      const Eigen::Vector3d& n = patches_[si].normal;
      const Eigen::Vector3d f = -patch_force(pi);  // on the tool
      const double fn = f.dot(n);
      const double ft = (f - fn * n).norm();
      const double mu_eff = mu + c.cone_boost * (1 - smooth01(c.release_age / kReleaseFade));
      if (!(fn > 0) || ft <= mu_eff * fn * (1 + 1e-9)) continue;
      const double beta = mu_eff * fn / ft;
      for (int r = 0; r < k.row_count; ++r)
        if (k.row_patch[static_cast<std::size_t>(r)] == pi && r > 0 &&
            k.row_patch[static_cast<std::size_t>(r - 1)] == pi)
          b_[static_cast<std::size_t>(r)] *= beta;  // the tangential rows (the normal row comes first)
      c.slipping = true;
      changed = true;
    }
    if (!changed) break;
    patch_solver_->solve(b_.data(), mu_.data());
  }
}

// Stage 5: node forces (the ContactFrame entries), per-point forces and states, each instrument's force.
void ToolContacts::distribute_forces(double dt, ContactTick* out) noexcept {
  const PatchConstraints& k = *constraints_;
  patch_solver_->node_forces(k, mu_.data(), lambda_.data());
  patch_solver_->union_displacements(lambda_.data(), k.node_count, union_u_.data());
  ContactSolution& s = solution_;
  s = ContactSolution{};
  int count = 0;
  for (int u = 0; u < k.node_count; ++u) {
    if (lambda_[static_cast<std::size_t>(u)].isZero(0)) continue;
    const auto l = static_cast<std::size_t>(count++);
    node_instrument_[l] = union_instrument_[static_cast<std::size_t>(u)];
    s.nodes[l] = k.nodes[static_cast<std::size_t>(u)];
    s.lambda[l] = lambda_[static_cast<std::size_t>(u)];
    s.displacement[l] = union_u_[static_cast<std::size_t>(u)];
    s.corrected[l] = patch_solver_->g(u, u) * s.lambda[l];
    s.tool_force -= s.lambda[l];
  }
  s.count = count;
  s.status = ContactStatus::kOk;
  s.rcond = 1;
  std::array<Eigen::Vector3d, kMaxInstruments> dir_sum, force;
  for (auto& d : dir_sum) d.setZero();
  for (auto& f : force) f.setZero();
  each_point([&](int t, int, int g, const ToolGeometry& geometry) {
    const auto si = static_cast<std::size_t>(g);
    const auto st = static_cast<std::size_t>(t);
    const double mu = tools_[st].friction;
    PointContact& c = points_[si];
    const int pi = patch_of_point_[si];
    bool on = false;
    if (pi >= 0)
      for (int r = 0; r < k.row_count; ++r)
        if (k.row_patch[static_cast<std::size_t>(r)] == pi && enabled_[static_cast<std::size_t>(r)]) on = true;
    if (c.release_age >= 0) c.release_age += dt;
    if (c.cone_boost > 0 && c.release_age >= kReleaseFade) {
      c.cone_boost = 0;
      c.release_age = -1;
      c.sticking = mu > 0;
    }
    if (!on) {
      if (kind_[si] == kSlide || kind_[si] == kStick) {
        c.active = false;
        c.sticking = false;
      }
      return;
    }
    c.force = -patch_force(pi);
    force[st] += c.force;
    if (kind_[si] == kFading) return;  // a fading hold is not a contact
    dir_sum[st] += c.offset;
    ++out[t].points_in_contact;
    out[t].grasp = out[t].grasp || c.grasp;
    if (kind_[si] == kSlide || kind_[si] == kStick) c.active = true;
    if (kind_[si] == kStick) {
      c.sticking = true;
      if (c.slipping) {
        // The stuck material point moves to where the reduced tangential offset puts it, on the rest surface.
        const Eigen::Vector3d& n = patches_[si].normal;
        Eigen::Vector3d t_off = Eigen::Vector3d::Zero();
        for (int r = 0; r < k.row_count; ++r)
          if (k.row_patch[static_cast<std::size_t>(r)] == pi && r > 0 &&
              k.row_patch[static_cast<std::size_t>(r - 1)] == pi)
            t_off += b_[static_cast<std::size_t>(r)] * k.row_direction[static_cast<std::size_t>(r)];
        const Eigen::Vector3d target =
            geometry.points[static_cast<std::size_t>(g - t * kMaxShaftPoints)] - t_off + c.depth * n;
        const RestPoint rp = surface_->closest_local(target, c.stick_triangle);
        if (rp.found) {
          c.stick_anchor = rp.point;
          c.stick_triangle = rp.triangle;
        }
      }
    }
  });
  // The bodies' pushes, and their loads taken out of the tool's force (-sum lambda holds them).
  bool bodies = false;
  for (int j = 0; j < body_results_; ++j) {
    const int r = body_row_[static_cast<std::size_t>(j)];
    if (r < 0) continue;
    BodyForce& bf = body_force_[static_cast<std::size_t>(j)];
    bf.solved = true;
    bf.push = enabled_[static_cast<std::size_t>(r)] ? std::max(0.0, -mu_[static_cast<std::size_t>(r)]) : 0.0;
    const Eigen::Vector3d& n = bodies_[static_cast<std::size_t>(j)].normal;
    Eigen::Vector3d on_organ = Eigen::Vector3d::Zero();  // the share of the corners with a row (fixed ones: support)
    for (int e = k.patch_start[static_cast<std::size_t>(k.row_patch[static_cast<std::size_t>(r)])];
         e < k.patch_start[static_cast<std::size_t>(k.row_patch[static_cast<std::size_t>(r)]) + 1]; ++e)
      on_organ -= k.entry_weight[static_cast<std::size_t>(e)] * bf.push * n;
    s.tool_force += on_organ;
    body_load_ -= bf.push * n;
    bodies = true;
  }
  // One instrument without bodies: the solve's own sum over the union nodes (as a one-instrument solve adds them; the
  // per-point sum above is the same force in another order of additions).
  if (count_ == 1 && !bodies) force[0] = s.tool_force;
  // Multirate: the nodes' forces from the tracker's local model where its snapshot covers them; each instrument's
  // force is the sum over its own nodes.
  if (multirate_ != nullptr) {
    multirate_->apply(s);
    for (auto& f : force) f.setZero();
    for (int l = 0; l < s.count; ++l)
      force[static_cast<std::size_t>(node_instrument_[static_cast<std::size_t>(l)])] -=
          s.lambda[static_cast<std::size_t>(l)];
  }
  for (int t = 0; t < count_; ++t) {
    if (geometry_[static_cast<std::size_t>(t)] == nullptr) continue;
    finish(t, force[static_cast<std::size_t>(t)], dir_sum[static_cast<std::size_t>(t)], out[t]);
  }
}

}  // namespace surgsim::contact
