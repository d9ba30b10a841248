#include "intestine/broad_phase.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim::intestine {

namespace {

inline bool overlap(const double* alo, const double* ahi, const double* blo, const double* bhi) noexcept {
  // Non-short-circuit: six comparisons, no branch.
  return (alo[0] <= bhi[0]) & (blo[0] <= ahi[0]) & (alo[1] <= bhi[1]) & (blo[1] <= ahi[1]) & (alo[2] <= bhi[2]) &
         (blo[2] <= ahi[2]);
}

}  // namespace

BroadPhaseDetector::BroadPhaseDetector(CollisionTopology topology) : topo_(std::move(topology)) {
  if (topo_.rows < 2 || topo_.cols < 2 || topo_.grid.size() != static_cast<std::size_t>(topo_.rows * topo_.cols)) {
    throw_error("broad phase: the grid needs rows x cols >= 2 x 2 node indices");
  }
  if (!(topo_.intestine_radius > 0) || !(topo_.mesentery_half_thickness >= 0)) {
    throw_error("broad phase: radii must be positive");
  }
  nseg_ = topo_.segments();
  ncell_ = topo_.cells();
  cw_ = topo_.cols - 1;
  seg_node_.resize(2 * static_cast<std::size_t>(nseg_));
  for (int a = 0; a < nseg_; ++a) {
    seg_node_[2 * static_cast<std::size_t>(a)] = topo_.node(0, a);
    seg_node_[2 * static_cast<std::size_t>(a) + 1] = topo_.node(0, a + 1);
  }
  cell_node_.resize(4 * static_cast<std::size_t>(ncell_));
  for (int c = 0; c < ncell_; ++c) {
    const int r = c / cw_, k = c % cw_;
    int* n = &cell_node_[4 * static_cast<std::size_t>(c)];
    n[0] = topo_.node(r, k);
    n[1] = topo_.node(r, k + 1);
    n[2] = topo_.node(r + 1, k + 1);
    n[3] = topo_.node(r + 1, k);
  }
  cell_ok_ = topo_.cell_tested_table();
  seg_box_.resize(static_cast<std::size_t>(nseg_));
  cell_box_.resize(static_cast<std::size_t>(ncell_));
  seg_block_.resize(static_cast<std::size_t>((nseg_ + kBlock - 1) / kBlock));
  // Cell blocks: kBlock consecutive cells of one row (a block never spans two rows).
  for (int r = 0; r < topo_.rows - 1; ++r) {
    for (int k = 0; k < cw_; k += kBlock) {
      cell_block_first_.push_back(r * cw_ + k);
      cell_block_end_.push_back(r * cw_ + std::min(cw_, k + kBlock));
    }
  }
  cell_block_.resize(cell_block_first_.size());
  seg_sphere_.resize(static_cast<std::size_t>(nseg_));
  cell_sphere_.resize(static_cast<std::size_t>(ncell_));
  tri_axes_.resize(2 * static_cast<std::size_t>(ncell_));
  tri_stamp_.assign(2 * static_cast<std::size_t>(ncell_), 0u);
  const int nodes = *std::max_element(topo_.grid.begin(), topo_.grid.end()) + 1;
  if (*std::min_element(topo_.grid.begin(), topo_.grid.end()) < 0) throw_error("broad phase: negative node index");
  x_prev_.resize(3, nodes);
  travel_.assign(static_cast<std::size_t>(nseg_ + ncell_), 0.0);
  wake_.assign(static_cast<std::size_t>(nseg_) * static_cast<std::size_t>(nseg_ + ncell_), 0.0f);
  step_move_.assign(static_cast<std::size_t>(nseg_ + ncell_), 0.0);
  const std::size_t blocks = seg_block_.size() + cell_block_.size();
  block_travel_.assign(blocks, 0.0);
  block_wake_.assign(seg_block_.size() * blocks, 0.0);
}

