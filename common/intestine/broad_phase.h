// An exact broad phase for the intestine's self-collisions: what a user would pick instead of the stochastic
// detector (stochastic_collision.h) when every contact must be found. Sweep and prune: each step every intestine
// segment's bounding box (grown by the tube radius) and every mesentery triangle's (grown by the half thickness) is
// sorted along the axis over which the elements spread most (insertion sort from the last step's order, which is
// nearly sorted when the body moves little), segments and triangles each in their own list; each segment is swept
// forward over the segments and the triangles that start inside its extent, each triangle over the segments that
// start inside its own (so every overlapping pair once, and no triangle-triangle pair is ever looked at), and the
// pairs whose boxes also overlap on the two other axes go to the reference's exact
// narrow phase (segment_contact, triangle_contact: segment-segment, and segment-triangle with the point-triangle,
// edge-triangle and crossing cases). Mesentery-mesentery pairs are not tested, as in the reference.
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
  long overlaps = 0;   // element pairs whose grown boxes overlap on all three axes (tested pairs only)
  int contacts = 0;    // contacts written
  int overflow = 0;    // contacts refused by the list
};

class BroadPhaseDetector {
 public:
  /// Init phase (allocates; throws surgsim::Error on a bad topology).
  explicit BroadPhaseDetector(CollisionTopology topology);

  const CollisionTopology& topology() const { return topo_; }

  /// Every tested element pair closer than the sum of the radii + margin (m), appended to `out` (not cleared): the
  /// contacts of detect_brute_force(topology(), x, out, margin). No allocation.
  BroadPhaseStats detect(const Eigen::Matrix3Xd& x, ContactList& out, double margin = 0) noexcept;

 private:
  CollisionTopology topo_;
  std::vector<int> seg_node_;                 // 2 per segment
  std::vector<int> tri_node_;                 // 3 per triangle
  std::vector<char> cell_ok_;                 // segments x cells: topology().cell_tested
  std::vector<Eigen::Vector3d> lo_, hi_;      // grown boxes: segments first, then triangles
  std::vector<int> seg_order_, tri_order_;    // segments, triangles (nseg + t) sorted by lo_[axis]
  int axis_ = -1;                             // sort axis of order_
};

}  // namespace surgsim::intestine
