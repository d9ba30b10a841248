// Stochastic self-collision detection for the intestine and its mesentery (Raghupathi et al. 2004, section 4;
// docs/DESIGN.md, section 'Intestine: mass-spring + stochastic collisions'), and the brute-force reference.
//
// Elements: the intestine is a chain of segments (capsules of radius r_i); the mesentery is a grid of quads
// ("cells"), each split into two triangles, of half-thickness r_m. Row 0 of the grid is the intestine's chain.
//
// The detector keeps "active pairs" that track local minima of the distance between elements:
//   - intestine-intestine pairs (a, b) of non-neighbouring segments (|a - b| > segment_exclusion): each step a pair
//     moves to the closest of the 9 pairs (a + {-1,0,1}, b + {-1,0,1}) until none is closer (the 9-neighbour update,
//     at most max_moves moves per step);
//   - intestine-mesentery pairs (segment s, cell c): two-step convergence, first along the intestine with the cell
//     fixed (s +- 1), then over the mesentery with the segment fixed (the 8 cells around c), repeated until neither
//     step moves; the segment-cell distance uses point-triangle and edge-triangle tests (segment ends against the
//     triangle, segment against the triangle's edges, and the segment crossing the triangle);
//   - pairs that converge to the same minimum are merged (one survives), pairs farther apart than drop_factor times
//     the sum of their radii are dropped, and n new random pairs of each kind are drawn per step from a seeded
//     generator and given new_pair_moves moves before the drop test;
//   - mesentery-mesentery collisions are not tested, as in the paper: the membrane is thin, its folds are held apart
//     by the intestine they carry, and its pairs would outnumber all the others.
// A pair whose distance is below the sum of the radii is reported as a CollisionContact. Where two tubes lie
// side by side the distance has a long flat valley rather than one minimum, and the tracked pairs slide to its
// deepest point and merge there: the response would then push one pair of the zone while the rest sinks. So each
// colliding minimum also reports its contact zone: the colliding pairs reached from it through neighbouring pairs
// (the same 9 / 10 neighbourhoods as the update), at most zone_budget of them, each contact once per step.
// zone_budget = 0 reports the minima alone, as the paper does.
//
// Speed (the result is bit-identical to running every step in full): the element tables (segment and triangle
// nodes, which segment-cell pairs are tested) are built once; each step caches every segment's and triangle's bounding
// sphere and every node's displacement since the last step. A candidate whose bounding spheres are already farther
// than the distance to beat is rejected without the exact test (and its lower bound is kept). A tracked pair that
// converged keeps its margin (how much closer than every neighbour it was); while the nodes around it have moved
// less than that margin allows (the distances are 1-Lipschitz in the node positions), it is still the local minimum
// and only its own distance is evaluated. Those steps give the same pairs and contacts as converging in full. Two
// further savings change which pairs are tracked, not the contacts of a step's reach: a pair whose whole
// neighbourhood was out of contact by a gap waits, unevaluated and unmoved, until the displacement of the nodes
// around it could have closed the gap; a new random pair is not converged when every pair its moves could reach is
// farther than the drop distance (it would be dropped). Every pair is evaluated at most once a step (a memo shared
// by the convergence and the contact zones).
// Measured (intestine_bench --quick, 2 cores): detection p50 about 110 us, p99 about 170 us of thread CPU at n = 10,
// from 344 / 426; the exact broad phase (broad_phase.h, every contact) about 55 / 100-170 us live (table 1) and
// 70 / 210-260 in table 3b (run between the other two, caches cold), the brute force about 800 / 900 us. The
// scene's intestine.detector chooses which one the haptic step runs.
//
// Phases: construction allocates (pair arrays, the merge tables); detect() allocates nothing and is deterministic for
// a given seed and input. detect_brute_force() tests every element pair (with a bounding-box cull): the reference
// for recall, O(n^2), not for the loop.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <vector>

#include "intestine/collision_response.h"

namespace surgsim::intestine {

/// Which nodes form the intestine and the mesentery, and the radii.
struct CollisionTopology {
  int rows = 0;                  // mesentery grid rows (row 0: the intestine, last row: the vessel)
  int cols = 0;                  // grid columns = intestine nodes; segments = cols - 1
  std::vector<int> grid;         // rows x cols node indices, row-major: node(r, c) = grid[r cols + c]
  double intestine_radius = 0.02;             // m
  double mesentery_half_thickness = 0.005;    // m
  int segment_exclusion = 2;     // segments a, b with |a - b| <= this are neighbours and never tested
  int cell_exclusion = 2;        // cells of grid row 0 within this many columns of a segment are never tested
  int taper_columns = 0;         // columns at each end where the mesentery narrows: there cells of EVERY row within
                                 // cell_exclusion columns of a segment are never tested (the tube lies on them)

