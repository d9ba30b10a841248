// The intestine scene's body (Raghupathi et al. 2004; docs/DESIGN.md, section 'Intestine: mass-spring + stochastic
// collisions'): small intestine and mesentery as one mass-spring grid, a probe, stochastic self-collisions and the
// displacement-velocity response, stepped at the haptic rate.
//
// Rest shape: a folded sine curve of length `length` on the inner surface of a cylinder of radius
// `cylinder_radius` whose axis is the mesenteric vessel; the intestine (a tube of radius `intestine_radius`) follows
// the curve and the mesentery (a membrane `mesentery_thickness` thick) joins it to the axis. The grid has `rows` x
// `columns` masses: row 0 is the intestine, row rows-1 lies on the vessel and is fixed, the rows between are the
// mesentery; node (r, c) has index r * columns + c, so the intestine's points are the first `columns` positions.
//
// Callers:
//   haptic node (1 kHz): IntestineModel once (init; throws surgsim::core::Error on bad parameters), one IntestineState
//     (init; allocates everything), then per tick one probe per instrument (at most kMaxProbes)
//       Probe probes[n] = {{true, tip_i, radius, force_limit_i}, ...};   // active = false: instrument i's input lost
//       intestine::step(model, state, probes, n, dt, report);    // noexcept, allocates nothing
//       force feedback i = report.probes[i].force (N, on instrument i, clamped to its force_limit; .saturated)
//     Every probe has its own penalty contacts (up to probe_capacity each), force, clamp and counts; all of them push
//     the same body in one integration step. The one-probe step(model, state, probe, dt, report) is the same with
//     n = 1, and report.probe_force, probe_contacts, ... repeat probes[0].
//       BodyState       = state.positions(), state.point_count() points (x, y, z), <= kMaxIntestineNodes
//       faults          = report.status != StepStatus::kOk (the state was restored, nothing non-finite escapes)
//     Cost on this machine (intestine_bench, default parameters, n = 10, thread CPU): the mass-spring phase (probe
//     included) p50 about 75 us, p99 about 110 us; the response p50 15, p99 20 us; detection on top grows with the
//     random pairs n and the contacts.
//   visual node: receives the positions (same layout); the intestine's points are the first columns() of them, the
//     whole rows x columns grid is the mesentery. Init: TubeBuilder tube(TubeParams{radius}, columns);
//     TubeMesh mesh = tube.make_mesh(kTubeMaxLod); MesenteryMesh strip = make_mesentery_mesh(rows, columns);
//     FrameRateController rate(FrameRateParams{target_hz}). Per frame: lod = rate.update(measured_fps);
//     tube.build(points, columns, lod, mesh); mesentery_strip(points, strip); draw mesh (triangles) and strip
//     (a triangle strip). All allocation-free (tube_geometry.h, frame_rate_controller.h).
//   tests and benchmarks: the three phases step_dynamics / step_detection / step_response that step() chains, so
//     that the brute-force reference can look at the same positions as the stochastic detector.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "intestine/broad_phase.h"
#include "intestine/collision_response.h"
#include "intestine/mass_spring.h"
#include "intestine/stochastic_collision.h"

