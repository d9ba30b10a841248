#include "mesh/geometry.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace surgsim::mesh {

bool segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                      const Eigen::Vector3d& b, const Eigen::Vector3d& c, double& s, Eigen::Vector3d& bary) {
  constexpr double kEps = 1e-12;
  const Eigen::Vector3d d = p1 - p0;
  const Eigen::Vector3d e1 = b - a;
  const Eigen::Vector3d e2 = c - a;
  const Eigen::Vector3d h = d.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) < kEps * e1.norm() * e2.norm() * std::max(d.norm(), 1e-300)) return false;
  const double inv = 1.0 / det;
  const Eigen::Vector3d t = p0 - a;
  const double u = inv * t.dot(h);
  // A small tolerance closes the cracks between neighbouring triangles.
  constexpr double kTol = 1e-9;
  if (u < -kTol || u > 1 + kTol) return false;
  const Eigen::Vector3d q = t.cross(e1);
  const double v = inv * d.dot(q);
  if (v < -kTol || u + v > 1 + kTol) return false;
  const double ss = inv * e2.dot(q);
  if (ss < 0 || ss > 1) return false;
  s = ss;
  bary = Eigen::Vector3d(1 - u - v, u, v);
  return true;
}

Eigen::Vector3d closest_point_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c, Eigen::Vector3d& bary) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) { bary = {1, 0, 0}; return a; }
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) { bary = {0, 1, 0}; return b; }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    bary = {1 - v, v, 0};
    return a + v * ab;
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) { bary = {0, 0, 1}; return c; }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    bary = {1 - w, 0, w};
    return a + w * ac;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    bary = {0, 1 - w, w};
    return b + w * (c - b);
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  bary = {1 - v - w, v, w};
  return a + ab * v + ac * w;
}

}  // namespace surgsim::mesh