  int segments() const { return cols - 1; }
  int cells() const { return (rows - 1) * (cols - 1); }
  int node(int r, int c) const { return grid[static_cast<std::size_t>(r * cols + c)]; }
  /// Nodes of triangle t (0..2 cells - 1) of cell t / 2.
  void triangle(int t, int out[3]) const;
  bool segments_tested(int a, int b) const;  // non-neighbouring, both valid
  bool cell_tested(int segment, int cell) const;
  /// cell_tested for every pair, segments x cells, row-major (init phase: allocates).
  std::vector<char> cell_tested_table() const;
};

struct StochasticParams {
  int random_pairs = 10;             // new intestine-intestine pairs drawn per step (the paper's n)
  int random_mesentery_pairs = 10;   // new intestine-mesentery pairs drawn per step
  double drop_factor = 2.0;          // a pair farther apart than drop_factor x (sum of its radii) is dropped
  int max_moves = 4;                 // local-minimum moves per tracked pair per step
  int new_pair_moves = 4;            // moves a new random pair may make before the drop test
  int zone_budget = 32;              // contacts a minimum may add from its contact zone (0: the minimum alone)
  int capacity = 512;                // active pairs of each kind
  std::uint64_t seed = 1;
};

/// An active pair and what its last evaluation found.
struct ActivePair {
  int a = 0;            // segment
  int b = 0;            // segment (intestine-intestine) or mesentery cell (intestine-mesentery)
  int tri = 0;          // intestine-mesentery: the cell's closer triangle (0 or 1)
  double distance = 0;  // m, between the element axes / mid-surfaces
  double s = 0;         // parameter of the closest point on segment a
  Eigen::Vector3d wb = Eigen::Vector3d::Zero();  // closest point on b: (1 - t, t, 0) or triangle barycentrics
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit, from b to a (kept when the distance vanishes)
};

struct DetectStats {
  int segment_pairs = 0;     // active intestine-intestine pairs after the step
  int cell_pairs = 0;        // active intestine-mesentery pairs after the step
  int new_pairs = 0;         // random pairs that survived their first convergence
  int merged = 0;            // pairs merged into another one
  int dropped = 0;           // pairs dropped above the drop distance
  int contacts = 0;          // contacts written
  int overflow = 0;          // pairs or contacts refused for lack of capacity
  long distance_tests = 0;   // element-element distance evaluations (exact tests and bounding-sphere rejections)
  int settled = 0;           // tracked pairs provably still at their minimum: neighbours not re-tested
};

/// Closest points of segments [p0, p1] and [q0, q1]: returns the distance, s and t the parameters (Ericson 5.1.9).
double segment_segment(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                       const Eigen::Vector3d& q1, double& s, double& t) noexcept;

/// Closest points of segment [p0, p1] and triangle (a, b, c): returns the distance, s the segment parameter, bary the
/// triangle's barycentrics. 0 when the segment crosses the triangle. With a finite `bound`, returns +infinity
/// (s, bary unset) as soon as a cheap lower bound (bounding spheres, then the triangle's plane) shows the distance
/// is at least `bound`.
double segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                        const Eigen::Vector3d& b, const Eigen::Vector3d& c, double& s, Eigen::Vector3d& bary,
                        double bound = std::numeric_limits<double>::infinity()) noexcept;

class StochasticDetector {
 public:
  /// Init phase (allocates; throws surgsim::core::Error on a bad topology or parameters).
  StochasticDetector(CollisionTopology topology, const StochasticParams& params);

  const CollisionTopology& topology() const { return topo_; }
  const StochasticParams& params() const { return params_; }
  /// Changes the number of random pairs drawn per step (benchmarks). No allocation.
  void set_random_pairs(int segment_pairs, int mesentery_pairs) noexcept;

  /// Forgets every active pair and reseeds the generator. No allocation.
  void reset(std::uint64_t seed) noexcept;

