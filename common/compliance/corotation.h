// Corotational (warped) precomputed compliance, for large rotations. The tensors G stay those of the rest shape; at run
// time each node n carries a rotation R_n of the tissue around it, and the compliance between nodes i and j becomes
//   W_ij = R_i G_ij R_j^T     (m/N):
// a force lambda_j (world frame) is taken to the rest frame (R_j^T lambda_j, the constraint directions' half), the
// rest-frame response G_ij R_j^T lambda_j is rotated back (R_i, the response's half). Both halves are needed: with
// only one of them a rigidly turned organ answers a push along its rotated normal with the rest normal's stiffness
// in the wrong direction (SOFA's PrecomputedConstraintCorrection since its 2023 change rotates its response but
// rotates the constraint normals on a copy that is thrown away; tests/common/compliance/corotation_test.cpp catches
// both one-half variants through RotationHalves).
//
// Rotations. R_n is the shape-matching rotation of node n's one-ring on the boundary surface (the node and its
// surface neighbours): A_n = sum_k (x_k - xbar)(X_k - Xbar)^T over the ring, X rest and x = X + u~ positions,
// R_n = the rotation maximizing tr(R^T A_n) (the rotational part of the polar decomposition; a flat ring, rank 2,
// still gives a proper rotation: the normal follows the two in-plane axes). It is computed by
// Higham's scaled Newton iteration for the polar factor (Mueller et al. 2016's iteration for an inverted ring): no
// allocation, no SVD. The displacements are the REST-FRAME response u~ = G R^T lambda of the previous solve, not the
// rotated one R u~: estimated from the rotated response the rotation feeds back on itself (a grasp dragged 2 cm
// across a 4 cm slab ran away from 31 to 160 degrees in tests/haptic_node/organs/liver_corotation_test.cpp); from
// u~ it is the rotation of the linear field, a fixed point without that loop. In the haptic loop the rotations lag
// one tick (at 1 kHz a lobe turning at 90 degrees/s is 0.09 degrees behind).
//
// Free configuration. The response is added to the organ's configuration without contact, x_free = Q X + t, where
// (Q, t) is the rigid frame of the fixed set (shape matching of the fixed nodes: the identity while the attachment
// does not move, as in every shipped scene). A rigid motion of the whole organ with its fixed set therefore costs no
// force on the corotational path; the linear path reads the same motion as strain.
//
// What it does not do (build/bench/large_deformation_bench against the neo-Hookean Newton reference on the shipped
// liver): a region that turns about a hinge at a fixed set that stays put (a lobe lifted by its tip) keeps the
// linear model's lever-arm strain, because the rigid part of that motion is not in x_free, and warping the total
// response rotates displacements that are mostly translation and bending: the force error is larger than the linear
// model's for a deep press (18 % against 4.7 % at 10 % indentation) and a lifted lobe (5.2 against 0.58 at 90
// degrees), and as large with the Newton field's own rotations (so it is the form, not the rotation estimate). The
// form that fixes lifting needs the rotation integrated along the tissue, or the free motion of a running
// corotational FEM as SOFA has; linear stays the default.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "concurrency/triple_buffer.h"
#include "mesh/mesh.h"

namespace surgsim::compliance {

/// How the liver's precomputed compliance is used at run time (scene key liver.deformation).
enum class LiverDeformation : std::uint8_t {
  kLinear = 0,        // G as precomputed (Cotin 1998)
  kCorotational = 1,  // W_ij = R_i G_ij R_j^T with per-node rotations from the current displacement
  kMultirate = 2,     // a neo-Hookean tracker off the loop, its local model at 1 kHz (nonlinear/multirate.h)
};
const char* to_string(LiverDeformation deformation);

/// Which halves of the rotation the warped compliance applies. Only kBoth is correct; the other two are the
/// mistakes the tests must catch (a test seam, never chosen by a scene).
enum class RotationHalves : std::uint8_t {
  kBoth = 0,             // W = R_i G R_j^T
  kResponseOnly = 1,     // W = R_i G        (constraint directions left in the world frame)
  kConstraintsOnly = 2,  // W = G R_j^T      (response left in the rest frame)
};

/// W = R_a G R_b^T (or the one-half variant). noexcept, no allocation.
inline Eigen::Matrix3d warp_block(const Eigen::Matrix3d& ra, const Eigen::Matrix3d& g, const Eigen::Matrix3d& rb,
                                  RotationHalves halves = RotationHalves::kBoth) noexcept {
  switch (halves) {
    case RotationHalves::kResponseOnly: return ra * g;
    case RotationHalves::kConstraintsOnly: return g * rb.transpose();
    case RotationHalves::kBoth:
    default: return ra * g * rb.transpose();
  }
}

/// The rotation R maximizing tr(R^T A) (the rotation of the polar decomposition of A for det A > 0), written to q.
/// Works on A + cof(A) (same rotation, full rank for a flat ring): when its determinant is positive by Higham's
/// scaled Newton iteration (quadratic: 5-8 iterations to round-off), otherwise (an inverted ring) by the iteration
/// of Mueller et al. 2016 starting from q, which stays a proper rotation. At most `max_iterations`; returns the
/// iterations done. A zero (or non-finite) A leaves q unchanged. noexcept, no allocation.
int extract_rotation(const Eigen::Matrix3d& a, Eigen::Quaterniond& q, int max_iterations = 20) noexcept;

/// A rigid frame x = r X + t.
struct RigidFrame {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return r * x + t; }
};

