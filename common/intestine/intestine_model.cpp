#include "intestine/intestine_model.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "mesh/geometry.h"
#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::intestine {

namespace {

constexpr double kPi = 3.14159265358979323846;

// A frame (e0 along the vessel, e1, e2 across) for the cylinder.
void axis_frame(const Eigen::Vector3d& axis, Eigen::Vector3d& e0, Eigen::Vector3d& e1, Eigen::Vector3d& e2) {
  e0 = axis.normalized();
  const Eigen::Vector3d helper = std::abs(e0.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitY();
  e1 = helper.cross(e0).normalized();  // for the default axis (x): e1 = y
  e2 = e0.cross(e1);                   // and e2 = z
}

// The folded sine in cylinder coordinates, phi in [0, 2 pi folds]: angle around the vessel and position along it.
//   theta(phi) = span / (2 pi folds) (phi + shape / 2 sin 2 phi),   s(phi) = amplitude cos phi
// shape = 0 is a sine; shape = 1 stops the angle at the legs (phi = pi/2 mod pi) so the legs run along the vessel
// and the crests are round, which keeps the folds apart.
struct FoldedSine {
  double radius, span, shape, amplitude;
  int folds;
  double end;  // phi at the curve's end: 2 pi folds, or (tapered mesentery) 2 pi folds - pi, ends apart on the vessel
  Eigen::Vector2d at(double phi) const {  // (arc along the circumference, along the vessel), m
    const double theta = span / end * (phi + 0.5 * shape * std::sin(2 * phi));
    return {radius * theta, amplitude * std::cos(phi)};
  }
  double length(int samples) const {
    double l = 0;
    Eigen::Vector2d prev = at(0);
    for (int i = 1; i <= samples; ++i) {
      const Eigen::Vector2d p = at(end * i / samples);
      l += (p - prev).norm();
      prev = p;
    }
    return l;
  }
};

}  // namespace

const char* to_string(CollisionDetector detector) {
  return detector == CollisionDetector::kBroadPhase ? "broad_phase" : "stochastic";
}

const char* to_string(StepStatus status) {
  switch (status) {
    case StepStatus::kOk: return "ok";
    case StepStatus::kBadInput: return "bad input";
    case StepStatus::kNonFinite: return "non-finite value (state restored)";
    case StepStatus::kSolverFailed: return "implicit solve failed (state restored)";
  }
  return "?";
}

double mesentery_width_factor(const IntestineParams& p, int column) {
  if (!(p.mesentery_taper > 0)) return 1.0;
  const double taper = p.mesentery_taper * (p.columns - 1);
  const double d = std::min(column, p.columns - 1 - column);
  return d >= taper ? 1.0 : std::sin(0.5 * kPi * (d + 0.5) / (taper + 0.5));
}

double mesentery_root_extension(const IntestineParams& p) {
  return p.mesentery_taper > 0 ? 4 * p.intestine_radius + 0.5 * p.mesentery_thickness : 0.0;
}

int mesentery_taper_columns(const IntestineParams& p) {
  return p.mesentery_taper > 0 ? static_cast<int>(std::ceil(p.mesentery_taper * (p.columns - 1))) : 0;
}

MassSpring IntestineModel::build(const IntestineParams& p, double& amplitude, double& segment_length) {
  // Validation (init phase: an actionable message).
  if (p.columns < 4 || p.rows < 2 || p.rows * p.columns > kMaxIntestineNodes) {
    throw_error("intestine: columns >= 4 and rows >= 2 with rows x columns <= ", kMaxIntestineNodes, " (got ",
                p.rows, " x ", p.columns, ")");
  }
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (!positive(p.length) || !positive(p.cylinder_radius) || p.folds < 1 || !positive(p.angular_span) ||
      p.angular_span > 2 * kPi || !(p.fold_shape >= 0 && p.fold_shape <= 2) || !positive(p.intestine_radius) ||
      !(p.mesentery_thickness >= 0)) {
    throw_error("intestine: length, cylinder_radius, angular_span (<= 2 pi), intestine_radius must be > 0, folds >= 1, "
                "fold_shape in [0, 2], mesentery_thickness >= 0");
  }
  if (!positive(p.intestine_node_mass) || !positive(p.mesentery_node_mass) || !(p.structural_stiffness >= 0) ||
      !(p.shear_stiffness >= 0) || !(p.bending_stiffness >= 0) || !(p.spring_damping >= 0) || !(p.drag >= 0) ||
      !p.gravity.allFinite() || !(p.probe_stiffness >= 0) || !positive(p.probe_force_limit) || p.probe_capacity < 1 ||
      p.contact_capacity < 1 || p.response.iterations < 0 || !(p.obstacle_stiffness >= 0) ||
      !std::isfinite(p.obstacle_stiffness) || p.obstacle_capacity < 0) {
    throw_error(
        "intestine: masses > 0, stiffnesses (obstacle_stiffness finite), damping, drag >= 0, "
        "probe_force_limit > 0, probe and contact capacities >= 1, obstacle_capacity >= 0, response iterations "
        ">= 0");
  }
  if (!p.axis_direction.allFinite() || p.axis_direction.norm() < 1e-9 || !p.axis_origin.allFinite()) {
    throw_error("intestine: axis_direction must be a non-zero vector and axis_origin finite");
  }
  if (!(p.mesentery_taper >= 0 && p.mesentery_taper <= 0.45)) {
    throw_error("intestine: mesentery_taper ", p.mesentery_taper,
                " is out of [0, 0.45] (the fraction of the length at each end over which the mesentery narrows)");
  }
  const double arc = p.cylinder_radius * p.angular_span;
  if (p.length <= arc) {
    throw_error("intestine: length ", p.length, " m must exceed the arc the curve covers (", arc,
                " m): no room for folds");
  }

  // Amplitude of the folds such that the curve is `length` long (the length grows with the amplitude: bisection).
  const double curve_end = p.mesentery_taper > 0 ? 2 * kPi * p.folds - kPi : 2 * kPi * p.folds;
  FoldedSine curve{p.cylinder_radius, p.angular_span, p.fold_shape, 0.0, p.folds, curve_end};
  const int fine = 200 * p.folds * 10;
  double lo = 0, hi = p.length;
  for (int it = 0; it < 60; ++it) {
    curve.amplitude = 0.5 * (lo + hi);
    (curve.length(fine) < p.length ? lo : hi) = curve.amplitude;
  }
  amplitude = curve.amplitude = 0.5 * (lo + hi);

  // Intestine nodes equally spaced in arc length along the curve.
  const int cols = p.columns, rows = p.rows;
  std::vector<Eigen::Vector2d> dense(static_cast<std::size_t>(fine) + 1);
  std::vector<double> acc(static_cast<std::size_t>(fine) + 1, 0.0);
  const double end = curve_end;
  for (int i = 0; i <= fine; ++i) {
    dense[static_cast<std::size_t>(i)] = curve.at(end * i / fine);
    if (i > 0) {
      acc[static_cast<std::size_t>(i)] =
          acc[static_cast<std::size_t>(i - 1)] +
          (dense[static_cast<std::size_t>(i)] - dense[static_cast<std::size_t>(i - 1)]).norm();
    }
  }
  const double total = acc.back();
  Eigen::Vector3d e0, e1, e2;
  axis_frame(p.axis_direction, e0, e1, e2);
  // The curve is centred along the vessel and its angle range centred on "up" (e2): the opening faces down.
  const double theta0 = 0.5 * kPi - 0.5 * p.angular_span;
  Eigen::Matrix3Xd rest(3, rows * cols);
  std::size_t k = 0;
  for (int c = 0; c < cols; ++c) {
    const double target = total * c / (cols - 1);
    while (k + 1 < acc.size() - 1 && acc[k + 1] < target) ++k;
    const double seg = acc[k + 1] - acc[k];
    const double f = seg > 0 ? std::clamp((target - acc[k]) / seg, 0.0, 1.0) : 0.0;
    const Eigen::Vector2d q = (1 - f) * dense[k] + f * dense[k + 1];
    const double theta = theta0 + q.x() / p.cylinder_radius;
    // Tapered ends: besides narrowing, the curve is carried along the vessel beyond the folds' range [-A, A] (the
    // duodenojejunal flexure and the ileocecal junction lie at the two ends of the root, beyond the fan of folds), by
    // root_extension (1 - w) away from the vessel's centre on the side of its end, so that the narrowed ends meet the
    // vessel where no other fold's sheet is (every crest's sheet meets it at s = +-A).
    const double w = mesentery_width_factor(p, c);
    const double end_side = (2 * c < cols - 1 ? dense.front().y() : dense.back().y()) >= 0 ? 1.0 : -1.0;
    const double s = q.y() + end_side * mesentery_root_extension(p) * (1.0 - w);
    const Eigen::Vector3d on_axis = p.axis_origin + s * e0;
    const Eigen::Vector3d radial = std::cos(theta) * e1 + std::sin(theta) * e2;
    // Row r at radius R w (1 - r / (rows - 1)): row 0 on the cylinder (narrowed by w near the ends), the last row on
    // the vessel.
    for (int r = 0; r < rows; ++r) {
      const double rad = p.cylinder_radius * w * (1.0 - static_cast<double>(r) / (rows - 1));
      rest.col(r * cols + c) = on_axis + rad * radial;
    }
  }
  segment_length = total / (cols - 1);

  // Masses; the vessel row is fixed.
  const int n = rows * cols;
  std::vector<double> mass(static_cast<std::size_t>(n), p.mesentery_node_mass);
  std::vector<std::uint8_t> fixed(static_cast<std::size_t>(n), 0);
  for (int c = 0; c < cols; ++c) {
    mass[static_cast<std::size_t>(c)] = p.intestine_node_mass;
    fixed[static_cast<std::size_t>((rows - 1) * cols + c)] = 1;
  }
  // Springs: structural (grid edges), shear (both diagonals), bending (intestine c, c + 2).
  std::vector<Spring> springs;
  auto add = [&](int i, int j, double k, SpringKind kind) {
    if (fixed[static_cast<std::size_t>(i)] && fixed[static_cast<std::size_t>(j)]) return;
    const double l = (rest.col(j) - rest.col(i)).norm();
    if (!(l > 1e-9)) throw_error("intestine: nodes ", i, " and ", j, " coincide at rest");
    springs.push_back(Spring{i, j, l, k, p.spring_damping, kind});
  };
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      if (c + 1 < cols) add(i, i + 1, p.structural_stiffness, SpringKind::kStructural);
      if (r + 1 < rows) add(i, i + cols, p.structural_stiffness, SpringKind::kStructural);
      if (r + 1 < rows && c + 1 < cols) {
        add(i, i + cols + 1, p.shear_stiffness, SpringKind::kShear);
        add(i + 1, i + cols, p.shear_stiffness, SpringKind::kShear);
      }
    }
  }
  for (int c = 0; c + 2 < cols; ++c) add(c, c + 2, p.bending_stiffness, SpringKind::kBending);

  // Band order: column by column, so every spring couples slots at most 2 (rows - 1) apart.
  std::vector<int> order(static_cast<std::size_t>(n), -1);
  for (int c = 0; c < cols; ++c) {
    for (int r = 0; r + 1 < rows; ++r) order[static_cast<std::size_t>(r * cols + c)] = c * (rows - 1) + r;
  }
  return MassSpring(std::move(rest), std::move(mass), std::move(fixed), std::move(springs), p.gravity, p.drag,
                    std::move(order));
}