  /// Run phase: updates the active pairs at positions x (3 x N) and appends a contact to `out` (not cleared) for
  /// each pair closer than the sum of the radii. No allocation.
  DetectStats detect(const Eigen::Matrix3Xd& x, ContactList& out) noexcept;

  int segment_pair_count() const { return seg_count_; }
  int cell_pair_count() const { return cell_count_; }
  const ActivePair& segment_pair(int i) const { return seg_pairs_[static_cast<std::size_t>(i)]; }
  const ActivePair& cell_pair(int i) const { return cell_pairs_[static_cast<std::size_t>(i)]; }
  /// Adds a pair by hand (tests): segments a, b, or segment a and cell b when `mesentery`. False if refused.
  bool add_pair(int a, int b, bool mesentery) noexcept;

 private:
  std::uint64_t next_random() noexcept;
  int uniform(int n) noexcept;
  // The distance of a pair, or a lower bound >= `bound` when it is not closer (out then unused); remembered for the
  // step, so that converging pairs and contact zones that meet evaluate each pair once.
  double eval_segments(const Eigen::Matrix3Xd& x, int a, int b, double bound, ActivePair& out) noexcept;
  double eval_cell(const Eigen::Matrix3Xd& x, int s, int cell, double bound, ActivePair& out) noexcept;
  double eval(const Eigen::Matrix3Xd& x, bool mesentery, int a, int b, double bound, ActivePair& out) noexcept;
  double compute_segments(const Eigen::Matrix3Xd& x, int a, int b, double bound, ActivePair& out) noexcept;
  double compute_cell(const Eigen::Matrix3Xd& x, int s, int cell, double bound, ActivePair& out) noexcept;
  // Converge p (at most `moves` moves); returns the margin of the minimum reached (a lower bound of how much farther
  // every neighbour is), or -infinity when the moves ran out first.
  double converge_segments(const Eigen::Matrix3Xd& x, ActivePair& p, int moves) noexcept;
  double converge_cell(const Eigen::Matrix3Xd& x, ActivePair& p, int moves) noexcept;
  void cache_step(const Eigen::Matrix3Xd& x) noexcept;
  void clear_tables() noexcept;  // every stamp table to 0
  // True when every pair that `moves` moves can reach from (a, b) is farther than `drop` (bounding spheres).
  bool beyond_reach(bool mesentery, int a, int b, int moves, double drop) const noexcept;
  bool cell_ok(int seg, int cell) const noexcept {
    return seg >= 0 && seg < nseg_ && cell >= 0 && cell < ncell_ &&
           cell_ok_[static_cast<std::size_t>(seg) * static_cast<std::size_t>(ncell_) + static_cast<std::size_t>(cell)];
  }
  bool claim(std::vector<std::uint32_t>& owner, int key) noexcept;
  bool emit(const ActivePair& p, bool mesentery, ContactList& out, DetectStats& st) noexcept;
  void expand(const Eigen::Matrix3Xd& x, const ActivePair& p, bool mesentery, ContactList& out,
              DetectStats& st) noexcept;

  CollisionTopology topo_;
  StochasticParams params_;
  std::uint64_t rng_ = 0;
  std::vector<ActivePair> seg_pairs_;
  std::vector<ActivePair> cell_pairs_;
  int seg_count_ = 0;
  int cell_count_ = 0;
  // Merge tables: owner[key] == stamp_ when a pair already sits on that key this step.
  std::vector<std::uint32_t> seg_owner_;   // segments x segments
  std::vector<std::uint32_t> cell_owner_;  // segments x cells
  std::vector<std::uint32_t> seg_reported_;   // contacts already reported this step (same keys)
  std::vector<std::uint32_t> cell_reported_;
  // The step's evaluations: memo_stamp == stamp_ when memo_pool_[memo_index] holds the pair's result.
  struct Memo {
    ActivePair pair;
    double value = 0;    // distance, or a lower bound when !exact
    bool exact = false;
  };
  std::vector<std::uint32_t> seg_memo_stamp_, cell_memo_stamp_, seg_memo_index_, cell_memo_index_;
  std::vector<Memo> memo_pool_;
  int memo_used_ = 0;
  std::vector<std::uint32_t> seg_clear_;   // pairs expand() evaluated this step and found out of contact
  std::vector<std::uint32_t> cell_clear_;
  std::vector<ActivePair> zone_;  // flood-fill queue of expand(), zone_budget + 1 entries
  // Element tables (construction) and the per-step caches of cache_step().
  int nseg_ = 0, ncell_ = 0, nodes_ = 0;
  std::vector<int> seg_node_;           // 2 per segment
  std::vector<int> tri_node_;           // 3 per triangle
  std::vector<char> cell_ok_;           // segments x cells: topology().cell_tested
  std::vector<Eigen::Vector4d> seg_sphere_;   // centre, radius per segment
  std::vector<Eigen::Vector4d> tri_sphere_;   // per triangle
  std::vector<Eigen::Vector4d> cell_sphere_;  // per cell (both triangles)
  Eigen::Matrix3Xd x_prev_;                  // positions at the last detect()
  bool have_prev_ = false;
  // Displacement since the last step: node_move_ squared (m^2), an element's its largest node's (m).
  std::vector<double> node_move_, seg_move_, cell_move_;
  std::vector<double> seg_near_move_, cell_near_move_;    // the largest over the element and its neighbours
  std::vector<double> seg_margin_, cell_margin_;          // per active pair: margin left of its last convergence
  std::vector<double> seg_gap_, cell_gap_;                // per active pair: how far its neighbourhood is from contact
  std::uint32_t stamp_ = 0;
  long tests_ = 0;
};

