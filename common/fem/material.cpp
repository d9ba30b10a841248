#include "fem/material.h"

#include <algorithm>

namespace surgsim::fem {

namespace {
bool in_box(const Eigen::Vector3d& x, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  return (x.array() >= lo.array()).all() && (x.array() <= hi.array()).all();
}
}  // namespace

bool FixedRegion::fixes(int index, const Eigen::Vector3d& x_scene) const {
  if (std::find(nodes.begin(), nodes.end(), index) != nodes.end()) return true;
  const Eigen::Vector3d x = frame.to_organ(x_scene);
  for (const auto& b : boxes) {
    if (in_box(x, b.first, b.second)) return true;
  }
  return has_plane && (x - plane_point).dot(plane_normal) >= 0;
}

}  // namespace surgsim::fem
