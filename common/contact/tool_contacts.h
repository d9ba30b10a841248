// Tool-organ contacts for the liver (paper sections 4-5; docs/DESIGN.md, sections 'Liver: precomputed linear
// elasticity' and 'Collision (liver)'): the quasi non-linear force
// law and the device clamp over one of two contact models (ToolSpec::contact_model).
//
// patch (default): a tool point is a tip of radius r (tool.tip_radius). While it is below the REST surface
// (found by a continuous segment query, or after a reset from the trocar along the shaft, so a tool already inside
// is found again at once) its closest rest point is followed by a local walk (contact/contact_surface.h): a straight
// press keeps its anchor and its depth grows monotonically. Its contact is one scalar constraint along the patch
// normal n over the tip's footprint: w_i the shape functions integrated against the flat punch's pressure over the
// disc of radius r (ContactSurface::footprint, sum 1), and in series the near field the mesh cannot resolve
// (contact/near_field.h):  sum_i w_i n.u_i + dC_n lambda_n = -depth, so the force is that of a tip of radius r on
// any mesh (tool.tip_model nodes: the earlier Wendland weights over the nodes within r, no near field). It is
// solved through the precomputed tensors (compliance/patch_solve.h) with the other points' constraints; unilateral (a
// constraint that would pull is dropped, active set) and frictionless, or with Coulomb friction (tool.friction = mu)
// a sticking 3-D constraint of its patch while |F_t| <= mu F_n that slides along the surface when it would exceed it
// (the stick anchor is moved so that |F_t| = mu F_n). A grasp (jaw closed on a contact) is a bilateral 3-D
// constraint of the patch at its anchor. Continuity in time: a new contact's initial penetration of the (smoothed)
// deformed surface is blended in over kOnsetRamp s (at 0.1 m/s and 1 kHz that is at most 0.1 mm, so slow contacts
// are unchanged; a fast stab no longer jumps to the device limit); a grasp released out of the tissue lets go of
// its hold over kReleaseFade s, one released inside keeps its tangential hold as a friction cone shrinking over the
// same time. The ContactFrame carries one entry per patch node, lambda_i = w_i n lambda (the visual node is
// unchanged); when the union of the patches has more nodes than tool.contact_capacity the smallest weights are left
// out, the rest renormalized, and the tick says over_capacity.
//
// triangle (the paper's model): continuous detection against the deformed surface, each contact displacement
// distributed over the three vertices of its triangle (alpha_v d, all three components), lambda = G_CC^-1 u*.
//
// Several instruments: every tool point of every instrument is a contact of ONE constrained solve (the
// patch rows, or the triangle model's G_CC, of all instruments together), so the mutual-influence correction couples
// them exactly as one direct solve with every constraint would. Instrument t's force is the sum of its own points'
// contact forces, put through the law along its own mean imposed displacement and clamped to its own device limit.
// Each instrument may add at most its own contact_capacity new nodes to the union; the union holds at most
// kMaxContacts (64) nodes. A node shared by two instruments' patches is reported (ContactEntry::instrument) as the
// first one's. An instrument whose input is lost (or whose pose is not finite) drops only its own contacts.
//
// Corotational (scene key liver.deformation, patch model only): the patch solve's compliance is warped by
// the union nodes' rotations, W = R_i G R_j^T (compliance/corotation.h), the rotations recomputed every tick from the
// previous solution's rest-frame response and a background field of every surface node that refresh_rotations()
// (LiverOrgan's 200 Hz thread) hands over lock-free. The onset gap and deformed() stay linear.
//
// Multirate (liver.deformation: multirate, both contact models): after the tick's linear solve, the
// solution's nodes and displacements are handed to a MultirateContacts (attach_multirate();
// nonlinear/multirate_contacts.h) as its tracker's targets, and the forces applied come from its newest snapshot's
// local model f_c + S du (nodes the snapshot does not hold keep the linear lambda); each instrument's force is the sum
// over its own nodes, through the device clamp (no quasi non-linear law: refused in this mode). Without an attached
// MultirateContacts the tick is linear. The solution keeps the applied lambdas, so the ContactFrame carries them and
// deformed() (the onset gap, the triangle model's detection) sees their linear response G lambda.
//
// step() runs the stages of ContactStage in order (each timed: stage_times()), allocates nothing and never returns a
// non-finite force.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "contact/bucket_grid.h"
#include "contact/contact_surface.h"
#include "contact/near_field.h"
#include "compliance/corotation.h"
#include "compliance/patch_solve.h"
#include "mesh/mesh.h"
#include "compliance/superposition.h"
#include "tool/tool.h"
#include "contact/contact_types.h"

