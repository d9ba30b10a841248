// Distances between triangle surfaces: closest-point queries on a bounding-volume tree, and the symmetric Hausdorff
// and mean distances the round-trip figures report.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "mesh/tri_surface.h"

namespace surgsim::imaging {

/// Closest points on a triangle surface. Copies what it needs; the surface may go away afterwards.
class TriangleTree {
 public:
  explicit TriangleTree(const mesh::TriSurface& mesh);
  /// Distance (m) from p (m) to the nearest point of the surface; `closest`, if given, receives that point.
  double distance(const Eigen::Vector3d& p, Eigen::Vector3d* closest = nullptr) const;

 private:
  struct Node {
    Eigen::Vector3d lo, hi;  // box, m
    int left = -1, right = -1;  // children, or -1 for a leaf
    int begin = 0, end = 0;     // leaf: range in order_
  };
  int build(int begin, int end, const std::vector<Eigen::Vector3d>& centroids);

  std::vector<Eigen::Matrix3d> tris_;  // columns: the three corners, m
  std::vector<int> order_;             // triangle indices, grouped by leaf
  std::vector<Node> nodes_;
};

/// Closest point to p on triangle (a, b, c) (C. Ericson, Real-Time Collision Detection, 2005, section 5.1.5).
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c);

/// Distances between two surfaces, by sampling each (its vertices and points on every triangle at most
/// `sample_spacing` apart) against the other: the sampled Hausdorff distance is a lower bound of the exact one,
/// short of it by at most about sample_spacing / 2.
struct SurfaceDistance {
  double hausdorff = 0.0;   // m, max(a_to_b_max, b_to_a_max)
  double mean = 0.0;        // m, mean of the two area-weighted mean distances
  double a_to_b_max = 0.0;  // m
  double b_to_a_max = 0.0;  // m
  double a_to_b_mean = 0.0; // m, area-weighted
  double b_to_a_mean = 0.0; // m, area-weighted
};
SurfaceDistance surface_distance(const mesh::TriSurface& a, const mesh::TriSurface& b, double sample_spacing);

/// Sample points on a surface (vertices, then per triangle a barycentric grid whose spacing is at most `spacing`)
/// with their area weights (the vertices weigh 0).
void sample_surface(const mesh::TriSurface& mesh, double spacing, std::vector<Eigen::Vector3d>& points,
                    std::vector<double>& weights);

}  // namespace surgsim::imaging