namespace surgsim::intestine {

/// Which self-collision detector a step runs (intestine.detector in a scene).
enum class CollisionDetector : std::uint8_t {
  kStochastic = 0,  // the paper's active pairs and random pairs (stochastic_collision.h): finds most contacts
  kBroadPhase = 1,  // the exact box hierarchy (broad_phase.h): the brute-force reference's contacts, every one
};
const char* to_string(CollisionDetector detector);

/// Most nodes a model may have: the bound of a BodyState's positions.
constexpr int kMaxIntestineNodes = 2048;
/// Most probes one step takes: one per instrument of the scene (kMaxInstruments of tool/trajectory.h).
constexpr int kMaxProbes = 4;
/// Most obstacles (other organs' surfaces) one step takes.
constexpr int kMaxObstacles = 8;

/// The nearest point of an obstacle's surface to a query point.
struct ObstacleHit {
  double distance = 0;                                // m, signed: positive on the free side
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, the free side's normal at the nearest point
};

/// A surface the body may not pass: another organ of the scene (the abdominal wall, a rib, the floor). The body rests
/// on it and slides along it without friction: each node whose sphere (the tube's radius on the intestine's row, half
/// the membrane's thickness on the mesentery's) overlaps the surface gets a penalty contact along the surface's normal,
/// linearized in the implicit step as the probe's are. The intestine library knows nothing of what the surface is:
/// the haptic node adapts each organ (haptic_node/organs/).
class Obstacle {
 public:
  virtual ~Obstacle() = default;
  /// Run phase, noexcept, no allocation, deterministic: the surface point nearest `p` among those within
  /// `max_distance` (m); false when there is none.
  virtual bool nearest(const Eigen::Vector3d& p, double max_distance, ObstacleHit& hit) const noexcept = 0;
  /// The same for the body's node `node` at `p` (the step asks this one): an obstacle that solved its contacts with
  /// the body's nodes itself (an organ that yields: the liver) answers by node. Default: nearest(p, ...).
  virtual bool nearest(int node, const Eigen::Vector3d& p, double max_distance, ObstacleHit& hit) const noexcept {
    (void)node;
    return nearest(p, max_distance, hit);
  }
};

struct IntestineParams {
  // Rest shape.
  double length = 4.0;               // m, arc length of the intestine
  double cylinder_radius = 0.15;     // m, the curve lies on this cylinder around the vessel (mesentery width)
  int folds = 5;                     // periods of the folded sine around the cylinder
  double angular_span = 5.65486677646;  // rad (0.9 turn): angle covered around the vessel, < 2 pi keeps the ends apart
  double fold_shape = 1.0;           // 0..2: 0 a plain sine, 1 vertical legs and round crests, 2 legs leaning back
  // The mesentery narrows towards both ends of the intestine (paper section 7): over this fraction of the length at
  // each end (0..0.45; 0: full width everywhere) every row's distance from the vessel is scaled by
  // sin(pi/2 (d + 1/2) / (T + 1/2)), d the column's distance from its end and T = taper (columns - 1): the width
  // would reach zero half a segment past the last mass (7.5 % of cylinder_radius at the end masses with 0.1 and 100
  // columns). The fold curve then runs 4.5 instead of 5 periods (folds - 1/2) so that its two ends lie apart along
  // the vessel instead of side by side, the tapered columns are carried along the vessel beyond the folds' range by
  // mesentery_root_extension() (1 - w) (the ends attach at the two ends of the root, beyond the fan of folds, where
  // no crest's sheet meets the vessel), and the tube lying on its own narrowed mesentery there is not a collision
  // (CollisionTopology::taper_columns).
  double mesentery_taper = 0.0;
  Eigen::Vector3d axis_origin = Eigen::Vector3d::Zero();  // m, centre of the curve on the vessel
  Eigen::Vector3d axis_direction = Eigen::Vector3d::UnitX();  // the vessel (normalized on use)
  int columns = 100;                 // masses along the intestine, >= 4
  int rows = 4;                      // masses across the mesentery (row 0 intestine, last row fixed on the vessel), >= 2
  double intestine_radius = 0.02;    // m
  double mesentery_thickness = 0.01; // m

  // Masses and springs.
  double intestine_node_mass = 0.012;  // kg per intestine node (1.2 kg for 100 nodes)
  double mesentery_node_mass = 0.004;  // kg per mesentery node
  double structural_stiffness = 300;   // N/m, grid edges
  double shear_stiffness = 100;        // N/m, both diagonals of every grid cell
  double bending_stiffness = 30;       // N/m, intestine nodes c and c + 2
  double spring_damping = 0.1;         // N s/m, along every spring
  double drag = 2.0;                   // 1/s, viscous drag of the surrounding medium, f = -drag m v
  Eigen::Vector3d gravity = Eigen::Vector3d(0, 0, -9.81);  // m/s^2
  Integrator integrator = Integrator::kImplicitEuler;

  // Probe (the tool tip as a sphere).
  double probe_stiffness = 300;      // N/m, penalty stiffness of the probe contact
  double probe_force_limit = 8.0;    // N, a probe's force is clamped to this unless the probe gives its own limit
  int probe_capacity = 32;           // simultaneous contacts (elements) of EACH probe, more are counted and ignored

  // Collisions.
  bool self_collisions = true;
  CollisionDetector detector = CollisionDetector::kStochastic;  // which one step() runs (the other is not stepped)
  int segment_exclusion = 2;         // neighbouring segments, never tested (|a - b| <= this)
  int cell_exclusion = 2;            // mesentery cells of the first row within this many columns of a segment
  StochasticParams detection;        // random pairs per step, drop factor, moves, zone budget, capacity, seed
  ResponseParams response;           // iterations
  int contact_capacity = 1024;       // contacts per step (more are counted in StepReport::contacts_overflow)