/// The rigid frame best matching rest positions X_k (mesh rows `nodes`) to X_k + u_k (shape matching: rotation of the
/// covariance, translation of the centroids). `u` is #V x 3 (m). Identity for fewer than 3 nodes or zero u.
/// Allocates nothing itself; for init, tests and benchmarks.
RigidFrame fit_rigid_frame(const Eigen::MatrixX3d& rest, const std::vector<int>& nodes, const Eigen::MatrixX3d& u);

/// Per-node rotations of the boundary surface. Construction allocates; update(), rotation() do not.
class NodeRotations {
 public:
  static constexpr int kTickIterations = 4;   // iterations per update in the loop (warm start)
  static constexpr int kColdIterations = 30;  // iterations of a full refresh (update_all)

  /// Rings from the boundary triangles; interior nodes keep the identity.
  NodeRotations(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface);

  int node_count() const { return static_cast<int>(q_.size()); }
  /// Ring of node n: its surface neighbours (the node itself is not listed).
  int ring_size(int n) const { return start_[static_cast<std::size_t>(n) + 1] - start_[static_cast<std::size_t>(n)]; }
  const int* ring(int n) const { return ring_.data() + start_[static_cast<std::size_t>(n)]; }
  bool on_surface(int n) const { return ring_size(n) > 0; }

  /// Recomputes node n's rotation from the displacements `u(k)` (m, world frame) of the node and its ring, warm
  /// started from its current rotation. `u` is any callable int -> Eigen::Vector3d. noexcept when `u` is.
  template <class Displacement>
  void update(int n, const Displacement& u, int iterations = kTickIterations) {
    if (!on_surface(n)) return;
    const Eigen::Vector3d x0 = rest_.row(n).transpose();
    const Eigen::Vector3d un = u(n);
    Eigen::Vector3d xbar = x0 + un, rbar = x0;
    const int* r = ring(n);
    const int size = ring_size(n);
    for (int i = 0; i < size; ++i) {
      xbar += rest_.row(r[i]).transpose() + u(r[i]);
      rbar += rest_.row(r[i]).transpose();
    }
    xbar /= size + 1;
    rbar /= size + 1;
    Eigen::Matrix3d a = (x0 + un - xbar) * (x0 - rbar).transpose();
    for (int i = 0; i < size; ++i) {
      const Eigen::Vector3d xr = rest_.row(r[i]).transpose();
      a.noalias() += (xr + u(r[i]) - xbar) * (xr - rbar).transpose();
    }
    Eigen::Quaterniond& q = q_[static_cast<std::size_t>(n)];
    extract_rotation(a, q, iterations);
    r_[static_cast<std::size_t>(n)] = q.toRotationMatrix();
  }

  /// Every surface node from u (#V x 3, m), `iterations` each (warm started).
  void update_all(const Eigen::MatrixX3d& u, int iterations = kColdIterations);

  const Eigen::Matrix3d& rotation(int n) const { return r_[static_cast<std::size_t>(n)]; }
  const Eigen::Quaterniond& quaternion(int n) const { return q_[static_cast<std::size_t>(n)]; }
  void set(int n, const Eigen::Quaterniond& q) noexcept {
    q_[static_cast<std::size_t>(n)] = q;
    r_[static_cast<std::size_t>(n)] = q.toRotationMatrix();
  }
  /// Every rotation the identity.
  void reset() noexcept;
  const Eigen::MatrixX3d& rest() const { return rest_; }

 private:
  Eigen::MatrixX3d rest_;          // #V x 3, m
  std::vector<int> start_, ring_;  // CSR rings
  std::vector<Eigen::Quaterniond> q_;
  std::vector<Eigen::Matrix3d> r_;
};

}  // namespace surgsim::compliance