namespace surgsim::nonlinear {
class NonlinearLaw;
class MultirateContacts;
}  // namespace surgsim::nonlinear

namespace surgsim::contact {

/// One tool point's contact (fixed capacity, plain data).
struct PointContact {
  bool active = false;  // pushing (or holding) this tick
  bool grasp = false;
  int triangle = -1;
  std::array<int, 3> nodes{{-1, -1, -1}};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();   // m, point of the REST surface the tool point drags (patch:
                                                      // the closest rest point of the tool point)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // outward unit normal there (patch: interpolated vertex normal)
  // --- patch model ---
  bool tracked = false;                               // the point is below the rest surface (depth > 0)
  bool resumed = false;                               // tracked again after a reset with the tool inside: no onset ramp
  double depth = 0;                                   // m below the rest surface along the patch normal
  Eigen::Vector3d facing = Eigen::Vector3d::UnitZ();  // normal where the point entered: the walk keeps to faces
                                                      // within 60 degrees of it
  bool sticking = false;  // friction or a released grasp's fading hold: 3-D constraint at stick_anchor
  int stick_triangle = -1;
  Eigen::Vector3d stick_anchor = Eigen::Vector3d::Zero();
  int grasp_triangle = -1;
  Eigen::Vector3d grasp_anchor = Eigen::Vector3d::Zero();
  double onset_gap = 0;     // m, penetration of the deformed patch when the contact began (blended in)
  double age = 0;           // s since the contact began
  double release_age = -1;  // s since a grasp let go (>= 0 while its hold fades)
  Eigen::Vector3d release_offset = Eigen::Vector3d::Zero();  // m, the grasp's imposed patch displacement then
  double cone_boost = 0;  // extra friction coefficient of a grasp released inside, fading to 0
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // m, imposed patch displacement this tick
  Eigen::Vector3d force = Eigen::Vector3d::Zero();   // N, on the tool from this point (before the law and clamp)
  bool slipping = false;                             // a sticking contact slid this tick (|F_t| = mu F_n)
};

/// A point of another body resting on the organ (the field's bowel on the liver), as its owner found it on the REST
/// surface: a sphere whose nearest rest point lies at barycentric `bary` of the triangle `nodes`, `gap` (m) the signed
/// distance of the sphere's surface from the rest surface along that triangle's outward unit `normal` (negative:
/// overlapping it), `stiffness` (N/m) the sphere's penalty. In the patch model's solve it is one more unilateral
/// row along `normal` on the weighted mean displacement of the three nodes, with the penalty's compliance 1 /
/// stiffness in series: p = stiffness (n . sum_i w_i u_i - gap) when it pushes (p >= 0 the push on the body), solved
/// in ONE system with every instrument's rows, so the organ dents under the body as a direct solve with those forces
/// and the body feels the dented surface at once (no lag between the two). A fixed corner carries its share to the
/// support (its weight stays, its displacement is 0).
struct BodyPoint {
  std::array<int, 3> nodes{{-1, -1, -1}};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double gap = 0;        // m
  double stiffness = 0;  // N/m, > 0
};

/// The solve's answer for one BodyPoint.
struct BodyForce {
  bool solved = false;  // the point had a row in the last solve (false: no room, no free node, no solve: its owner
                        // falls back to its own contact)
  double push = 0;      // N, >= 0: the push on the body along the point's normal (0: not touching)
};

/// The patch of one tool point this tick (patch model).
struct PointPatch {
  int count = 0;
  std::array<int, compliance::kMaxContacts> nodes{};
  std::array<double, compliance::kMaxContacts> weights{};
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  int dropped = 0;  // nodes inside the radius left out (patch capacity or the tick's contact capacity)
  int fixed = 0;    // nodes inside the radius without a constraint (fixed)
  double near_normal = 0;   // m/N, the tip's near field in series with the patch (footprint model), normal row
  double near_tangent = 0;  // m/N, the same for the tangential rows
  // Where the footprint's quadrature points were found last tick (ContactSurface::footprint's `walk`), valid while
  // the patch's centre stays within the tip radius of walk_centre.
  std::array<int, ContactSurface::kFootprintPoints> walk{};
  Eigen::Vector3d walk_centre = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
};

class ToolContacts {
 public:
  static constexpr double kGraspCloseJaw = 0.05;  // rad: at or below, a touching jaw grasps
  static constexpr double kGraspOpenJaw = 0.15;   // rad: above, a grasp lets go (hysteresis)
  static constexpr double kOnsetRamp = 0.02;      // s, a new contact's initial penetration blended in
  static constexpr double kReleaseFade = 0.05;    // s, a released grasp's hold fades out
  static constexpr double kDefaultDt = 1e-3;      // s, tick length when the caller gives none

