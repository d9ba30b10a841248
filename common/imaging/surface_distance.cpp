#include "imaging/surface_distance.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::imaging {

Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  // Voronoi regions of the vertices, then of the edges, else the face.
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  if (!(std::fabs(denom) > 0.0)) return a;  // degenerate triangle
  return a + ab * (vb / denom) + ac * (vc / denom);
}

TriangleTree::TriangleTree(const TriSurface& mesh) {
  const auto n = static_cast<std::size_t>(mesh.tris.rows());
  if (n == 0) throw_error("distance query: the surface has no triangles");
  tris_.resize(n);
  std::vector<Eigen::Vector3d> centroids(n);
  for (std::size_t f = 0; f < n; ++f) {
    for (int k = 0; k < 3; ++k) tris_[f].col(k) = mesh.vertices.row(mesh.tris(static_cast<Eigen::Index>(f), k)).transpose();
    centroids[f] = tris_[f].rowwise().mean();
  }
  order_.resize(n);
  for (std::size_t f = 0; f < n; ++f) order_[f] = static_cast<int>(f);
  nodes_.reserve(2 * n);
  build(0, static_cast<int>(n), centroids);
}

int TriangleTree::build(int begin, int end, const std::vector<Eigen::Vector3d>& centroids) {
  constexpr int kLeafSize = 8;
  const int id = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int i = begin; i < end; ++i) {
    const Eigen::Matrix3d& t = tris_[static_cast<std::size_t>(order_[static_cast<std::size_t>(i)])];
    lo = lo.cwiseMin(t.rowwise().minCoeff());
    hi = hi.cwiseMax(t.rowwise().maxCoeff());
  }
  nodes_[static_cast<std::size_t>(id)].lo = lo;
  nodes_[static_cast<std::size_t>(id)].hi = hi;
  if (end - begin <= kLeafSize) {
    nodes_[static_cast<std::size_t>(id)].begin = begin;
    nodes_[static_cast<std::size_t>(id)].end = end;
    return id;
  }
  // Median split of the centroids along the box's longest axis.
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end, [&](int x, int y) {
    return centroids[static_cast<std::size_t>(x)][axis] < centroids[static_cast<std::size_t>(y)][axis];
  });
  const int left = build(begin, mid, centroids);
  const int right = build(mid, end, centroids);
  nodes_[static_cast<std::size_t>(id)].left = left;
  nodes_[static_cast<std::size_t>(id)].right = right;
  return id;
}

double TriangleTree::distance(const Eigen::Vector3d& p, Eigen::Vector3d* closest) const {
  auto box_distance2 = [&p](const Node& n) {
    return (n.lo - p).cwiseMax(p - n.hi).cwiseMax(0.0).squaredNorm();
  };
  double best2 = std::numeric_limits<double>::infinity();
  Eigen::Vector3d best_point = p;
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[static_cast<std::size_t>(stack[--top])];
    if (box_distance2(n) >= best2) continue;
    if (n.left < 0) {
      for (int i = n.begin; i < n.end; ++i) {
        const Eigen::Matrix3d& t = tris_[static_cast<std::size_t>(order_[static_cast<std::size_t>(i)])];
        const Eigen::Vector3d q = closest_point_on_triangle(p, t.col(0), t.col(1), t.col(2));
        const double d2 = (q - p).squaredNorm();
        if (d2 < best2) {
          best2 = d2;
          best_point = q;
        }
      }
      continue;
    }
    // Nearer child last, so that it is visited first.
    const Node& l = nodes_[static_cast<std::size_t>(n.left)];
    const Node& r = nodes_[static_cast<std::size_t>(n.right)];
    const bool left_first = box_distance2(l) <= box_distance2(r);
    stack[top++] = left_first ? n.right : n.left;
    stack[top++] = left_first ? n.left : n.right;
  }
  if (closest != nullptr) *closest = best_point;
  return std::sqrt(best2);
}

void sample_surface(const TriSurface& mesh, double spacing, std::vector<Eigen::Vector3d>& points,
                    std::vector<double>& weights) {
  if (!(spacing > 0.0)) throw_error("surface sampling: the spacing must be positive");
  points.clear();
  weights.clear();
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) {
    points.push_back(mesh.vertices.row(v).transpose());
    weights.push_back(0.0);
  }
  for (Eigen::Index f = 0; f < mesh.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.tris(f, 0));
    const Eigen::Vector3d b = mesh.vertices.row(mesh.tris(f, 1));
    const Eigen::Vector3d c = mesh.vertices.row(mesh.tris(f, 2));
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int m = std::max(1, static_cast<int>(std::ceil(longest / spacing)));
    // Points at barycentric (i + 1/3, j + 1/3) / m: the centroids of the m^2 sub-triangles pointing the same way,
    // each standing for 1/m^2 of the area.
    const double area = 0.5 * (b - a).cross(c - a).norm();
    const double w = area / (static_cast<double>(m) * m);
    for (int i = 0; i < m; ++i) {
      for (int j = 0; i + j < m; ++j) {
        const double u = (i + 1.0 / 3.0) / m, v = (j + 1.0 / 3.0) / m;
        points.push_back(a + u * (b - a) + v * (c - a));
        weights.push_back(w * (m * m) / (m * (m + 1) / 2.0));
      }
    }
  }
}

SurfaceDistance surface_distance(const TriSurface& a, const TriSurface& b, double sample_spacing) {
  SurfaceDistance out;
  auto one_way = [sample_spacing](const TriSurface& from, const TriangleTree& to, double& max_d, double& mean_d) {
    std::vector<Eigen::Vector3d> points;
    std::vector<double> weights;
    sample_surface(from, sample_spacing, points, weights);
    double sum = 0.0, total = 0.0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double d = to.distance(points[i]);
      max_d = std::max(max_d, d);
      sum += weights[i] * d;
      total += weights[i];
    }
    mean_d = total > 0.0 ? sum / total : 0.0;
  };
  const TriangleTree tree_a(a), tree_b(b);
  one_way(a, tree_b, out.a_to_b_max, out.a_to_b_mean);
  one_way(b, tree_a, out.b_to_a_max, out.b_to_a_mean);
  out.hausdorff = std::max(out.a_to_b_max, out.b_to_a_max);
  out.mean = 0.5 * (out.a_to_b_mean + out.b_to_a_mean);
  return out;
}

}  // namespace surgsim::imaging