IntestineModel::IntestineModel(const IntestineParams& params)
    : params_(params), system_(build(params, amplitude_, segment_length_)) {
  topology_.rows = params_.rows;
  topology_.cols = params_.columns;
  topology_.grid.resize(static_cast<std::size_t>(node_count()));
  for (int i = 0; i < node_count(); ++i) topology_.grid[static_cast<std::size_t>(i)] = i;
  topology_.intestine_radius = params_.intestine_radius;
  topology_.mesentery_half_thickness = 0.5 * params_.mesentery_thickness;
  topology_.segment_exclusion = params_.segment_exclusion;
  topology_.cell_exclusion = params_.cell_exclusion;
  topology_.taper_columns = mesentery_taper_columns(params_);
}

IntestineState::IntestineState(const IntestineModel& model, std::uint64_t seed)
    : x(model.rest()),
      v(Eigen::Matrix3Xd::Zero(3, model.node_count())),
      work_(model.mass_spring()),
      detector_(model.topology(), model.params().detection),
      broad_(model.topology()),
      contacts_(model.params().contact_capacity),
      probe_contacts_(static_cast<std::size_t>(kMaxProbes) * static_cast<std::size_t>(model.params().probe_capacity) +
                      static_cast<std::size_t>(model.params().obstacle_capacity)),
      x_entry_(model.rest()),
      v_entry_(Eigen::Matrix3Xd::Zero(3, model.node_count())) {
  reset(model, seed);
}