  static constexpr int kMaxPoints = tool::kMaxInstruments * tool::kMaxShaftPoints;  // tool points of all instruments

  /// Init (allocates). `tensors` must hold the "haptic" block; all references must outlive this object. `tools`:
  /// the instruments (1..kMaxInstruments, one contact model: the first's).
  /// `deformation` kCorotational (patch model only; throws otherwise) warps the compliance by per-node rotations
  /// (compliance/corotation.h): the contact nodes' rotations are recomputed every tick from the previous solution and a
  /// field of every surface node refreshed by refresh_rotations(), which the owner calls off the loop thread.
  ToolContacts(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface, const compliance::Tensors& tensors,
               const std::vector<tool::ToolSpec>& tools, const nonlinear::NonlinearLaw* law = nullptr,
               compliance::LiverDeformation deformation = compliance::LiverDeformation::kLinear);
  /// One instrument.
  ToolContacts(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface, const compliance::Tensors& tensors,
               const tool::ToolSpec& tool, const nonlinear::NonlinearLaw* law = nullptr)
      : ToolContacts(mesh, surface, tensors, std::vector<tool::ToolSpec>{tool}, law) {}

  /// One haptic tick of `dt` s for `count` instruments (at most instruments()): inputs[t].tool is instrument t's
  /// geometry (null: its input is lost, its contacts are dropped), inputs[t].jaw its jaw opening (rad); out[t] its
  /// force. noexcept, no allocation.
  void step(const InstrumentInput* inputs, int count, ContactTick* out, double dt = kDefaultDt) noexcept;
  /// One instrument (instrument 0).
  void step(const tool::ToolGeometry& geometry, double jaw, ContactTick& out, double dt = kDefaultDt) noexcept {
    const InstrumentInput in{&geometry, jaw};
    step(&in, 1, &out, dt);
  }
  /// Bodies resting on the organ for the NEXT step() only (patch model, linear or corotational; with any other
  /// model, or multirate, no point is solved): at most kMaxBodyPoints, the rest counted in body_overflow(). They come
  /// after every instrument's points in the union of nodes, which they may fill up to kMaxContacts nodes (the
  /// instruments' own contact capacities bound theirs). No allocation.
  static constexpr int kMaxBodyPoints = 96;
  /// Contact entries of nodes only bodies load carry this instrument index (ContactEntry::instrument).
  static constexpr int kBodyInstrument = tool::kMaxInstruments;
  void set_bodies(const BodyPoint* points, int count) noexcept;
  /// The last step()'s answer for body point j of the set_bodies() before it.
  int body_count() const { return body_results_; }
  const BodyForce& body_force(int j) const { return body_force_[static_cast<std::size_t>(j)]; }
  /// Body point j as the last step() was given it.
  const BodyPoint& body(int j) const { return bodies_[static_cast<std::size_t>(j)]; }
  /// Body points given past kMaxBodyPoints, or left out of a solve for the contact capacity, since construction.
  long body_overflow() const { return body_overflow_; }
  /// The push on the organ's side of body points in the last step: sum over solved points of -push n (N).
  const Eigen::Vector3d& body_load() const { return body_load_; }

  /// Corotational only (else nothing): the rest-frame response u~_n = sum_l G(n, k_l) R_l^T lambda_l of every row
  /// of the haptic block under the newest solution step() published, then the rotation of every surface node from
  /// it, published back to step() (lock-free, latest value). Call it from ONE thread other than step()'s at >= 100
  /// Hz (LiverOrgan runs it at 200 Hz), or between steps in tests. No allocation.
  void refresh_rotations() noexcept;
  compliance::LiverDeformation deformation() const { return deformation_; }
  /// Multirate: the non-linear side this object hands its solutions to and takes its forces from (must outlive it;
  /// null: linear). Init only.
  void attach_multirate(nonlinear::MultirateContacts* multirate) { multirate_ = multirate; }
  nonlinear::MultirateContacts* multirate() const { return multirate_; }
  /// The loop's rotations (corotational; null otherwise): the contact nodes' are those of the last step().
  const compliance::NodeRotations* rotations() const { return rotations_.get(); }
  /// Drops every contact of every instrument and forgets the previous tool positions.
  void reset() noexcept;
  /// Drops instrument t's contacts (its input is lost) and forgets its previous position.
  void reset_instrument(int t) noexcept;