/// Detection quality of `found` against the reference `truth` (both from the same positions), the paper's fig. 14 as
/// numbers. A contact is identified by its elements (segment pair, or segment and mesentery cell); depth_recall
/// weighs each by its penetration (radius sum - distance), the part that matters to the response. A contact zone
/// ("region") is a set of reference contacts joined through neighbouring elements (segments +-1, cells of the 8
/// around); it counts as found when any of its contacts is. Allocates: tests and benchmarks only.
struct RecallStats {
  long truth = 0, found = 0;            // reference contacts, and those the detector reported
  double depth_truth = 0;               // m, sum of the reference contacts' penetrations
  double depth_found = 0;               // m, the same over the reported ones
  double max_missed = 0;                // m, deepest reference contact the detector missed
  long regions = 0, regions_found = 0;  // contact zones
  double pair_recall() const { return truth ? static_cast<double>(found) / truth : 1.0; }
  double depth_recall() const { return depth_truth > 0 ? depth_found / depth_truth : 1.0; }
  double region_recall() const { return regions ? static_cast<double>(regions_found) / regions : 1.0; }
  RecallStats& operator+=(const RecallStats& o);
};
RecallStats compare_with_reference(const CollisionTopology& topology, const ContactList& found,
                                   const ContactList& truth);

/// The exact narrow phase of the reference (and of BroadPhaseDetector): the contact of segments a < b, or of segment a
/// and mesentery triangle tri, when closer than the sum of the radii + margin; false (c unset) otherwise. Does not
/// check that the pair is tested (CollisionTopology::segments_tested / cell_tested).
bool segment_contact(const CollisionTopology& topology, const Eigen::Matrix3Xd& x, int a, int b, double margin,
                     CollisionContact& c) noexcept;
/// triangle_contact culls with the bounds of segment_triangle first; with cull = false it goes straight to the exact
/// distance (for a caller that culled already: the same contact whenever the pair is closer than the bound).
bool triangle_contact(const CollisionTopology& topology, const Eigen::Matrix3Xd& x, int a, int tri, double margin,
                      CollisionContact& c, bool cull = true) noexcept;

/// The contacts segment_contact and triangle_contact build, from the distance and closest-point parameters the caller
/// got from segment_segment / segment_triangle on the same positions (a pair already found closer than the bound):
/// the same contact without a second exact test (BroadPhaseDetector).
void segment_contact_at(const CollisionTopology& topology, const Eigen::Matrix3Xd& x, int a, int b, double d, double s,
                        double t, CollisionContact& c) noexcept;
void triangle_contact_at(const CollisionTopology& topology, const Eigen::Matrix3Xd& x, int a, int tri, double d,
                         double s, const Eigen::Vector3d& bary, CollisionContact& c) noexcept;

/// Reference: every tested element pair closer than the sum of the radii + margin (m), appended to `out`.
/// No allocation; O(segments^2 + segments x cells) with a bounding-box cull.
void detect_brute_force(const CollisionTopology& topology, const Eigen::Matrix3Xd& x, ContactList& out,
                        double margin = 0) noexcept;

}  // namespace surgsim::intestine