void IntestineState::reset(const IntestineModel& model, std::uint64_t seed) noexcept {
  x = model.rest();
  v.setZero();
  time = 0;
  steps = 0;
  faults = 0;
  contacts_.clear();
  detector_.reset(seed != 0 ? seed : model.params().detection.seed);
}

namespace {

// One probe's penalty contacts with the body at positions x (on step entry): intestine segments as capsules, mesentery
// triangles as slabs of half the thickness, written to out[0..capacity) (more are counted in r.overflow). Its force
// on the tool is minus the sum of the forces on the body, clamped to `limit`. Returns the contacts written.
int touch(const IntestineModel& model, const Eigen::Matrix3Xd& x, const Probe& probe, double limit,
          PenaltyContact* out, int capacity, ProbeReport& r) noexcept {
  const IntestineParams& p = model.params();
  int np = 0;
  Eigen::Vector3d body_force = Eigen::Vector3d::Zero();
  const bool probe_ok = probe.center.allFinite() && std::isfinite(probe.radius) && probe.radius >= 0;
  if (probe.active && !probe_ok) r.rejected = true;
  if (probe.active && probe_ok && p.probe_stiffness > 0) {
    const CollisionTopology& topo = model.topology();
    const Eigen::Vector3d& c = probe.center;
    auto add = [&](int count, const int* nodes, const double* w, const Eigen::Vector3d& point, double reach) {
      const Eigen::Vector3d d = point - c;
      const double dist = d.norm();
      const double depth = reach - dist;
      if (!(depth > 0)) return;
      if (np >= capacity) {
        ++r.overflow;
        return;
      }
      PenaltyContact& pc = out[np++];
      pc.count = count;
      for (int k = 0; k < 3; ++k) {
        pc.nodes[static_cast<std::size_t>(k)] = k < count ? nodes[k] : -1;
        pc.weights[static_cast<std::size_t>(k)] = k < count ? w[k] : 0.0;
      }
      pc.normal = dist > 1e-9 ? Eigen::Vector3d(d / dist) : Eigen::Vector3d(-p.gravity.normalized());
      if (!pc.normal.allFinite()) pc.normal = Eigen::Vector3d::UnitZ();
      pc.depth = depth;
      pc.stiffness = p.probe_stiffness;
      body_force += p.probe_stiffness * depth * pc.normal;
    };
    const double reach_i = probe.radius + p.intestine_radius;
    const double reach_m = probe.radius + 0.5 * p.mesentery_thickness;
    for (int s = 0; s < topo.segments(); ++s) {
      const int nodes[2] = {topo.node(0, s), topo.node(0, s + 1)};
      const Eigen::Vector3d a = x.col(nodes[0]), b = x.col(nodes[1]);
      if (((a.cwiseMin(b) - c).array() > reach_i).any() || ((c - a.cwiseMax(b)).array() > reach_i).any()) continue;
      const Eigen::Vector3d ab = b - a;
      const double t = std::clamp(ab.dot(c - a) / std::max(ab.squaredNorm(), 1e-18), 0.0, 1.0);
      const double w[2] = {1 - t, t};
      add(2, nodes, w, a + t * ab, reach_i);
    }
    // Mesentery cells: a cell whose four corners' box is out of reach skips both its triangles.
    const double* px = x.data();
    for (int r = 0; r + 1 < topo.rows; ++r) {
      for (int col = 0; col + 1 < topo.cols; ++col) {
        const double* q[4] = {px + 3 * topo.node(r, col), px + 3 * topo.node(r, col + 1),
                              px + 3 * topo.node(r + 1, col), px + 3 * topo.node(r + 1, col + 1)};
        bool out = false;
        for (int k = 0; k < 3 && !out; ++k) {
          const double lo = std::min(std::min(q[0][k], q[1][k]), std::min(q[2][k], q[3][k]));
          const double hi = std::max(std::max(q[0][k], q[1][k]), std::max(q[2][k], q[3][k]));
          out = lo - c[k] > reach_m || c[k] - hi > reach_m;
        }
        if (out) continue;
        const int cell = r * (topo.cols - 1) + col;
        for (int tri = 2 * cell; tri < 2 * cell + 2; ++tri) {
          int nodes[3];
          topo.triangle(tri, nodes);
          const Eigen::Vector3d A = x.col(nodes[0]), B = x.col(nodes[1]), C = x.col(nodes[2]);
          if (((A.cwiseMin(B).cwiseMin(C) - c).array() > reach_m).any() ||
              ((c - A.cwiseMax(B).cwiseMax(C)).array() > reach_m).any()) {
            continue;
          }
          Eigen::Vector3d bary;
          const Eigen::Vector3d qc = closest_point_triangle(c, A, B, C, bary);
          const double w[3] = {bary[0], bary[1], bary[2]};
          add(3, nodes, w, qc, reach_m);
        }
      }
    }
  }
  r.contacts = np;
  const Eigen::Vector3d tool = -body_force;
  r.force_raw = tool.norm();
  if (!tool.allFinite()) {
    r.force.setZero();
  } else if (r.force_raw > limit) {
    r.force = tool * (limit / r.force_raw);
    r.saturated = true;
  } else {
    r.force = tool;
  }
  return np;
}

// The one-probe fields of the report: probe 0's values (zero without probes).
void mirror_probe0(StepReport& report) noexcept {
  const ProbeReport& r0 = report.probes[0];
  report.probe_rejected = r0.rejected;
  report.probe_contacts = r0.contacts;
  report.probe_overflow = r0.overflow;
  report.probe_force = r0.force;
  report.probe_force_raw = r0.force_raw;
  report.probe_saturated = r0.saturated;
}

// The obstacles' contacts at the positions on entry, after the probes' (storage from `out`, room for `room`): one
// single-node penalty contact per free node whose sphere overlaps an obstacle, with each obstacle's range in `begin`.
int touch_obstacles(const IntestineModel& model, const Eigen::Matrix3Xd& x, const Obstacle* const* obstacles,
                    int obstacle_count, PenaltyContact* out, int room, StepReport& report,
                    std::array<int, kMaxObstacles + 1>& begin) noexcept {
  const IntestineParams& p = model.params();
  const MassSpring& system = model.mass_spring();
  int n = 0;
  report.obstacle_count = obstacle_count;
  for (int k = 0; k < obstacle_count; ++k) {
    begin[static_cast<std::size_t>(k)] = n;
    ObstacleReport& r = report.obstacles[static_cast<std::size_t>(k)];
    if (!(p.obstacle_stiffness > 0)) continue;
    for (int node = 0; node < system.node_count(); ++node) {
      const double radius = obstacle_radius(model, node);
      if (!(radius > 0)) continue;
      ObstacleHit hit;
      const Eigen::Vector3d xn = x.col(node);
      if (!obstacles[k]->nearest(node, xn, radius, hit) || !(hit.distance < radius) || !std::isfinite(hit.distance) ||
          !hit.normal.allFinite()) {
        continue;
      }
      const double depth = radius - hit.distance;
      ++r.contacts;
      r.max_depth = std::max(r.max_depth, depth);
      if (n >= room) {
        ++report.obstacle_overflow;
        continue;
      }
      PenaltyContact& c = out[n++];
      c.count = 1;
      c.nodes = {{node, -1, -1}};
      c.weights = {{1, 0, 0}};
      c.normal = hit.normal;
      c.depth = depth;
      c.stiffness = p.obstacle_stiffness;
    }
  }
  begin[static_cast<std::size_t>(obstacle_count)] = n;
  return n;
}

}  // namespace

