// A rigid organ's surface (abdominal wall, rib, spine segment): a consistently oriented triangle surface in world
// coordinates with the side an instrument moves in (its free side), and the queries the haptic loop asks of it at
// 1 kHz (closest point, first contact of a moving sphere) through its own uniform grid. Everything is allocated when
// the surface is built; the queries allocate nothing and never throw.
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "mesh/tri_surface.h"

namespace surgsim::rigid {

/// The point of the surface closest to a query point.
struct ClosestPoint {
  bool found = false;                                // a triangle lies within the query's max_distance
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // m, on the surface
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit, the free side's normal at `point` (towards the query
                                                     // point when it is on the free side, away from it otherwise)
  double distance = 0;                               // m, signed: positive on the free side
  int triangle = -1;                                 // the triangle holding `point`
  Eigen::Vector3i corners = Eigen::Vector3i::Constant(-1);  // its vertices (indices into the surface's vertices)
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();           // `point` = sum bary[k] vertices[corners[k]]
};

/// The first contact of a sphere moving along a segment.
struct SegmentHit {
  bool hit = false;
  double t = 1;                                      // fraction of the segment travelled at first contact, [0, 1]
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // m, the sphere's centre at first contact
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit, from the touched point towards the centre
  int triangle = -1;
};

/// A feature of the surface touching a sphere (for the proxy's constraint planes).
struct Touch {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // m, closest point on the surface
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit, from `point` towards the query point
  double distance = 0;                               // m, unsigned
  int triangle = -1;
};

class RigidSurface {
 public:
  /// `surface` in world coordinates, counter-clockwise seen from the free side (from outside for a closed organ);
  /// `cavity`: the free side is the other one (an abdominal wall seen from inside the abdomen). Open surfaces (a
  /// plane patch, a rib without caps) are allowed when consistently oriented. `where` (a file, a scene key) names
  /// the surface in messages. Throws surgsim::core::Error naming `where` when there are no triangles, an index is
  /// out of range, a coordinate is not finite, a triangle is degenerate, or an edge is used twice in the same
  /// direction or by more than two triangles (no consistent side to push out to).
  RigidSurface(const mesh::TriSurface& surface, bool cavity, const std::string& where);

  /// The surface point closest to `p` among the triangles within `max_distance` (m) of it (found = false if none).
  ClosestPoint closest_point(const Eigen::Vector3d& p, double max_distance) const noexcept;

  /// The first contact of a sphere of `radius` (m) whose centre moves from `a` to `b` with any triangle (either
  /// side): the moving sphere first touches a face, an edge or a vertex. A sphere that already overlaps a feature
  /// and moves deeper into it hits at t = 0. hit = false when the whole motion is free.
  SegmentHit segment_hit(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double radius) const noexcept;

  /// The surface features within `max_distance` (m) of `p` that are local minima of the distance (a triangle's
  /// edge or vertex is left out when a triangle sharing it comes nearer: on a flat or concave region only the faces
  /// under p count), one per distinct normal direction, at most `capacity` written to `out`; returns how many.
  int touching(const Eigen::Vector3d& p, double max_distance, Touch* out, int capacity) const noexcept;

  const Eigen::AlignedBox3d& bounds() const { return bounds_; }  // m, of the vertices
  int triangle_count() const { return static_cast<int>(tris_.size()); }
  const mesh::TriSurface& surface() const { return surface_; }  // as given (its own orientation)
  bool cavity() const { return cavity_; }
  const std::string& where() const { return where_; }
  /// Unit normal of triangle `t` towards the free side.
  const Eigen::Vector3d& face_normal(int t) const { return face_normal_[static_cast<std::size_t>(t)]; }

 private:
  struct Tri {
    int v[3];
  };
  // Calls f(triangle) for every triangle registered in the grid cells overlapping [lo, hi] (a triangle may come
  // more than once; nothing when the box misses the grid).
  template <typename F>
  void for_each_in_box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, F&& f) const noexcept;
  void build_grid();
  // Whether the closest point q (barycentric `bary`) of triangle f to p, at distance d, is on an edge or vertex
  // that a triangle sharing it comes nearer to p than d.
  bool dominated(const Eigen::Vector3d& p, int f, const Eigen::Vector3d& bary, double d) const noexcept;
  double triangle_distance(const Eigen::Vector3d& p, int f) const noexcept;
  Eigen::Vector3d closest_on(const Eigen::Vector3d& p, int f, Eigen::Vector3d& bary) const noexcept;
  // Calls f(triangle, closest point, its barycentrics, squared distance) for the triangles within max_distance.
  template <typename F>
  void for_each_near(const Eigen::Vector3d& p, double max_distance, F&& f) const noexcept;

  mesh::TriSurface surface_;
  bool cavity_ = false;
  std::string where_;
  std::vector<Eigen::Vector3d> vertices_;        // m
  std::vector<Tri> tris_;                        // counter-clockwise seen from the free side
  std::vector<Eigen::Vector3d> face_normal_;     // unit, towards the free side
  std::vector<Eigen::Vector3d> edge_normal_;     // 3 per triangle (edge k: v[k] -> v[k+1]): sum of the two faces'
  std::vector<Eigen::Vector3d> vertex_normal_;   // angle-weighted pseudo-normal (Baerentzen and Aanaes 2005)
  std::vector<int> neighbour_;                   // 3 per triangle: the triangle across edge k, -1 on a boundary
  std::vector<int> vertex_start_, vertex_tris_;  // the triangles around vertex v: vertex_tris_[start[v]..start[v+1])
  Eigen::AlignedBox3d bounds_;
  // Uniform grid: cell (i, j, k) holds cell_tris_[cell_start_[c] .. cell_start_[c + 1]) with c = i + n0 (j + n1 k).
  Eigen::Vector3d grid_origin_ = Eigen::Vector3d::Zero();  // m
  double cell_ = 1;                                        // m, cell edge
  Eigen::Vector3i cells_ = Eigen::Vector3i::Ones();
  std::vector<int> cell_start_;
  std::vector<int> cell_tris_;
};

}  // namespace surgsim::rigid