  // Obstacles (other organs: the wall, the floor, ribs).
  double obstacle_stiffness = 2000;  // N/m, penalty stiffness of a node on an obstacle (a node's weight, 0.08 N,
                                     // sinks 0.04 mm; a 2 N push spread over 10 nodes 0.1 mm)
  int obstacle_capacity = 512;       // node contacts on all obstacles in a step, more are counted and ignored
};

/// The mesentery's width at intestine column `column` as a fraction of cylinder_radius (1 without a taper).
double mesentery_width_factor(const IntestineParams& params, int column);
/// How far beyond the folds' range along the vessel (m) the tapered ends are carried, scaled by 1 - width factor:
/// 4 intestine_radius + mesentery_thickness / 2 (one radius and the half thickness clear the crests' sheets at
/// s = +-amplitude, three radii of margin), 0 without a taper.
double mesentery_root_extension(const IntestineParams& params);
/// Columns at each end inside the taper (0 without one).
int mesentery_taper_columns(const IntestineParams& params);

/// The immutable model: parameters, rest shape, mass-spring system, collision topology.
class IntestineModel {
 public:
  /// Init phase: builds the rest shape and the springs. Throws surgsim::core::Error on parameters out of range.
  explicit IntestineModel(const IntestineParams& params);

  const IntestineParams& params() const { return params_; }
  int rows() const { return params_.rows; }
  int columns() const { return params_.columns; }
  int node_count() const { return params_.rows * params_.columns; }
  int node(int row, int column) const { return row * params_.columns + column; }
  const Eigen::Matrix3Xd& rest() const { return system_.rest(); }  // 3 x N, m
  const MassSpring& mass_spring() const { return system_; }
  const CollisionTopology& topology() const { return topology_; }
  double fold_amplitude() const { return amplitude_; }  // m, along the vessel, found so that the length is right
  double segment_length() const { return segment_length_; }  // m, intestine rest segment

 private:
  static MassSpring build(const IntestineParams& p, double& amplitude, double& segment_length);
  IntestineParams params_;
  double amplitude_ = 0;
  double segment_length_ = 0;
  MassSpring system_;
  CollisionTopology topology_;
};

/// A probe driven by an instrument: a sphere at its tool tip.
struct Probe {
  bool active = false;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // m
  double radius = 0.005;                             // m
  double force_limit = 0;  // N, this probe's clamp (its instrument's device limit); not > 0: params().probe_force_limit
};

enum class StepStatus : std::uint8_t {
  kOk = 0,
  kBadInput,      // non-finite or non-positive dt: nothing was done
  kNonFinite,     // a non-finite value appeared: the state was restored to its value before the step
  kSolverFailed,  // the implicit matrix was not positive definite: state restored
};
const char* to_string(StepStatus status);

/// What one step did for one probe. Plain data.
struct ProbeReport {
  bool rejected = false;            // an active probe with a non-finite centre or radius: ignored
  int contacts = 0;                 // elements it touches
  int overflow = 0;                 // its contacts beyond probe_capacity (ignored)
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // N, on its tool, clamped to its limit (zero on a refused step)
  double force_raw = 0;             // N, magnitude before the clamp
  bool saturated = false;           // force_raw exceeded its limit
};

/// What one step did against one obstacle. Plain data.
struct ObstacleReport {
  int contacts = 0;                                 // nodes on it at the step's start
  double max_depth = 0;                             // m, deepest overlap of a node's sphere with it at the step's start
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  // N, its push on the body over the step (the implicit step's
                                                    // penalty at the step's end positions)
};

/// What one step did. Plain data.
struct StepReport {
  StepStatus status = StepStatus::kOk;
  int probe_count = 0;              // probes the step took: probes[0..probe_count)
  std::array<ProbeReport, kMaxProbes> probes{};
  // Probe 0 (what the one-probe callers read): the same values as probes[0].
  bool probe_rejected = false;      // the probe had a non-finite centre or radius and was ignored
  int probe_contacts = 0;           // elements touched by the probe
  int probe_overflow = 0;           // probe contacts beyond probe_capacity (ignored)
  Eigen::Vector3d probe_force = Eigen::Vector3d::Zero();  // N, on the tool, clamped to the probe's limit
  double probe_force_raw = 0;       // N, magnitude before the clamp
  bool probe_saturated = false;
  DetectStats detection;            // active pairs, new, merged, dropped, distance tests
  int contacts = 0;                 // self-collision contacts processed
  int contacts_overflow = 0;        // contacts beyond contact_capacity (ignored)
  ResponseReport response;          // penetration before / after
  int obstacle_count = 0;           // obstacles the step took
  std::array<ObstacleReport, kMaxObstacles> obstacles{};
  int obstacle_overflow = 0;  // node contacts beyond obstacle_capacity (ignored)
};

/// The mutable state: positions, velocities and every workspace of a step, preallocated for one model.
class IntestineState {
 public:
  /// Init phase (allocates): rest positions, zero velocities, detector seeded with `seed` (params().detection.seed
  /// when 0).
  explicit IntestineState(const IntestineModel& model, std::uint64_t seed = 0);

