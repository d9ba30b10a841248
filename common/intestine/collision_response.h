// Displacement-velocity collision response (Raghupathi et al. 2004, eqs. 2-9; docs/DESIGN.md, section 'Intestine:
// mass-spring + stochastic collisions').
//
// A contact joins a point of element A (an intestine segment: 2 nodes) and a point of element B (a segment or a
// mesentery triangle: 2 or 3 nodes), each a barycentric combination p = sum w_k x_k, with a unit collision direction
// n (from B towards A) and the distance to restore, the sum of the two radii. The response:
//   - velocity: if the contact points approach along n, (v_A - v_B).n < 0, that component is cancelled;
//   - position: the points are moved apart along n until (p_A - p_B).n = r_A + r_B.
// Each correction D (a velocity or a displacement of the contact points along n) is shared over the nodes with the
// minimum-norm weighting of the paper, generalized to unequal masses: node k moves by +-lambda w_k m_k^-1 n with
// lambda = D / (sum_A w^2 m^-1 + sum_B w^2 m^-1), so that the interpolated points move by exactly D (fixed nodes,
// m^-1 = 0, do not move). With equal masses this is the paper's (1 - u, u) / ((1-u)^2 + u^2 + (1-v)^2 + v^2) form.
// Contacts are processed in order (Gauss-Seidel) for a fixed number of iterations; the weights and n stay those of
// detection, the gap is re-evaluated at every iteration.
//
// Run phase only: respond() allocates nothing. ContactList is a fixed-capacity list filled by the detectors.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

namespace surgsim::intestine {

enum class ContactKind : std::uint8_t { kSegmentSegment = 0, kSegmentTriangle = 1 };

/// One collision between two elements, as found by detection (stochastic or brute force).
struct CollisionContact {
  ContactKind kind = ContactKind::kSegmentSegment;
  int count_a = 2;                           // nodes of side A (2: a segment)
  int count_b = 2;                           // nodes of side B (2: a segment, 3: a triangle)
  std::array<int, 5> nodes{{-1, -1, -1, -1, -1}};  // A's nodes then B's
  std::array<double, 5> weights{{0, 0, 0, 0, 0}};  // barycentric, each side sums to 1
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, from B's point towards A's point
  double radius_sum = 0;                     // m, distance the response restores
  double distance = 0;                       // m, at detection
  int element_a = -1;                        // segment index
  int element_b = -1;                        // segment index, or mesentery triangle index (2 cell + t)
};

/// Fixed-capacity contact list (no allocation after construction; an overflow is counted, not stored).
class ContactList {
 public:
  explicit ContactList(int capacity = 0) : items_(static_cast<std::size_t>(capacity)) {}
  int capacity() const { return static_cast<int>(items_.size()); }
  int size() const { return size_; }
  int dropped() const { return dropped_; }  // contacts refused for lack of room since clear()
  void clear() noexcept {
    size_ = 0;
    dropped_ = 0;
  }
  bool push(const CollisionContact& c) noexcept {
    if (size_ >= capacity()) {
      ++dropped_;
      return false;
    }
    items_[static_cast<std::size_t>(size_++)] = c;
    return true;
  }
  const CollisionContact& operator[](int i) const { return items_[static_cast<std::size_t>(i)]; }
  CollisionContact& operator[](int i) { return items_[static_cast<std::size_t>(i)]; }
  const CollisionContact* begin() const { return items_.data(); }
  const CollisionContact* end() const { return items_.data() + size_; }

 private:
  std::vector<CollisionContact> items_;
  int size_ = 0;
  int dropped_ = 0;
};

struct ResponseParams {
  int iterations = 4;          // Gauss-Seidel sweeps over the contacts (fixed count: bounded time)
  bool correct_velocity = true;
  bool correct_position = true;
};

struct ResponseReport {
  double max_penetration_before = 0;  // m, largest r_A + r_B - (p_A - p_B).n over the contacts before the response
  double max_penetration_after = 0;   // m, the same after the last sweep
  int velocity_corrections = 0;       // contacts whose approach velocity was cancelled (first sweep)
};

/// Signed gap (m) of a contact at positions x: (p_A - p_B).n - radius_sum (< 0: penetrating).
double contact_gap(const CollisionContact& c, const Eigen::Matrix3Xd& x) noexcept;

/// Applies the response to x and v (3 x N) in place. `inverse_mass` has N entries (0 for fixed nodes).
void respond(const ContactList& contacts, const double* inverse_mass, const ResponseParams& params,
             Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, ResponseReport& report) noexcept;

}  // namespace surgsim::intestine
