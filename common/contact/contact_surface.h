// The rest surface as a tool of finite radius sees it, for the liver's patch contact: area-weighted vertex normals, a
// LOCAL closest-point search that walks from the previous triangle to its neighbours (so a contact slides with the
// tool and never jumps to another face because that face became closer: a straight press keeps its anchor and its
// depth grows monotonically), and the patch of a contact: the free surface nodes within the tip radius r of the
// contact point with Wendland C2 weights phi(q) = (1 - q)^4 (4 q + 1), q = |x_i - c| / r, times a smooth gate on
// the agreement of the node's normal with the contact's (nodes of an opposite or side face do not take part),
// normalized to sum 1.
//
// Why these weights: a point contact imposed on the three vertices of one triangle makes the stiffness depend on
// where the tip sits inside the triangle (53 % ripple on a slab). Spreading the constraint over every node within a
// radius of 2-3 mesh edges with a C2 compactly supported kernel makes the patch compliance c^T G c, a quadrature of
// a smooth weight against the Green's function, nearly independent of the position relative to the nodes; the
// kernel is C2 at its boundary, so nodes entering and leaving the support change nothing abruptly.
//
// Init allocates (per-triangle candidate lists: free surface nodes within r + circumradius of the centroid);
// queries allocate nothing and never throw.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "mesh/mesh.h"

namespace surgsim::contact {

/// A point of the rest surface.
struct RestPoint {
  bool found = false;
  int triangle = -1;
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  Eigen::Vector3d point = Eigen::Vector3d::Zero();         // m
  Eigen::Vector3d face_normal = Eigen::Vector3d::UnitZ();  // outward unit normal of the triangle
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();       // interpolated vertex normal (unit, continuous)
  double distance = 0;                                     // m
};

class ContactSurface {
 public:
  static constexpr int kMaxWalk = 256;  // triangles a local search visits at most

  /// `free_node`: per mesh node, non-zero when the node may carry a constraint (free surface node with a tensor
  /// column). `radius` > 0 (m). Throws surgsim::core::Error on an empty surface or a bad radius.
  ContactSurface(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface,
                 const std::vector<std::uint8_t>& free_node, double radius);

  /// Mean edge length of the surface (m).
  static double mean_edge(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface);

  double radius() const { return radius_; }
  const mesh::SurfaceMesh& surface() const { return surface_; }
  const Eigen::Vector3d& vertex_normal(int node) const { return vertex_normals_[static_cast<std::size_t>(node)]; }

  /// Closest point of the rest surface to p on triangle `triangle`.
  RestPoint on_triangle(const Eigen::Vector3d& p, int triangle) const noexcept;
  /// Local closest point: from `start`, moves to the closest triangle among those sharing a vertex with the current
  /// one while that is strictly closer. Continuous in p, and it stays on the face it started from unless the
  /// surface itself leads elsewhere. With `facing`, only triangles whose outward normal
  /// are entered within 60 degrees of it (a tip pressed deeper than the curvature radius of a convex face does not
  /// slide round the organ to the opposite face).
  RestPoint closest_local(const Eigen::Vector3d& p, int start, const Eigen::Vector3d* facing = nullptr) const noexcept;

  /// Patch of a contact at rest point `c` (on triangle `triangle`) with gating normal `normal`: up to `capacity`
  /// nodes (the largest weights when more are inside the radius), weights normalized to sum 1. Returns the count
  /// (0: no free node inside). `dropped` counts nodes inside the radius left out for the capacity, `fixed` the
  /// surface nodes inside the radius that carry no constraint (fixed).
  int patch(const Eigen::Vector3d& c, int triangle, const Eigen::Vector3d& normal, int capacity, int* nodes,
            double* weights, int* dropped, int* fixed) const noexcept;

  /// Footprint of a tip of radius `a` (m) centred at rest point `c` (on triangle `triangle`), pressed along
  /// `normal`: the weight of node i is the integral of its shape function against the flat punch's pressure
  /// p(rho) = 1 / (2 pi a sqrt(a^2 - rho^2)) over the disc of radius a in the plane normal to `normal`, projected
  /// along `normal` onto the surface (kFootprintRings x kFootprintAngles points, exact for the pressure's radial
  /// singularity: rho = a sqrt(1 - u^2) with u Gauss-Legendre on [0, 1]). Points that fall off the surface or on a
  /// face turned more than about 78 degrees from `normal` are left out. Weights of nodes that carry no constraint
  /// (fixed) are left out (`fixed` counts those nodes); up to `capacity` nodes (the largest; `dropped` counts the
  /// rest); the kept weights normalized to sum 1. Continuous in c: the weights are integrals, not a selection.
  /// Returns the count (0: nothing free under the tip).
  /// `walk` (optional, kFootprintPoints entries, in and out): the triangle each quadrature point was found on last
  /// time (-1: none), where its walk starts (a tip that moved a little finds each point in one step); a walk that
  /// fails from there is tried again from the previous point's triangle, as without `walk`.
  int footprint(const Eigen::Vector3d& c, int triangle, const Eigen::Vector3d& normal, double a, int capacity,
                int* nodes, double* weights, int* dropped, int* fixed, int* walk = nullptr) const noexcept;
  static constexpr int kFootprintRings = 4;
  static constexpr int kFootprintAngles = 12;
  static constexpr int kFootprintPoints = kFootprintRings * kFootprintAngles;

  /// The patch normal: normalized sum of w_i n_i.
  Eigen::Vector3d patch_normal(const int* nodes, const double* weights, int count) const noexcept;

 private:
  const mesh::TetMesh& mesh_;
  const mesh::SurfaceMesh& surface_;
  double radius_;
  std::vector<Eigen::Vector3d> vertex_normals_;  // per mesh node (zero off the surface)
  std::vector<Eigen::Vector3d> face_normals_;
  mesh::NodeTriangles node_tris_;             // node -> incident triangles
  std::vector<int> cand_start_, cand_nodes_;  // triangle -> candidate patch nodes (CSR), free or fixed
  std::vector<std::uint8_t> free_;
  std::vector<int> adjacent_;  // 3 per triangle: the triangle across the edge opposite vertex v (-1: none)
  std::array<double, kFootprintRings> ring_rho_{}, ring_weight_{};  // rho / a and the ring's share of the load
  // cos and sin of each quadrature point's angle, per ring (the rings are staggered by half a step).
  std::array<double, kFootprintRings * kFootprintAngles> angle_cos_{}, angle_sin_{};
  std::vector<Eigen::Vector3d> corners_;  // 3 per triangle: its nodes' rest positions (the walk reads them together)
  /// The triangle (walking from `f`) that holds q projected along the frame's normal, with its barycentrics.
  int locate(const Eigen::Vector3d& q, const Eigen::Vector3d& t1, const Eigen::Vector3d& t2,
             const Eigen::Vector3d& normal, int f, Eigen::Vector3d& bary) const noexcept;
};

}  // namespace surgsim::contact