double obstacle_radius(const IntestineModel& model, int node) noexcept {
  const IntestineParams& p = model.params();
  if (node < 0 || node >= model.mass_spring().node_count() || model.mass_spring().fixed(node)) return 0;
  return node < p.columns ? p.intestine_radius : 0.5 * p.mesentery_thickness;
}

void step_dynamics(const IntestineModel& model, IntestineState& state, const Probe* probes, int probe_count, double dt,
                   StepReport& report, const Obstacle* const* obstacles, int obstacle_count) noexcept {
  report = StepReport{};
  const IntestineParams& p = model.params();
  if (!(dt > 0) || !std::isfinite(dt) || probe_count < 0 || probe_count > kMaxProbes ||
      (probes == nullptr && probe_count > 0) || obstacle_count < 0 || obstacle_count > kMaxObstacles ||
      (obstacles == nullptr && obstacle_count > 0)) {
    report.status = StepStatus::kBadInput;
    return;
  }
  for (int k = 0; k < obstacle_count; ++k) {
    if (obstacles[k] == nullptr) {
      report.status = StepStatus::kBadInput;
      return;
    }
  }
  state.x_entry_ = state.x;
  state.v_entry_ = state.v;

  // Every probe's contacts (at the positions on entry), one after the other in the preallocated storage, each probe
  // with its own capacity and its own force limit.
  report.probe_count = probe_count;
  int np = 0;
  for (int i = 0; i < probe_count; ++i) {
    const Probe& probe = probes[i];
    const double limit = probe.force_limit > 0 ? probe.force_limit : p.probe_force_limit;
    np += touch(model, state.x, probe, limit, state.probe_contacts_.data() + np, p.probe_capacity,
                report.probes[static_cast<std::size_t>(i)]);
  }
  mirror_probe0(report);
  // Then the obstacles' (their storage follows the probes' whole capacity).
  std::array<int, kMaxObstacles + 1> begin{};
  const int first_obstacle = np;
  np += touch_obstacles(model, state.x, obstacles, obstacle_count, state.probe_contacts_.data() + np,
                        std::min(p.obstacle_capacity, static_cast<int>(state.probe_contacts_.size()) - np), report,
                        begin);

  const IntegrateStatus s =
      integrate(model.mass_spring(), p.integrator, state.probe_contacts_.data(), np, dt, state.x, state.v, state.work_);
  if (s == IntegrateStatus::kNonFinite) report.status = StepStatus::kNonFinite;
  if (s == IntegrateStatus::kNotPositive) report.status = StepStatus::kSolverFailed;
  if (report.status != StepStatus::kOk) return;
  // Each obstacle's push over the step: the implicit step's penalty, k (depth0 - n . (x1 - x0)) n per node (the
  // symplectic step uses the depth at entry).
  const bool implicit = p.integrator == Integrator::kImplicitEuler;
  for (int k = 0; k < obstacle_count; ++k) {
    Eigen::Vector3d f = Eigen::Vector3d::Zero();
    for (int l = first_obstacle + begin[static_cast<std::size_t>(k)];
         l < first_obstacle + begin[static_cast<std::size_t>(k) + 1]; ++l) {
      const PenaltyContact& c = state.probe_contacts_[static_cast<std::size_t>(l)];
      const int node = c.nodes[0];
      const double depth = implicit ? c.depth - c.normal.dot(state.x.col(node) - state.x_entry_.col(node)) : c.depth;
      f += c.stiffness * depth * c.normal;
    }
    report.obstacles[static_cast<std::size_t>(k)].force = f;
  }
}

