// An exact broad phase for the intestine's self-collisions: what a user would pick instead of the stochastic
// detector (stochastic_collision.h) when every contact must be found. The topology never changes, so the hierarchy
// is fixed and only refitted each step (as cloth simulators do): every intestine segment's bounding box (grown by the
// tube radius) and every mesentery cell's (its four corners, grown by the half thickness), then the boxes of blocks of
// kBlock consecutive segments and of kBlock consecutive cells along a mesentery row. Block pairs whose boxes overlap
// open their element pairs; element pairs whose boxes overlap go to the reference's exact narrow phase
// (segment_contact, triangle_contact for both triangles of the cell: segment-segment, and segment-triangle with the
// point-triangle, edge-triangle and crossing cases). Mesentery-mesentery pairs are not tested, as in the reference.
//
// Why not sweep and prune: the folded intestine and its mesentery fill one box of ~0.3 m a side, and a segment's
// grown extent along any axis covers a quarter of it, so a sweep along one axis visits ~15 000 element pairs a step to
// find the ~500 that overlap on all three (measured: the sweep took more than half of the detector's 200 us). The
// hierarchy tests ~2 000 block pairs and ~5 000 element pairs, each a few comparisons on contiguous boxes.
//
// A block pair whose boxes overlap but whose element pairs all sleep sleeps as a whole for the smallest of their
// slacks (so a body that has not moved is not looked at again), and a contact is built from the exact test's own
// distance (segment_contact_at, triangle_contact_at) rather than from a second one.
//
// The contacts are those of detect_brute_force (same elements, same values), in another order: recall 1 by
// construction. Construction allocates; detect() allocates nothing and is deterministic.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "intestine/collision_response.h"
#include "intestine/stochastic_collision.h"

namespace surgsim::intestine {

struct BroadPhaseStats {
  long overlaps = 0;   // element pairs (segment-segment, segment-cell) whose grown boxes overlap (tested pairs only)
  long asleep = 0;     // element pairs not looked at: provably still out of contact since their last test
  int contacts = 0;    // contacts written
  int overflow = 0;    // contacts refused by the list
};

class BroadPhaseDetector {
 public:
  static constexpr int kBlock = 4;  // elements per block of the hierarchy

  /// Init phase (allocates; throws surgsim::core::Error on a bad topology).
  explicit BroadPhaseDetector(CollisionTopology topology);

  const CollisionTopology& topology() const { return topo_; }

  /// Every tested element pair closer than the sum of the radii + margin (m), appended to `out` (not cleared): the
  /// contacts of detect_brute_force(topology(), x, out, margin). Successive calls are taken as successive positions
  /// of one body (pairs far apart sleep while its nodes move less than their gap). No allocation.
  BroadPhaseStats detect(const Eigen::Matrix3Xd& x, ContactList& out, double margin = 0) noexcept;
  /// Forgets the previous positions (every pair is tested on the next call). No allocation.
  void reset() noexcept { have_prev_ = false; }

 private:
  struct Box {
    double lo[3], hi[3];  // m
  };
  CollisionTopology topo_;
  int nseg_ = 0, ncell_ = 0, cw_ = 0;         // segments, cells, cells per mesentery row
  std::vector<int> seg_node_;                 // 2 per segment
  std::vector<int> cell_node_;                // 4 per cell: (r, c) (r, c + 1) (r + 1, c + 1) (r + 1, c)
  std::vector<char> cell_ok_;                 // segments x cells: topology().cell_tested
  std::vector<Box> seg_box_, cell_box_;       // grown element boxes
  // Per step, for the cheap rejections before the exact test: segment middle and half length; cell centroid and
  // farthest-corner radius; a triangle's separating axes (its normal and the outward normals of its three side
  // planes, unnormalized, with their offsets and squared lengths), computed when first needed in the step
  // (tri_stamp_ == stamp_).
  struct TriangleAxes {
    double axis[4][3];   // normal, then edge k's outward side normal (edge k from corner k to corner k + 1)
    double offset[4];    // axis . a corner on it
    double length2[4];   // |axis|^2
  };
  std::vector<Eigen::Vector4d> seg_sphere_, cell_sphere_;
  std::vector<TriangleAxes> tri_axes_;
  std::vector<unsigned> tri_stamp_;
  // Temporal coherence: travel_ of an element is the sum over the steps of its largest node displacement; an element
  // pair found farther than the contact distance by a gap g sleeps (is not looked at) until the travel of its two
  // elements since then exceeds g (a distance between them changes by at most their nodes' displacements). wake_ holds
  // travel(a) + travel(b) + g at the pair's last test, per segment pair (segments x segments) and segment-cell pair
  // (segments x cells, after them). Reset on the first step and whenever the margin changes.
  Eigen::Matrix3Xd x_prev_;
  bool have_prev_ = false;
  double last_margin_ = 0;
  std::vector<double> travel_;   // segments, then cells
  std::vector<float> wake_;       // float (half the cache), rounded down: a pair may wake early, never late
  // The same for blocks (their largest element displacement per step): segment blocks, then cell blocks; block pairs
  // segment block x (segment blocks, then cell blocks).
  std::vector<double> step_move_;  // this step's displacement of each element (segments, then cells)
  std::vector<double> block_travel_;
  std::vector<double> block_wake_;
  unsigned stamp_ = 0;
  std::vector<Box> seg_block_, cell_block_;   // block boxes; cell blocks row by row
  std::vector<int> cell_block_first_, cell_block_end_;  // cells of each cell block
};

}  // namespace surgsim::intestine