  /// Back to rest, zero velocity, time 0, detector reseeded. No allocation.
  void reset(const IntestineModel& model, std::uint64_t seed = 0) noexcept;

  Eigen::Matrix3Xd x;  // 3 x N positions (m); column n = node n
  Eigen::Matrix3Xd v;  // 3 x N velocities (m/s)
  double time = 0;     // s, simulated
  std::uint64_t steps = 0;
  std::uint64_t faults = 0;  // steps that ended with a status other than kOk

  /// Flat positions, (x, y, z) of node n at 3n..3n+2; point_count() nodes. The intestine's points come first.
  const double* positions() const { return x.data(); }
  int point_count() const { return static_cast<int>(x.cols()); }

  StochasticDetector& detector() { return detector_; }
  const StochasticDetector& detector() const { return detector_; }
  const ContactList& contacts() const { return contacts_; }
  ContactList& contacts() { return contacts_; }
  const MassSpringWorkspace& workspace() const { return work_; }

 private:
  friend void step_dynamics(const IntestineModel&, IntestineState&, const Probe*, int, double, StepReport&,
                            const Obstacle* const*, int) noexcept;
  friend void step_detection(const IntestineModel&, IntestineState&, StepReport&) noexcept;
  friend void step_response(const IntestineModel&, IntestineState&, StepReport&) noexcept;
  friend void step(const IntestineModel&, IntestineState&, const Probe*, int, double, StepReport&,
                   const Obstacle* const*, int) noexcept;
  MassSpringWorkspace work_;
  StochasticDetector detector_;
  BroadPhaseDetector broad_;
  ContactList contacts_;
  // kMaxProbes x probe_capacity + obstacle_capacity: each step's probes' contacts in order, then the obstacles'
  std::vector<PenaltyContact> probe_contacts_;
  Eigen::Matrix3Xd x_entry_, v_entry_;  // the state at step entry (guard)
};

/// The radius (m) of node `node`'s sphere against obstacles: the tube's on the intestine's row, half the membrane's
/// thickness on the mesentery; 0 for a fixed node (it touches nothing). No allocation.
double obstacle_radius(const IntestineModel& model, int node) noexcept;

/// Run phase: one step of dt (s) at the haptic rate with probes[0..probe_count) (0..kMaxProbes; inactive ones touch
/// nothing): mass-spring (every probe's contacts included), stochastic detection, response. Allocates nothing; on a
/// non-finite result or a failed solve the state is restored, every probe force is zero and report.status says why;
/// a probe_count out of range (or null probes with probe_count > 0) is kBadInput (nothing done).
/// `obstacles[0..obstacle_count)` (0..kMaxObstacles, each non-null) are the surfaces the body rests on; an
/// obstacle_count out of range is kBadInput.
void step(const IntestineModel& model, IntestineState& state, const Probe* probes, int probe_count, double dt,
          StepReport& report, const Obstacle* const* obstacles = nullptr, int obstacle_count = 0) noexcept;
/// One probe: step(model, state, &probe, 1, dt, report).
inline void step(const IntestineModel& model, IntestineState& state, const Probe& probe, double dt,
                 StepReport& report) noexcept {
  step(model, state, &probe, 1, dt, report);
}

/// The phases of step(), in order (report is reset by step_dynamics). For tests and benchmarks.
void step_dynamics(const IntestineModel& model, IntestineState& state, const Probe* probes, int probe_count, double dt,
                   StepReport& report, const Obstacle* const* obstacles = nullptr, int obstacle_count = 0) noexcept;
inline void step_dynamics(const IntestineModel& model, IntestineState& state, const Probe& probe, double dt,
                          StepReport& report) noexcept {
  step_dynamics(model, state, &probe, 1, dt, report);
}
void step_detection(const IntestineModel& model, IntestineState& state, StepReport& report) noexcept;
void step_response(const IntestineModel& model, IntestineState& state, StepReport& report) noexcept;

/// Kinetic + spring + gravity energy (J) of the state.
double energy(const IntestineModel& model, const IntestineState& state);

}  // namespace surgsim::intestine
