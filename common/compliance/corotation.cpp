#include "compliance/corotation.h"

#include <algorithm>
#include <cmath>

using namespace surgsim::mesh;

namespace surgsim::compliance {

const char* to_string(LiverDeformation deformation) {
  switch (deformation) {
    case LiverDeformation::kCorotational: return "corotational";
    case LiverDeformation::kMultirate: return "multirate";
    case LiverDeformation::kLinear:
    default: return "linear";
  }
}

int extract_rotation(const Eigen::Matrix3d& a_in, Eigen::Quaterniond& q, int max_iterations) noexcept {
  const double scale = a_in.norm();
  if (!(scale > 0) || !std::isfinite(scale)) return 0;
  // A + cof(A) has the same rotation as A (A = Q S gives cof(A) = Q cof(S)) and is of full rank when A has rank 2:
  // a flat ring (every point on a plane) converges as fast as a solid one.
  Eigen::Matrix3d a = a_in / scale;
  Eigen::Matrix3d cof;
  cof.col(0) = a.col(1).cross(a.col(2));
  cof.col(1) = a.col(2).cross(a.col(0));
  cof.col(2) = a.col(0).cross(a.col(1));
  a += cof;
  // det > 0: the scaled Newton iteration of Higham (1986), X <- (g X + X^-T / g) / 2, quadratic, to the orthogonal
  // polar factor (a proper rotation since det > 0).
  const double det = a.determinant();
  if (det > 1e-12) {
    Eigen::Matrix3d x = a;
    int it = 0;
    for (; it < max_iterations; ++it) {
      const Eigen::Matrix3d xi = x.inverse();
      const double g = std::sqrt(std::sqrt(xi.squaredNorm() / x.squaredNorm()));
      const Eigen::Matrix3d next = 0.5 * (g * x + xi.transpose() / g);
      const double change = (next - x).norm();
      x = next;
      if (change < 1e-15) break;
    }
    q = Eigen::Quaterniond(x);
    q.normalize();
    return it;
  }
  // det <= 0 (an inverted ring): Mueller's iteration from the previous rotation stays a proper rotation.
  int it = 0;
  for (; it < max_iterations; ++it) {
    const Eigen::Matrix3d r = q.toRotationMatrix();
    const Eigen::Vector3d num = r.col(0).cross(a.col(0)) + r.col(1).cross(a.col(1)) + r.col(2).cross(a.col(2));
    const double den = std::abs(r.col(0).dot(a.col(0)) + r.col(1).dot(a.col(1)) + r.col(2).dot(a.col(2))) + 1e-9;
    const Eigen::Vector3d omega = num / den;
    const double w = omega.norm();
    if (w < 1e-12) break;
    q = Eigen::Quaterniond(Eigen::AngleAxisd(w, omega / w)) * q;
    q.normalize();
  }
  return it;
}

RigidFrame fit_rigid_frame(const Eigen::MatrixX3d& rest, const std::vector<int>& nodes, const Eigen::MatrixX3d& u) {
  RigidFrame f;
  if (nodes.size() < 3) return f;
  Eigen::Vector3d xbar = Eigen::Vector3d::Zero(), rbar = Eigen::Vector3d::Zero();
  for (int n : nodes) {
    rbar += rest.row(n).transpose();
    xbar += (rest.row(n) + u.row(n)).transpose();
  }
  rbar /= static_cast<double>(nodes.size());
  xbar /= static_cast<double>(nodes.size());
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  for (int n : nodes) a += ((rest.row(n) + u.row(n)).transpose() - xbar) * (rest.row(n).transpose() - rbar).transpose();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  extract_rotation(a, q, 100);
  f.r = q.toRotationMatrix();
  f.t = xbar - f.r * rbar;
  return f;
}

NodeRotations::NodeRotations(const TetMesh& mesh, const SurfaceMesh& surface) : rest_(mesh.nodes) {
  const auto n = static_cast<std::size_t>(mesh.nodes.rows());
  std::vector<std::vector<int>> nb(n);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f)
    for (int e = 0; e < 3; ++e) {
      const int a = surface.tris(f, e), b = surface.tris(f, (e + 1) % 3);
      nb[static_cast<std::size_t>(a)].push_back(b);
      nb[static_cast<std::size_t>(b)].push_back(a);
    }
  start_.assign(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i) {
    auto& v = nb[i];
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
    start_[i + 1] = start_[i] + static_cast<int>(v.size());
  }
  ring_.reserve(static_cast<std::size_t>(start_[n]));
  for (const auto& v : nb) ring_.insert(ring_.end(), v.begin(), v.end());
  q_.assign(n, Eigen::Quaterniond::Identity());
  r_.assign(n, Eigen::Matrix3d::Identity());
}

void NodeRotations::update_all(const Eigen::MatrixX3d& u, int iterations) {
  const auto disp = [&u](int k) -> Eigen::Vector3d { return u.row(k).transpose(); };
  for (int n = 0; n < node_count(); ++n) update(n, disp, iterations);
}

void NodeRotations::reset() noexcept {
  for (auto& q : q_) q = Eigen::Quaterniond::Identity();
  for (auto& r : r_) r = Eigen::Matrix3d::Identity();
}

}  // namespace surgsim::compliance
