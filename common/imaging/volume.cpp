#include "imaging/volume.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <random>
#include <sstream>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim::imaging {
namespace {

// Neighbour offsets: the 6 face neighbours first, then the 12 edge neighbours (together the 18-neighbourhood).
constexpr std::array<std::array<int, 3>, 18> kNeighbours = {{
    {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1},
    {1, 1, 0}, {1, -1, 0}, {-1, 1, 0}, {-1, -1, 0}, {1, 0, 1}, {1, 0, -1},
    {-1, 0, 1}, {-1, 0, -1}, {0, 1, 1}, {0, 1, -1}, {0, -1, 1}, {0, -1, -1},
}};

std::string name_of(const std::string& source) { return source.empty() ? "<in-memory volume>" : source; }

void check_consistent(const LabelVolume& volume) {
  const VoxelGrid& g = volume.grid;
  if (g.size.minCoeff() <= 0)
    throw_error(name_of(volume.source), ": the volume is empty (", g.size.x(), " x ", g.size.y(), " x ", g.size.z(),
                " voxels)");
  if (static_cast<std::int64_t>(volume.labels.size()) != g.voxel_count())
    throw_error(name_of(volume.source), ": ", volume.labels.size(), " labels for ", g.voxel_count(), " voxels");
  if (!(g.spacing.minCoeff() > 0.0) || !g.spacing.allFinite())
    throw_error(name_of(volume.source), ": voxel spacing must be positive, got ", g.spacing.transpose());
}

// Flood fill over voxels where `member(v)` holds, from `seeds`, using the first `neighbours` offsets; marks
// visited voxels with `id` in `component` and returns how many it marked.
template <typename Member>
std::int64_t flood(const VoxelGrid& g, std::vector<std::int64_t>& stack, std::vector<int>& component, int id,
                   int neighbours, const Member& member) {
  std::int64_t marked = 0;
  for (std::int64_t v : stack) component[static_cast<std::size_t>(v)] = id;
  marked += static_cast<std::int64_t>(stack.size());
  const std::int64_t nx = g.size.x(), ny = g.size.y();
  while (!stack.empty()) {
    const std::int64_t v = stack.back();
    stack.pop_back();
    const int i = static_cast<int>(v % nx), j = static_cast<int>((v / nx) % ny), k = static_cast<int>(v / (nx * ny));
    for (int n = 0; n < neighbours; ++n) {
      const int a = i + kNeighbours[n][0], b = j + kNeighbours[n][1], c = k + kNeighbours[n][2];
      if (a < 0 || b < 0 || c < 0 || a >= g.size.x() || b >= g.size.y() || c >= g.size.z()) continue;
      const std::int64_t w = g.index(a, b, c);
      if (component[static_cast<std::size_t>(w)] != 0 || !member(w)) continue;
      component[static_cast<std::size_t>(w)] = id;
      ++marked;
      stack.push_back(w);
    }
  }
  return marked;
}

}  // namespace

std::int64_t VoxelMask::count() const {
  return static_cast<std::int64_t>(std::count_if(inside.begin(), inside.end(), [](std::uint8_t v) { return v != 0; }));
}

std::vector<std::pair<std::int32_t, std::int64_t>> label_counts(const LabelVolume& volume) {
  std::map<std::int32_t, std::int64_t> counts;
  for (std::int32_t l : volume.labels) ++counts[l];
  return {counts.begin(), counts.end()};
}