BroadPhaseStats BroadPhaseDetector::detect(const Eigen::Matrix3Xd& x, ContactList& out, double margin) noexcept {
  BroadPhaseStats st;
  // Grown boxes: a pair of boxes overlaps whenever the reference's box cull keeps the pair (segment r_i + margin / 2,
  // cell r_m + margin / 2, so the sums are 2 r_i + margin and r_i + r_m + margin; a cell's box holds both triangles'),
  // plus a hair for rounding.
  const double hair = 1e-9;
  const double gs = topo_.intestine_radius + 0.5 * margin + hair;
  const double gt = topo_.mesentery_half_thickness + 0.5 * margin + hair;
  const double* px = x.data();
  for (int a = 0; a < nseg_; ++a) {
    const double* p = px + 3 * seg_node_[2 * static_cast<std::size_t>(a)];
    const double* q = px + 3 * seg_node_[2 * static_cast<std::size_t>(a) + 1];
    Box& b = seg_box_[static_cast<std::size_t>(a)];
    for (int k = 0; k < 3; ++k) {
      b.lo[k] = std::min(p[k], q[k]) - gs;
      b.hi[k] = std::max(p[k], q[k]) + gs;
    }
    const Eigen::Map<const Eigen::Vector3d> p0(p), p1(q);
    auto& sp = seg_sphere_[static_cast<std::size_t>(a)];
    sp.head<3>() = 0.5 * (p0 + p1);
    sp[3] = 0.5 * (p1 - p0).norm();
  }
  for (int c = 0; c < ncell_; ++c) {
    const int* n = &cell_node_[4 * static_cast<std::size_t>(c)];
    const double *p0 = px + 3 * n[0], *p1 = px + 3 * n[1], *p2 = px + 3 * n[2], *p3 = px + 3 * n[3];
    Box& b = cell_box_[static_cast<std::size_t>(c)];
    for (int k = 0; k < 3; ++k) {
      b.lo[k] = std::min(std::min(p0[k], p1[k]), std::min(p2[k], p3[k])) - gt;
      b.hi[k] = std::max(std::max(p0[k], p1[k]), std::max(p2[k], p3[k])) + gt;
    }
    const Eigen::Map<const Eigen::Vector3d> v0(p0), v1(p1), v2(p2), v3(p3);
    const Eigen::Vector3d g = 0.25 * (v0 + v1 + v2 + v3);
    auto& sp = cell_sphere_[static_cast<std::size_t>(c)];
    sp.head<3>() = g;
    sp[3] = std::sqrt(std::max(std::max((v0 - g).squaredNorm(), (v1 - g).squaredNorm()),
                               std::max((v2 - g).squaredNorm(), (v3 - g).squaredNorm())));
  }
  // Travel since the last call (nothing sleeps on the first call, after reset() or with another margin).
  const int nodes = static_cast<int>(x_prev_.cols());
  if (!have_prev_ || margin != last_margin_ || x.cols() < nodes) {
    for (auto* v : {&travel_, &block_travel_, &block_wake_}) std::fill(v->begin(), v->end(), 0.0);
    std::fill(wake_.begin(), wake_.end(), 0.0f);
  } else {
    auto move = [&](int n) { return (x.col(n) - x_prev_.col(n)).squaredNorm(); };
    for (int a = 0; a < nseg_; ++a) {
      const int* n = &seg_node_[2 * static_cast<std::size_t>(a)];
      step_move_[static_cast<std::size_t>(a)] = std::sqrt(std::max(move(n[0]), move(n[1])));
    }
    for (int k = 0; k < ncell_; ++k) {
      const int* n = &cell_node_[4 * static_cast<std::size_t>(k)];
      step_move_[static_cast<std::size_t>(nseg_ + k)] =
          std::sqrt(std::max(std::max(move(n[0]), move(n[1])), std::max(move(n[2]), move(n[3]))));
    }
    for (std::size_t e = 0; e < travel_.size(); ++e) travel_[e] += step_move_[e];
    const std::size_t nsb = seg_block_.size();
    for (std::size_t k = 0; k < nsb; ++k) {
      const int a0 = static_cast<int>(k) * kBlock, a1 = std::min(nseg_, a0 + kBlock);
      block_travel_[k] += *std::max_element(&step_move_[static_cast<std::size_t>(a0)],
                                            &step_move_[static_cast<std::size_t>(a1)]);
    }
    for (std::size_t k = 0; k < cell_block_.size(); ++k) {
      block_travel_[nsb + k] +=
          *std::max_element(&step_move_[static_cast<std::size_t>(nseg_ + cell_block_first_[k])],
                            &step_move_[static_cast<std::size_t>(nseg_ + cell_block_end_[k])]);
    }
  }
  if (x.cols() >= nodes) {
    x_prev_ = x.leftCols(nodes);
    have_prev_ = true;
  }
  last_margin_ = margin;
  const std::size_t wide = static_cast<std::size_t>(nseg_ + ncell_);
  // A pair asleep; and the wake of a pair found beyond the bound by `gap` (a hair less, for rounding).
  auto asleep = [&](int a, int e) {
    return travel_[static_cast<std::size_t>(a)] + travel_[static_cast<std::size_t>(e)] <
           static_cast<double>(wake_[static_cast<std::size_t>(a) * wide + static_cast<std::size_t>(e)]);
  };
  // How much more the two elements may travel before a sleeping pair wakes (<= 0: it is awake).
  auto slack = [&](int a, int e) {
    return static_cast<double>(wake_[static_cast<std::size_t>(a) * wide + static_cast<std::size_t>(e)]) -
           (travel_[static_cast<std::size_t>(a)] + travel_[static_cast<std::size_t>(e)]);
  };
  // Puts a pair to sleep; returns its slack (0 when the gap is too small to sleep on).
  auto sleep = [&](int a, int e, double gap) {
    float w = 0.0f;
    if (gap > hair) {
      const double wake = travel_[static_cast<std::size_t>(a)] + travel_[static_cast<std::size_t>(e)] + gap - hair;
      w = static_cast<float>(wake);
      if (static_cast<double>(w) > wake) w = std::nextafter(w, 0.0f);  // rounded down
    }
    wake_[static_cast<std::size_t>(a) * wide + static_cast<std::size_t>(e)] = w;
    return gap > hair ? slack(a, e) : 0.0;
  };
  // How far apart two grown boxes are (the largest gap along an axis; <= 0 when they overlap): the elements are at
  // least this much farther apart than the sum of their radii and the margin.
  auto box_gap = [](const Box& u, const Box& v) {
    double g = -std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) g = std::max(g, std::max(u.lo[k] - v.hi[k], v.lo[k] - u.hi[k]));
    return g;
  };

  const std::size_t blocks = block_travel_.size();
  auto block_asleep = [&](int i, int j) {
    return block_travel_[static_cast<std::size_t>(i)] + block_travel_[static_cast<std::size_t>(j)] <
           block_wake_[static_cast<std::size_t>(i) * blocks + static_cast<std::size_t>(j)];
  };
  // Puts a block pair to sleep for `gap`: the gap between their boxes, or the smallest slack of their element pairs
  // (pairs whose elements' boxes are apart from the other block's box count with that gap): an element's travel grows
  // by at most its block's, so until the two blocks have travelled that much every element pair in them is still
  // asleep, and none needs looking at. A gap within the hair leaves the pair awake.
  auto block_sleep = [&](int i, int j, double gap) {
    block_wake_[static_cast<std::size_t>(i) * blocks + static_cast<std::size_t>(j)] =
        gap > hair ? block_travel_[static_cast<std::size_t>(i)] + block_travel_[static_cast<std::size_t>(j)] + gap - hair
                   : 0.0;
  };

  // Refit the blocks.
  auto fit = [](Box& into, const Box* from, int count) {
    into = from[0];
    for (int i = 1; i < count; ++i) {
      for (int k = 0; k < 3; ++k) {
        into.lo[k] = std::min(into.lo[k], from[i].lo[k]);
        into.hi[k] = std::max(into.hi[k], from[i].hi[k]);
      }
    }
  };
  const int nsb = static_cast<int>(seg_block_.size()), ncb = static_cast<int>(cell_block_.size());
  for (int k = 0; k < nsb; ++k) {
    fit(seg_block_[static_cast<std::size_t>(k)], &seg_box_[static_cast<std::size_t>(k * kBlock)],
        std::min(kBlock, nseg_ - k * kBlock));
  }
  for (int k = 0; k < ncb; ++k) {
    const int first = cell_block_first_[static_cast<std::size_t>(k)];
    fit(cell_block_[static_cast<std::size_t>(k)], &cell_box_[static_cast<std::size_t>(first)],
        cell_block_end_[static_cast<std::size_t>(k)] - first);
  }

  CollisionContact c;
  auto push = [&](bool found) {
    if (!found) return;
    if (out.push(c)) {
      ++st.contacts;
    } else {
      ++st.overflow;
    }
  };
  // Cheap lower bounds before the exact tests (conservative: a pair they reject is not closer than the bound, so
  // the reference's exact test would not report it either).
  const double seg_bound = 2 * topo_.intestine_radius + margin;
  const double tri_bound = topo_.intestine_radius + topo_.mesentery_half_thickness + margin;
  if (++stamp_ == 0) {  // wrapped: no stale stamp may match
    std::fill(tri_stamp_.begin(), tri_stamp_.end(), 0u);
    stamp_ = 1;
  }
  // Bounding spheres of a segment and a cell: how much farther than the bound they are, or -1 when not.
  auto cell_gap = [&](int a, int cell) {
    const auto& ss = seg_sphere_[static_cast<std::size_t>(a)];
    const auto& cs = cell_sphere_[static_cast<std::size_t>(cell)];
    const double reach = tri_bound + ss[3] + cs[3];
    const double d2 = (ss.head<3>() - cs.head<3>()).squaredNorm();
    return d2 >= reach * reach ? std::sqrt(d2) - reach : -1.0;
  };
  // Separating axes of the segment and triangle t: its plane (both ends on the same side) and its three side planes
  // (both ends outside the same edge), each farther than the bound. Squared, no root: a gap g along an axis of
  // length L is at least the bound b when g >= 0 and g^2 >= b^2 L^2.
  const double tri_bound2 = tri_bound * tri_bound;
  auto triangle_gap = [&](int a, int t) {
    TriangleAxes& ax = tri_axes_[static_cast<std::size_t>(t)];
    if (tri_stamp_[static_cast<std::size_t>(t)] != stamp_) {
      tri_stamp_[static_cast<std::size_t>(t)] = stamp_;
      const int* n = &cell_node_[4 * static_cast<std::size_t>(t / 2)];
      // As CollisionTopology::triangle: corners (0, 1, 2) and (0, 2, 3) of the cell.
      const Eigen::Map<const Eigen::Vector3d> v[3] = {Eigen::Map<const Eigen::Vector3d>(px + 3 * n[0]),
                                                      Eigen::Map<const Eigen::Vector3d>(px + 3 * n[t % 2 == 0 ? 1 : 2]),
                                                      Eigen::Map<const Eigen::Vector3d>(px + 3 * n[t % 2 == 0 ? 2 : 3])};
      const Eigen::Vector3d nrm = (v[1] - v[0]).cross(v[2] - v[0]);
      for (int k = 0; k < 4; ++k) {
        const Eigen::Vector3d u = k == 0 ? nrm : Eigen::Vector3d((v[k % 3] - v[k - 1]).cross(nrm));
        const Eigen::Vector3d& on = k == 0 ? Eigen::Vector3d(v[0]) : Eigen::Vector3d(v[k - 1]);
        for (int i = 0; i < 3; ++i) ax.axis[k][i] = u[i];
        ax.offset[k] = u.dot(on);
        ax.length2[k] = u.squaredNorm();
      }
    }
    const double* p = px + 3 * seg_node_[2 * static_cast<std::size_t>(a)];
    const double* q = px + 3 * seg_node_[2 * static_cast<std::size_t>(a) + 1];
    double best = -1;
    for (int k = 0; k < 4; ++k) {
      const double* u = ax.axis[k];
      double g0 = u[0] * p[0] + u[1] * p[1] + u[2] * p[2] - ax.offset[k];
      double g1 = u[0] * q[0] + u[1] * q[1] + u[2] * q[2] - ax.offset[k];
      if (k == 0 && g0 < 0 && g1 < 0) {  // the plane: either side
        g0 = -g0;
        g1 = -g1;
      }
      const double g = std::min(g0, g1);
      if (g >= 0 && g * g >= tri_bound2 * ax.length2[k] && ax.length2[k] > 0) {
        best = std::max(best, g / std::sqrt(ax.length2[k]) - tri_bound);
      }
    }
    return best;
  };
  // Intestine-intestine: block pairs (i <= j), then segment pairs a < b that are tested.
  const int excl = topo_.segment_exclusion;
  for (int i = 0; i < nsb; ++i) {
    const Box& bi = seg_block_[static_cast<std::size_t>(i)];
    const int a0 = i * kBlock, a1 = std::min(nseg_, a0 + kBlock);
    for (int j = i; j < nsb; ++j) {
      const int b0 = j * kBlock, b1 = std::min(nseg_, b0 + kBlock);
      if (b1 - 1 - a0 <= excl) continue;  // every pair of the two blocks is a pair of neighbours
      if (block_asleep(i, j)) continue;
      const Box& bj = seg_block_[static_cast<std::size_t>(j)];
      if (!overlap(bi.lo, bi.hi, bj.lo, bj.hi)) {
        block_sleep(i, j, box_gap(bi, bj));
        continue;
      }
      double least = std::numeric_limits<double>::infinity();  // the block pair's smallest slack
      for (int a = a0; a < a1; ++a) {
        const Box& ba = seg_box_[static_cast<std::size_t>(a)];
        if (!overlap(ba.lo, ba.hi, bj.lo, bj.hi)) {
          least = std::min(least, box_gap(ba, bj));
          continue;
        }
        for (int b = std::max(b0, a + excl + 1); b < b1; ++b) {
          if (asleep(a, b)) {
            ++st.asleep;
            least = std::min(least, slack(a, b));
            continue;
          }
          const Box& bb = seg_box_[static_cast<std::size_t>(b)];
          if (!overlap(ba.lo, ba.hi, bb.lo, bb.hi)) {
            least = std::min(least, sleep(a, b, box_gap(ba, bb)));
            continue;
          }
          ++st.overlaps;
          // Bounding spheres: not closer than the contact distance (squared, no root unless rejected).
          const auto &sa = seg_sphere_[static_cast<std::size_t>(a)], &sb = seg_sphere_[static_cast<std::size_t>(b)];
          const double reach = seg_bound + sa[3] + sb[3];
          const double d2 = (sa.head<3>() - sb.head<3>()).squaredNorm();
          if (d2 >= reach * reach) {
            least = std::min(least, sleep(a, b, std::sqrt(d2) - reach));
            continue;
          }
          // The reference's distance; its contact only when closer than the bound.
          const double* p = px + 3 * seg_node_[2 * static_cast<std::size_t>(a)];
          const double* q = px + 3 * seg_node_[2 * static_cast<std::size_t>(b)];
          double s_ = 0, t_ = 0;
          const double d = segment_segment(Eigen::Map<const Eigen::Vector3d>(p),
                                           Eigen::Map<const Eigen::Vector3d>(px + 3 * seg_node_[2 * a + 1]),
                                           Eigen::Map<const Eigen::Vector3d>(q),
                                           Eigen::Map<const Eigen::Vector3d>(px + 3 * seg_node_[2 * b + 1]), s_, t_);
          least = std::min(least, sleep(a, b, d - seg_bound));
          if (d < seg_bound) {
            segment_contact_at(topo_, x, a, b, d, s_, t_, c);  // the contact segment_contact would build
            push(true);
          }
        }
      }
      block_sleep(i, j, least);
    }
  }
  // Intestine-mesentery: segment block x cell block, then segment x cell, then both triangles of the cell.
  for (int i = 0; i < nsb; ++i) {
    const Box& bi = seg_block_[static_cast<std::size_t>(i)];
    const int a0 = i * kBlock, a1 = std::min(nseg_, a0 + kBlock);
    for (int j = 0; j < ncb; ++j) {
      if (block_asleep(i, nsb + j)) continue;
      const Box& bj = cell_block_[static_cast<std::size_t>(j)];
      if (!overlap(bi.lo, bi.hi, bj.lo, bj.hi)) {
        block_sleep(i, nsb + j, box_gap(bi, bj));
        continue;
      }
      const int c0 = cell_block_first_[static_cast<std::size_t>(j)], c1 = cell_block_end_[static_cast<std::size_t>(j)];
      double least = std::numeric_limits<double>::infinity();  // the block pair's smallest slack
      for (int a = a0; a < a1; ++a) {
        const Box& ba = seg_box_[static_cast<std::size_t>(a)];
        if (!overlap(ba.lo, ba.hi, bj.lo, bj.hi)) {
          least = std::min(least, box_gap(ba, bj));
          continue;
        }
        const char* ok = &cell_ok_[static_cast<std::size_t>(a) * static_cast<std::size_t>(ncell_)];
        for (int cell = c0; cell < c1; ++cell) {
          if (!ok[cell]) continue;
          if (asleep(a, nseg_ + cell)) {
            ++st.asleep;
            least = std::min(least, slack(a, nseg_ + cell));
            continue;
          }
          const Box& bc = cell_box_[static_cast<std::size_t>(cell)];
          if (!overlap(ba.lo, ba.hi, bc.lo, bc.hi)) {
            least = std::min(least, sleep(a, nseg_ + cell, box_gap(ba, bc)));
            continue;
          }
          ++st.overlaps;
          const double cg = cell_gap(a, cell);
          if (cg >= 0) {
            least = std::min(least, sleep(a, nseg_ + cell, cg));
            continue;
          }
          double gap = std::numeric_limits<double>::infinity();
          for (int t = 2 * cell; t < 2 * cell + 2; ++t) {
            const double tg = triangle_gap(a, t);
            if (tg >= 0) {
              gap = std::min(gap, tg);
              continue;
            }
            // The reference's exact distance; its contact only when closer than the bound.
            const int* n = &cell_node_[4 * static_cast<std::size_t>(cell)];
            const int* sn = &seg_node_[2 * static_cast<std::size_t>(a)];
            double s_ = 0;
            Eigen::Vector3d bary;
            const double d = segment_triangle(Eigen::Map<const Eigen::Vector3d>(px + 3 * sn[0]),
                                              Eigen::Map<const Eigen::Vector3d>(px + 3 * sn[1]),
                                              Eigen::Map<const Eigen::Vector3d>(px + 3 * n[0]),
                                              Eigen::Map<const Eigen::Vector3d>(px + 3 * n[t % 2 == 0 ? 1 : 2]),
                                              Eigen::Map<const Eigen::Vector3d>(px + 3 * n[t % 2 == 0 ? 2 : 3]), s_,
                                              bary);
            gap = std::min(gap, d - tri_bound);
            if (d < tri_bound) {
              triangle_contact_at(topo_, x, a, t, d, s_, bary, c);  // the contact triangle_contact would build
              push(true);
            }
          }
          least = std::min(least, sleep(a, nseg_ + cell, gap));
        }
      }
      block_sleep(i, nsb + j, least);
    }
  }
  return st;
}

}  // namespace surgsim::intestine
