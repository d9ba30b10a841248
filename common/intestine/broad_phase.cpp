#include "intestine/broad_phase.h"

#include <algorithm>
#include <numeric>

#include "core/error.h"

namespace surgsim::intestine {

BroadPhaseDetector::BroadPhaseDetector(CollisionTopology topology) : topo_(std::move(topology)) {
  if (topo_.rows < 2 || topo_.cols < 2 || topo_.grid.size() != static_cast<std::size_t>(topo_.rows * topo_.cols)) {
    throw_error("broad phase: the grid needs rows x cols >= 2 x 2 node indices");
  }
  if (!(topo_.intestine_radius > 0) || !(topo_.mesentery_half_thickness >= 0)) {
    throw_error("broad phase: radii must be positive");
  }
  const int nseg = topo_.segments(), ntri = 2 * topo_.cells();
  seg_node_.resize(2 * static_cast<std::size_t>(nseg));
  for (int a = 0; a < nseg; ++a) {
    seg_node_[2 * static_cast<std::size_t>(a)] = topo_.node(0, a);
    seg_node_[2 * static_cast<std::size_t>(a) + 1] = topo_.node(0, a + 1);
  }
  tri_node_.resize(3 * static_cast<std::size_t>(ntri));
  for (int t = 0; t < ntri; ++t) topo_.triangle(t, &tri_node_[3 * static_cast<std::size_t>(t)]);
  cell_ok_.resize(static_cast<std::size_t>(nseg) * static_cast<std::size_t>(topo_.cells()));
  for (int a = 0; a < nseg; ++a) {
    for (int c = 0; c < topo_.cells(); ++c) {
      cell_ok_[static_cast<std::size_t>(a) * static_cast<std::size_t>(topo_.cells()) + static_cast<std::size_t>(c)] =
          topo_.cell_tested(a, c);
    }
  }
  const std::size_t n = static_cast<std::size_t>(nseg + ntri);
  lo_.resize(n);
  hi_.resize(n);
  seg_order_.resize(static_cast<std::size_t>(nseg));
  std::iota(seg_order_.begin(), seg_order_.end(), 0);
  tri_order_.resize(static_cast<std::size_t>(ntri));
  std::iota(tri_order_.begin(), tri_order_.end(), nseg);
  (void)n;
}

BroadPhaseStats BroadPhaseDetector::detect(const Eigen::Matrix3Xd& x, ContactList& out, double margin) noexcept {
  BroadPhaseStats st;
  const int nseg = topo_.segments(), ntri = 2 * topo_.cells(), n = nseg + ntri, ncell = topo_.cells();
  // Grown boxes: a pair of boxes overlaps exactly when the reference's box cull keeps it (segment r_i + margin / 2,
  // triangle r_m + margin / 2, so the sums are 2 r_i + margin and r_i + r_m + margin), plus a hair for rounding.
  const double hair = 1e-9;
  const double gs = topo_.intestine_radius + 0.5 * margin + hair;
  const double gt = topo_.mesentery_half_thickness + 0.5 * margin + hair;
  Eigen::Vector3d gmin = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d gmax = -gmin;
  for (int a = 0; a < nseg; ++a) {
    const auto p0 = x.col(seg_node_[2 * static_cast<std::size_t>(a)]);
    const auto p1 = x.col(seg_node_[2 * static_cast<std::size_t>(a) + 1]);
    lo_[static_cast<std::size_t>(a)] = p0.cwiseMin(p1).array() - gs;
    hi_[static_cast<std::size_t>(a)] = p0.cwiseMax(p1).array() + gs;
  }
  for (int t = 0; t < ntri; ++t) {
    const int* m = &tri_node_[3 * static_cast<std::size_t>(t)];
    const auto A = x.col(m[0]), B = x.col(m[1]), C = x.col(m[2]);
    lo_[static_cast<std::size_t>(nseg + t)] = A.cwiseMin(B).cwiseMin(C).array() - gt;
    hi_[static_cast<std::size_t>(nseg + t)] = A.cwiseMax(B).cwiseMax(C).array() + gt;
  }
  for (int e = 0; e < n; ++e) {
    gmin = gmin.cwiseMin(lo_[static_cast<std::size_t>(e)]);
    gmax = gmax.cwiseMax(hi_[static_cast<std::size_t>(e)]);
  }
  // The sweep axis: the widest spread (fewest overlaps along it). Keep the last axis unless another is 20 % wider,
  // so that the order stays nearly sorted from step to step.
  int axis = 0;
  (gmax - gmin).maxCoeff(&axis);
  if (axis_ >= 0 && (gmax - gmin)[axis] < 1.2 * (gmax - gmin)[axis_]) axis = axis_;
  auto key = [&](int e) { return lo_[static_cast<std::size_t>(e)][axis]; };
  auto before = [&](int u, int v) { return key(u) < key(v) || (key(u) == key(v) && u < v); };
  for (auto* order : {&seg_order_, &tri_order_}) {
    if (axis != axis_) {
      std::sort(order->begin(), order->end(), before);
      continue;
    }
    for (std::size_t i = 1; i < order->size(); ++i) {  // insertion sort: linear when nearly sorted
      const int e = (*order)[i];
      std::size_t j = i;
      while (j > 0 && before(e, (*order)[j - 1])) {
        (*order)[j] = (*order)[j - 1];
        --j;
      }
      (*order)[j] = e;
    }
  }
  axis_ = axis;
  const int o1 = (axis + 1) % 3, o2 = (axis + 2) % 3;
  auto overlap = [&](int u, int v) {
    const auto &lu = lo_[static_cast<std::size_t>(u)], &hu = hi_[static_cast<std::size_t>(u)];
    const auto &lv = lo_[static_cast<std::size_t>(v)], &hv = hi_[static_cast<std::size_t>(v)];
    return lu[o1] <= hv[o1] && lv[o1] <= hu[o1] && lu[o2] <= hv[o2] && lv[o2] <= hu[o2];
  };
  CollisionContact c;
  auto push = [&](bool found) {
    if (!found) return;
    if (out.push(c)) {
      ++st.contacts;
    } else {
      ++st.overflow;
    }
  };
  auto tested_cell = [&](int seg, int tri) {
    const std::size_t key =
        static_cast<std::size_t>(seg) * static_cast<std::size_t>(ncell) + static_cast<std::size_t>(tri / 2);
    return cell_ok_[key] != 0;
  };
  auto seg_tri = [&](int seg, int e) {
    if (!tested_cell(seg, e - nseg) || !overlap(seg, e)) return;
    ++st.overlaps;
    push(triangle_contact(topo_, x, seg, e - nseg, margin, c));
  };
  // Segments: against the segments and the triangles that start inside their extent (a triangle starting at the same
  // place as the segment counts here, one starting before it below).
  std::size_t t0 = 0;
  for (std::size_t i = 0; i < seg_order_.size(); ++i) {
    const int e = seg_order_[i];
    const double end = hi_[static_cast<std::size_t>(e)][axis];
    for (std::size_t j = i + 1; j < seg_order_.size() && key(seg_order_[j]) <= end; ++j) {
      const int u = seg_order_[j];
      if (!topo_.segments_tested(u, e) || !overlap(u, e)) continue;
      ++st.overlaps;
      push(segment_contact(topo_, x, std::min(u, e), std::max(u, e), margin, c));
    }
    while (t0 < tri_order_.size() && key(tri_order_[t0]) < key(e)) ++t0;
    for (std::size_t j = t0; j < tri_order_.size() && key(tri_order_[j]) <= end; ++j) seg_tri(e, tri_order_[j]);
  }
  // Triangles: against the segments that start strictly inside their extent.
  std::size_t s0 = 0;
  for (const int e : tri_order_) {
    const double end = hi_[static_cast<std::size_t>(e)][axis];
    while (s0 < seg_order_.size() && key(seg_order_[s0]) <= key(e)) ++s0;
    for (std::size_t j = s0; j < seg_order_.size() && key(seg_order_[j]) <= end; ++j) seg_tri(seg_order_[j], e);
  }
  return st;
}

}  // namespace surgsim::intestine