VoxelMask select_label(const LabelVolume& volume, std::optional<std::int32_t> label) {
  check_consistent(volume);
  const std::string name = name_of(volume.source);
  const auto counts = label_counts(volume);
  auto list = [&counts]() {
    std::ostringstream os;
    for (std::size_t i = 0; i < counts.size(); ++i)
      os << (i ? ", " : "") << counts[i].first << " (" << counts[i].second << " voxels)";
    return os.str();
  };
  std::int64_t foreground = 0;
  std::vector<std::int32_t> present;
  for (const auto& [l, n] : counts) {
    if (l == 0) continue;
    foreground += n;
    present.push_back(l);
  }
  if (foreground == 0) throw_error(name, ": no foreground: every voxel is 0 (an empty segmentation)");
  if (foreground == volume.grid.voxel_count() && counts.size() == 1)
    throw_error(name, ": every voxel is foreground (label ", counts.front().first,
                "): the organ must not fill the whole volume (crop it with a background border)");

  VoxelMask mask;
  mask.grid = volume.grid;
  mask.source = volume.source;
  if (label.has_value()) {
    if (*label == 0) throw_error(name, ": label 0 is the background; labels present: ", list());
    const auto it = std::find_if(counts.begin(), counts.end(), [&](const auto& c) { return c.first == *label; });
    if (it == counts.end()) throw_error(name, ": label ", *label, " not present; labels present: ", list());
    if (it->second == volume.grid.voxel_count())
      throw_error(name, ": every voxel has label ", *label, ": the organ must not fill the whole volume");
    mask.label = *label;
  } else {
    if (present.size() > 1)
      throw_error(name, ": ", present.size(), " foreground labels present (", list(), "): choose one with --label");
    mask.label = present.front();
  }
  mask.inside.resize(volume.labels.size());
  for (std::size_t v = 0; v < volume.labels.size(); ++v) mask.inside[v] = volume.labels[v] == mask.label ? 1 : 0;
  return mask;
}

MaskCleanup clean_mask(VoxelMask& mask) {
  const VoxelGrid& g = mask.grid;
  const std::size_t n = mask.inside.size();
  MaskCleanup report;
  std::vector<int> component(n, 0);
  std::vector<std::int64_t> stack;

  // Foreground components (6-connected); keep the largest (the first found wins a tie: scan order is fixed).
  auto is_fg = [&mask](std::int64_t v) { return mask.inside[static_cast<std::size_t>(v)] != 0; };
  int best = 0;
  std::int64_t best_size = 0, total = 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (!mask.inside[v] || component[v] != 0) continue;
    stack.assign(1, static_cast<std::int64_t>(v));
    const std::int64_t size = flood(g, stack, component, ++report.components, 6, is_fg);
    total += size;
    if (size > best_size) {
      best_size = size;
      best = report.components;
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (mask.inside[v] && component[v] != best) mask.inside[v] = 0;
  }
  report.removed_voxels = total - best_size;

  // Background reaching the border (18-connected, the complement of 6-connected foreground), then the rest.
  std::fill(component.begin(), component.end(), 0);
  auto is_bg = [&mask](std::int64_t v) { return mask.inside[static_cast<std::size_t>(v)] == 0; };
  for (int k = 0; k < g.size.z(); ++k) {
    for (int j = 0; j < g.size.y(); ++j) {
      for (int i = 0; i < g.size.x(); ++i) {
        const bool border = i == 0 || j == 0 || k == 0 || i == g.size.x() - 1 || j == g.size.y() - 1 ||
                            k == g.size.z() - 1;
        const std::int64_t v = g.index(i, j, k);
        if (!border || !is_bg(v) || component[static_cast<std::size_t>(v)] != 0) continue;
        stack.assign(1, v);
        flood(g, stack, component, 1, 18, is_bg);
      }
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (mask.inside[v] || component[v] != 0) continue;
    stack.assign(1, static_cast<std::int64_t>(v));
    report.filled_voxels += flood(g, stack, component, 2 + report.cavities++, 18, is_bg);
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (component[v] >= 2) mask.inside[v] = 1;
  }
  return report;
}

std::int64_t majority_filter(VoxelMask& mask, int passes) {
  const VoxelGrid& g = mask.grid;
  const int nx = g.size.x(), ny = g.size.y(), nz = g.size.z();
  const std::size_t n = mask.inside.size();
  std::vector<std::uint8_t> a(n), b(n);
  std::int64_t changed = 0;
  // Box sums by three 1D passes (values stay <= 27).
  auto pass = [&](const std::vector<std::uint8_t>& in, std::vector<std::uint8_t>& out, int axis) {
    const std::int64_t stride = axis == 0 ? 1 : (axis == 1 ? nx : std::int64_t{nx} * ny);
    const int len = g.size[axis];
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
          const std::int64_t v = g.index(i, j, k);
          const int pos = axis == 0 ? i : (axis == 1 ? j : k);
          int sum = in[static_cast<std::size_t>(v)];
          if (pos > 0) sum += in[static_cast<std::size_t>(v - stride)];
          if (pos + 1 < len) sum += in[static_cast<std::size_t>(v + stride)];
          out[static_cast<std::size_t>(v)] = static_cast<std::uint8_t>(sum);
        }
  };
  for (int p = 0; p < passes; ++p) {
    for (std::size_t v = 0; v < n; ++v) a[v] = mask.inside[v] ? 1 : 0;
    pass(a, b, 0);
    pass(b, a, 1);
    pass(a, b, 2);
    for (std::size_t v = 0; v < n; ++v) {
      const std::uint8_t now = b[v] >= 14 ? 1 : 0;
      if (now != (mask.inside[v] ? 1 : 0)) ++changed;
      mask.inside[v] = now;
    }
  }
  return changed;
}