  int instruments() const { return static_cast<int>(tools_.size()); }
  const compliance::ContactSolution& solution() const { return solution_; }
  /// The tensors' superposition the solutions are read through (solution_displacement).
  const compliance::Superposition& superposition() const { return superposition_; }
  /// The instrument whose contact holds solution node l (the first, when shared).
  int node_instrument(int l) const { return node_instrument_[static_cast<std::size_t>(l)]; }
  /// Solution nodes held by instrument t this tick.
  int instrument_nodes(int t) const { return instrument_nodes_[static_cast<std::size_t>(t)]; }
  /// The constrained solve's status in the last step() (kOk when it had nothing to solve).
  compliance::ContactStatus status() const { return status_; }
  /// Tool point i of instrument t (tip first).
  const PointContact& point(int i, int t = 0) const {
    return points_[static_cast<std::size_t>(t * tool::kMaxShaftPoints + i)];
  }
  /// Patch of tool point i of instrument t in the last step (patch model; count 0 without one).
  const PointPatch& patch(int i, int t = 0) const {
    return patches_[static_cast<std::size_t>(t * tool::kMaxShaftPoints + i)];
  }
  /// Tip radius in use (m; patch model).
  double tip_radius() const { return radius_; }
  const tool::ToolSpec& tool(int t = 0) const { return tools_[static_cast<std::size_t>(t)]; }
  /// Patch nodes left out for the contact capacity since construction.
  long dropped_nodes() const { return dropped_nodes_; }
  const BucketGrid& grid() const { return grid_; }
  /// Corrected constraint u~_l = G_{k_l k_l} lambda_l of solution node l (m).
  Eigen::Vector3d corrected(int l) const noexcept;
  /// Deformed position of a surface node under the current solution (rest for nodes without a column).
  Eigen::Vector3d deformed(int node) const noexcept;
  /// Displacement (m) of `node` under the current solution (false: the tensors cannot give it).
  bool solution_displacement(int node, Eigen::Vector3d& u) const noexcept;
  /// The time each stage of the last step() took (all 0 unless time_stages(true): off, step() reads no clock).
  const ContactStageTimes& stage_times() const noexcept { return stage_times_; }
  /// Init: whether step() times its stages (haptic_node --tick-trace).
  void time_stages(bool on) noexcept { time_stages_ = on; }

 private:
  static void deformed_cb(const void* self, int node, Eigen::Vector3d& out);
  void step_triangle(double dt, ContactTick* out) noexcept;
  /// The patch model's step: its stages in order (ContactStage), each a function.
  void step_patch(double dt, ContactTick* out) noexcept;
  void track_points() noexcept;
  void build_patches(double dt, ContactTick* out) noexcept;
  bool solve_active_set(double dt, ContactTick* out) noexcept;
  void apply_friction() noexcept;
  void distribute_forces(double dt, ContactTick* out) noexcept;
  template <class F>
  void each_point(F&& f);
  /// Force on the organ from patch p of the last solve (N), and its rows switched off.
  Eigen::Vector3d patch_force(int p_index) const noexcept;
  void disable_patch(int p_index) noexcept;
  void track(const tool::ToolGeometry& geometry, int i, int g, bool resume) noexcept;
  /// Instrument t's force from its contacts: the law along dir_sum, the clamp to its device limit.
  void finish(int t, Eigen::Vector3d force, const Eigen::Vector3d& dir_sum, ContactTick& out) noexcept;
  /// A failed solve: every instrument's force zero, the solution empty.
  void drop_solution() noexcept;
  /// instrument_nodes_ from node_instrument_.
  void count_instrument_nodes() noexcept;

