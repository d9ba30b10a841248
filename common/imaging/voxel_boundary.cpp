#include "imaging/voxel_boundary.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace surgsim::imaging {

VoxelBoundaryDistance::VoxelBoundaryDistance(const VoxelMask& mask) : size_(mask.grid.size), spacing_(mask.grid.spacing) {
  const Eigen::Vector3i n = size_;
  auto inside = [&](int i, int j, int k) {
    return i >= 0 && j >= 0 && k >= 0 && i < n.x() && j < n.y() && k < n.z() && mask.at(i, j, k);
  };
  faces_.assign(static_cast<std::size_t>(n.x() + 1) * (n.y() + 1) * (n.z() + 1), 0);
  for (int k = -1; k < n.z(); ++k) {
    for (int j = -1; j < n.y(); ++j) {
      for (int i = -1; i < n.x(); ++i) {
        const bool here = inside(i, j, k);
        std::uint8_t bits = 0;
        if (here != inside(i + 1, j, k)) bits |= 1;
        if (here != inside(i, j + 1, k)) bits |= 2;
        if (here != inside(i, j, k + 1)) bits |= 4;
        if (bits == 0) continue;
        face_count_ += (bits & 1) + ((bits >> 1) & 1) + ((bits >> 2) & 1);
        faces_[(static_cast<std::size_t>(k + 1) * (n.y() + 1) + (j + 1)) * (n.x() + 1) + (i + 1)] = bits;
      }
    }
  }
}

template <typename Visit>
void VoxelBoundaryDistance::scan(const Eigen::Vector3d& p, double limit, const Visit& visit) const {
  // The face towards +a of voxel v lies at a = (v_a + 1/2) spacing_a and spans v_b +- 1/2 on the other axes, so
  // the voxels to visit are those within limit + one voxel of p on each axis.
  std::array<int, 3> lo, hi;
  for (int c = 0; c < 3; ++c) {
    const double f = p[c] / spacing_[c], r = limit / spacing_[c];
    lo[static_cast<std::size_t>(c)] = std::max(-1, static_cast<int>(std::floor(f - r - 1.0)));
    hi[static_cast<std::size_t>(c)] = std::min(size_[c] - 1, static_cast<int>(std::ceil(f + r + 1.0)));
    if (lo[static_cast<std::size_t>(c)] > hi[static_cast<std::size_t>(c)]) return;
  }
  const double limit2 = limit * limit;
  for (int k = lo[2]; k <= hi[2]; ++k) {
    for (int j = lo[1]; j <= hi[1]; ++j) {
      const std::size_t row = (static_cast<std::size_t>(k + 1) * (size_.y() + 1) + (j + 1)) * (size_.x() + 1);
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const std::uint8_t bits = faces_[row + static_cast<std::size_t>(i + 1)];
        if (bits == 0) continue;
        const int v[3] = {i, j, k};
        for (int a = 0; a < 3; ++a) {
          if (((bits >> a) & 1) == 0) continue;
          double d2 = 0.0;
          for (int c = 0; c < 3; ++c) {
            const double centre = v[c] * spacing_[c];
            const double t = c == a ? std::fabs(p[c] - centre - 0.5 * spacing_[c])
                                    : std::max(0.0, std::fabs(p[c] - centre) - 0.5 * spacing_[c]);
            d2 += t * t;
          }
          if (d2 <= limit2 && !visit(d2, i, j, k, a)) return;
        }
      }
    }
  }
}

double VoxelBoundaryDistance::distance(const Eigen::Vector3d& p, double limit, Eigen::Vector3d* closest) const {
  double best2 = limit * limit;
  int best[4] = {0, 0, 0, -1};
  scan(p, limit, [&](double d2, int i, int j, int k, int a) {
    if (d2 < best2 || best[3] < 0) {
      best2 = d2;
      best[0] = i;
      best[1] = j;
      best[2] = k;
      best[3] = a;
    }
    return true;
  });
  if (best[3] < 0) return limit;
  if (closest != nullptr) {
    // Clamp p onto the face's rectangle.
    for (int c = 0; c < 3; ++c) {
      const double centre = best[c] * spacing_[c];
      (*closest)[c] = c == best[3] ? centre + 0.5 * spacing_[c]
                                   : std::clamp(p[c], centre - 0.5 * spacing_[c], centre + 0.5 * spacing_[c]);
    }
  }
  return std::sqrt(best2);
}

bool VoxelBoundaryDistance::within(const Eigen::Vector3d& p, double d) const {
  bool found = false;
  scan(p, d, [&found](double, int, int, int, int) {
    found = true;
    return false;
  });
  return found;
}

}  // namespace surgsim::imaging