LabelVolume voxelize(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& tris, double spacing,
                     int margin_voxels, std::int32_t label) {
  if (!(spacing > 0.0)) throw_error("voxelize: spacing must be positive, got ", spacing);
  if (tris.rows() == 0) throw_error("voxelize: the surface has no triangles");
  const Eigen::Vector3d lo = vertices.colwise().minCoeff(), hi = vertices.colwise().maxCoeff();
  LabelVolume volume;
  VoxelGrid& g = volume.grid;
  g.spacing = Eigen::Vector3d::Constant(spacing);
  for (int c = 0; c < 3; ++c) g.size[c] = static_cast<int>(std::ceil((hi[c] - lo[c]) / spacing)) + 1 + 2 * margin_voxels;
  // Centre the grid on the bounding box.
  const Eigen::Vector3d extent = (g.size.cast<double>() - Eigen::Vector3d::Ones()) * spacing;
  g.origin = 0.5 * (lo + hi) - 0.5 * extent;
  volume.labels.assign(static_cast<std::size_t>(g.voxel_count()), 0);
  volume.source = "<voxelized surface>";

  // Triangles binned by the columns (i, j) their xy-bounding box covers.
  const int nx = g.size.x(), ny = g.size.y();
  std::vector<std::vector<int>> bins(static_cast<std::size_t>(nx) * ny);
  for (int f = 0; f < tris.rows(); ++f) {
    Eigen::Vector2d a = vertices.row(tris(f, 0)).head<2>(), b = a;
    for (int k = 1; k < 3; ++k) {
      a = a.cwiseMin(vertices.row(tris(f, k)).head<2>().transpose());
      b = b.cwiseMax(vertices.row(tris(f, k)).head<2>().transpose());
    }
    const int i0 = std::max(0, static_cast<int>(std::floor((a.x() - g.origin.x()) / spacing)));
    const int i1 = std::min(nx - 1, static_cast<int>(std::ceil((b.x() - g.origin.x()) / spacing)));
    const int j0 = std::max(0, static_cast<int>(std::floor((a.y() - g.origin.y()) / spacing)));
    const int j1 = std::min(ny - 1, static_cast<int>(std::ceil((b.y() - g.origin.y()) / spacing)));
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) bins[static_cast<std::size_t>(j) * nx + i].push_back(f);
  }

  // Each column: the heights where the z-line through the voxel centres crosses the surface; a centre is inside
  // when an odd number of crossings lie below it. The line is nudged off the grid by an irrational fraction of a
  // voxel so that it never passes exactly through a vertex or an edge of a surface built on round coordinates.
  std::vector<double> crossings;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const double x = g.origin.x() + (i + 1e-4 * std::sqrt(2.0)) * spacing;
      const double y = g.origin.y() + (j + 1e-4 * std::sqrt(3.0)) * spacing;
      crossings.clear();
      for (int f : bins[static_cast<std::size_t>(j) * nx + i]) {
        const Eigen::Vector3d a = vertices.row(tris(f, 0)), b = vertices.row(tris(f, 1)), c = vertices.row(tris(f, 2));
        const double d = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
        if (d == 0.0) continue;  // vertical triangle: the line grazes it
        const double l1 = ((x - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (y - a.y())) / d;
        const double l2 = ((b.x() - a.x()) * (y - a.y()) - (x - a.x()) * (b.y() - a.y())) / d;
        if (l1 < 0.0 || l2 < 0.0 || l1 + l2 > 1.0) continue;
        crossings.push_back(a.z() + l1 * (b.z() - a.z()) + l2 * (c.z() - a.z()));
      }
      std::sort(crossings.begin(), crossings.end());
      std::size_t below = 0;
      for (int k = 0; k < g.size.z(); ++k) {
        const double z = g.origin.z() + k * spacing;
        while (below < crossings.size() && crossings[below] < z) ++below;
        if (below % 2 == 1) volume.labels[static_cast<std::size_t>(g.index(i, j, k))] = label;
      }
    }
  }
  return volume;
}