  const mesh::TetMesh& mesh_;
  const compliance::Tensors& tensors_;
  const compliance::TensorBlock& haptic_;
  std::vector<tool::ToolSpec> tools_;
  tool::ContactModel model_ = tool::ContactModel::kPatch;
  const nonlinear::NonlinearLaw* law_;
  BucketGrid grid_;
  compliance::Superposition superposition_;
  compliance::ContactSolution solution_;
  compliance::ContactStatus status_ = compliance::ContactStatus::kOk;
  // This tick's instruments (step() sets them; null geometry: not stepped this tick).
  int count_ = 0;
  std::array<const tool::ToolGeometry*, tool::kMaxInstruments> geometry_{};
  std::array<double, tool::kMaxInstruments> jaw_{};
  // Tool points of all instruments: instrument t's point i is index t * kMaxShaftPoints + i.
  std::array<PointContact, kMaxPoints> points_{};
  std::array<Eigen::Vector3d, kMaxPoints> previous_{};
  std::array<bool, tool::kMaxInstruments> have_previous_{};
  std::array<compliance::Contact, 3 * kMaxPoints> requests_{};
  std::array<int, 3 * kMaxPoints> request_instrument_{};
  std::array<int, compliance::kMaxContacts> node_instrument_{};  // per solution node
  std::array<int, tool::kMaxInstruments> instrument_nodes_{};    // solution nodes per instrument
  // --- patch model ---
  double radius_ = 0;
  tool::TipModel tip_model_ = tool::TipModel::kFootprint;
  std::unique_ptr<ContactSurface> surface_;
  std::unique_ptr<NearField> near_field_;  // footprint model
  std::unique_ptr<compliance::PatchSolver> patch_solver_;
  std::unique_ptr<compliance::PatchConstraints> constraints_;
  std::array<PointPatch, kMaxPoints> patches_{};
  std::array<int, kMaxPoints> patch_of_point_{};                  // index in constraints_ (-1: none)
  std::array<int, kMaxPoints> kind_{};                            // 0 none, 1 slide, 2 stick, 3 grasp, 4 fading grasp
  std::array<int, compliance::kMaxContacts> union_instrument_{};  // instrument that added union node u
  std::array<double, compliance::kMaxPatchRows> b_{}, mu_{};
  std::array<unsigned char, compliance::kMaxPatchRows> enabled_{};
  std::array<Eigen::Vector3d, compliance::kMaxContacts> lambda_{};
  std::array<Eigen::Vector3d, compliance::kMaxContacts> union_u_{};  // displacement of each union node (m)
  long dropped_nodes_ = 0;
  ContactStageTimes stage_times_{};
  bool time_stages_ = false;
  // --- corotational ---
  struct RotationInput {  // loop -> refresh_rotations(): the last solution's forces (world frame)
    int count = 0;
    std::array<int, compliance::kMaxContacts> nodes{};
    std::array<Eigen::Vector3d, compliance::kMaxContacts> lambda{};
  };
  struct RotationField {  // refresh_rotations() -> loop: every node's rest-frame displacement and rotation
    bool valid = false;
    Eigen::MatrixX3d u;                 // #V x 3, m: G R^T lambda (rest frame)
    std::vector<Eigen::Quaterniond> q;  // #V
  };
  /// The union nodes' rotations for this tick (from the previous solution and the background field).
  void rotate_union(const compliance::PatchConstraints& k) noexcept;
  /// solution_index_ and the worker's input from the new solution.
  void publish_solution() noexcept;
  compliance::LiverDeformation deformation_ = compliance::LiverDeformation::kLinear;
  std::unique_ptr<compliance::NodeRotations> rotations_;  // loop thread
  std::array<Eigen::Matrix3d, compliance::kMaxContacts> union_rotation_{};
  std::vector<int> solution_index_;  // #V: index in solution_ of the last step, or -1
  std::array<int, compliance::kMaxContacts> indexed_nodes_{};
  std::array<Eigen::Vector3d, compliance::kMaxContacts> rest_displacement_{};  // R_n^T u_n of the last solution's nodes
  int indexed_count_ = 0;
  concurrency::TripleBuffer<RotationInput> to_worker_;
  concurrency::TripleBuffer<RotationField> from_worker_;
  std::unique_ptr<compliance::NodeRotations> worker_rotations_;  // refresh_rotations()' thread
  Eigen::MatrixX3d worker_u_;
  std::array<Eigen::Vector3d, compliance::kMaxContacts> worker_rest_lambda_{};
  // --- bodies resting on the organ (set_bodies) ---
  /// Their patches and rows, after the instruments' (build_patches).
  void add_body_rows() noexcept;
  std::array<BodyPoint, kMaxBodyPoints> bodies_{};
  std::array<BodyForce, kMaxBodyPoints> body_force_{};
  std::array<int, kMaxBodyPoints> body_row_{};  // row of body point j in constraints_ (-1: none)
  int body_count_ = 0;                          // set_bodies() for the next step
  int body_results_ = 0;                        // body_force_ entries of the last step
  long body_overflow_ = 0;
  Eigen::Vector3d body_load_ = Eigen::Vector3d::Zero();
  // --- multirate ---
  nonlinear::MultirateContacts* multirate_ = nullptr;
};

}  // namespace surgsim::contact