void step_detection(const IntestineModel& model, IntestineState& state, StepReport& report) noexcept {
  state.contacts_.clear();
  if (report.status != StepStatus::kOk || !model.params().self_collisions) return;
  if (model.params().detector == CollisionDetector::kBroadPhase) {
    const BroadPhaseStats b = state.broad_.detect(state.x, state.contacts_);
    report.detection = DetectStats{};
    report.detection.contacts = b.contacts;
    report.detection.overflow = b.overflow;
    report.detection.distance_tests = b.overlaps;
  } else {
    report.detection = state.detector_.detect(state.x, state.contacts_);
  }
  report.contacts = state.contacts_.size();
  report.contacts_overflow = state.contacts_.dropped();
}

void step_response(const IntestineModel& model, IntestineState& state, StepReport& report) noexcept {
  if (report.status != StepStatus::kOk || state.contacts_.size() == 0) return;
  respond(state.contacts_, model.mass_spring().inverse_mass().data(), model.params().response, state.x, state.v,
          report.response);
}

void step(const IntestineModel& model, IntestineState& state, const Probe* probes, int probe_count, double dt,
          StepReport& report, const Obstacle* const* obstacles, int obstacle_count) noexcept {
  step_dynamics(model, state, probes, probe_count, dt, report, obstacles, obstacle_count);
  step_detection(model, state, report);
  step_response(model, state, report);
  if (report.status == StepStatus::kOk && (!state.x.allFinite() || !state.v.allFinite())) {
    state.x = state.x_entry_;
    state.v = state.v_entry_;
    report.status = StepStatus::kNonFinite;
  }
  if (report.status == StepStatus::kBadInput) {
    ++state.faults;
    return;
  }
  if (report.status != StepStatus::kOk) {
    ++state.faults;
    for (ProbeReport& r : report.probes) r.force.setZero();  // never send a force computed from a refused state
    report.probe_force.setZero();
    return;
  }
  state.time += dt;
  ++state.steps;
}

double energy(const IntestineModel& model, const IntestineState& state) {
  return model.mass_spring().kinetic_energy(state.v) + model.mass_spring().potential_energy(state.x);
}

}  // namespace surgsim::intestine