void add_label_noise(LabelVolume& volume, double probability, int speckles, std::uint32_t seed) {
  check_consistent(volume);
  const VoxelGrid& g = volume.grid;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const std::vector<std::int32_t> before = volume.labels;
  std::vector<std::int32_t> others;
  std::int32_t foreground = 0;
  for (int k = 0; k < g.size.z(); ++k) {
    for (int j = 0; j < g.size.y(); ++j) {
      for (int i = 0; i < g.size.x(); ++i) {
        const std::int32_t own = before[static_cast<std::size_t>(g.index(i, j, k))];
        if (own != 0 && foreground == 0) foreground = own;
        others.clear();
        for (int n = 0; n < 6; ++n) {
          const int a = i + kNeighbours[n][0], b = j + kNeighbours[n][1], c = k + kNeighbours[n][2];
          if (a < 0 || b < 0 || c < 0 || a >= g.size.x() || b >= g.size.y() || c >= g.size.z()) continue;
          const std::int32_t l = before[static_cast<std::size_t>(g.index(a, b, c))];
          if (l != own) others.push_back(l);
        }
        // Draw for every voxel so that the random sequence does not depend on where the boundary is.
        const double u = unit(rng);
        const std::size_t pick = static_cast<std::size_t>(unit(rng) * 6.0);
        if (others.empty() || u >= probability) continue;
        volume.labels[static_cast<std::size_t>(g.index(i, j, k))] = others[pick % others.size()];
      }
    }
  }
  if (foreground == 0) return;
  // Speckles: voxels whose 5 x 5 x 5 neighbourhood is all background (a bounded number of tries).
  std::uniform_int_distribution<int> di(0, g.size.x() - 1), dj(0, g.size.y() - 1), dk(0, g.size.z() - 1);
  for (int placed = 0, tries = 0; placed < speckles && tries < 1000 * speckles; ++tries) {
    const int i = di(rng), j = dj(rng), k = dk(rng);
    bool clear = true;
    for (int c = std::max(0, k - 2); clear && c <= std::min(g.size.z() - 1, k + 2); ++c)
      for (int b = std::max(0, j - 2); clear && b <= std::min(g.size.y() - 1, j + 2); ++b)
        for (int a = std::max(0, i - 2); clear && a <= std::min(g.size.x() - 1, i + 2); ++a)
          clear = volume.labels[static_cast<std::size_t>(g.index(a, b, c))] == 0;
    if (!clear) continue;
    volume.labels[static_cast<std::size_t>(g.index(i, j, k))] = foreground;
    ++placed;
  }
}

}  // namespace surgsim::imaging
