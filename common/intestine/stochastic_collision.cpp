#include "intestine/stochastic_collision.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <set>
#include <tuple>
#include <utility>

#include "mesh/geometry.h"
#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::intestine {

namespace {

constexpr double kTiny = 1e-12;
constexpr double kContactEps = 1e-9;  // m: below this the closest points give no direction
constexpr double kMarginEps = 1e-9;   // m: a margin left below this is spent (rounding of the distances)

double clamp01(double v) { return v < 0 ? 0 : (v > 1 ? 1 : v); }

// A unit vector orthogonal to d (any, deterministic).
Eigen::Vector3d orthogonal(const Eigen::Vector3d& d) {
  const Eigen::Vector3d axis =
      std::abs(d.x()) < std::abs(d.y()) ? (std::abs(d.x()) < std::abs(d.z()) ? Eigen::Vector3d::UnitX()
                                                                               : Eigen::Vector3d::UnitZ())
                                        : (std::abs(d.y()) < std::abs(d.z()) ? Eigen::Vector3d::UnitY()
                                                                             : Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d o = d.cross(axis);
  const double n = o.norm();
  return n > kTiny ? Eigen::Vector3d(o / n) : Eigen::Vector3d::UnitZ();
}

}  // namespace

double segment_segment(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                       const Eigen::Vector3d& q1, double& s, double& t) noexcept {
  const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  if (a <= kTiny && e <= kTiny) {
    s = t = 0;
  } else if (a <= kTiny) {
    s = 0;
    t = clamp01(f / e);
  } else {
    const double c = d1.dot(r);
    if (e <= kTiny) {
      t = 0;
      s = clamp01(-c / a);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;
      if (denom > 1e-10 * a * e) {
        s = clamp01((b * f - c * e) / denom);
      } else {
        // (Nearly) parallel: the middle of the overlap of q's projection on p, so that the contact is centred.
        const double u0 = clamp01(-c / a), u1 = clamp01((b - c) / a);
        s = 0.5 * (u0 + u1);
      }
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = clamp01(-c / a);
      } else if (t > 1) {
        t = 1;
        s = clamp01((b - c) / a);
      }
    }
  }
  return ((p0 + s * d1) - (q0 + t * d2)).norm();
}

namespace {

// A lower bound of the distance from segment [p0, p1] to triangle (a, b, c) from the triangle's plane: the nearer
// end's distance when both ends are on the same side, else 0.
double plane_bound(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                   const Eigen::Vector3d& b, const Eigen::Vector3d& c) noexcept {
  const Eigen::Vector3d nrm = (b - a).cross(c - a);
  const double nn = nrm.norm();
  if (!(nn > kTiny)) return 0;
  const double d0 = (p0 - a).dot(nrm) / nn, d1 = (p1 - a).dot(nrm) / nn;
  return d0 * d1 > 0 ? std::min(std::abs(d0), std::abs(d1)) : 0.0;
}

// The exact segment-triangle distance (segment_triangle without the bound).
double segment_triangle_exact(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, const Eigen::Vector3d& c, double& s,
                              Eigen::Vector3d& bary) noexcept {
  const Eigen::Vector3d e1 = b - a, e2 = c - a, d = p1 - p0;
  // The segment crossing the triangle (Moller-Trumbore restricted to [p0, p1]).
  const Eigen::Vector3d h = d.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) > kTiny * e1.norm() * e2.norm() * (d.norm() + kTiny)) {
    const double inv = 1.0 / det;
    const Eigen::Vector3d sv = p0 - a;
    const double u = inv * sv.dot(h);
    if (u >= 0 && u <= 1) {
      const Eigen::Vector3d q = sv.cross(e1);
      const double v = inv * d.dot(q);
      const double tt = inv * e2.dot(q);
      if (v >= 0 && u + v <= 1 && tt >= 0 && tt <= 1) {
        s = tt;
        bary = Eigen::Vector3d(1 - u - v, u, v);
        return 0;
      }
    }
  }
  // Point-triangle: the segment's ends.
  Eigen::Vector3d b0, b1;
  const double dd0 = (closest_point_triangle(p0, a, b, c, b0) - p0).norm();
  const double dd1 = (closest_point_triangle(p1, a, b, c, b1) - p1).norm();
  double best = dd0;
  s = 0;
  bary = b0;
  if (dd1 < best) {
    best = dd1;
    s = 1;
    bary = b1;
  }
  // Both ends above the triangle's interior and no crossing: the segment lies over the triangle, the distance to the
  // plane is linear along it, so an end is the closest point and the edges need no test.
  if ((b0.array() > 0).all() && (b1.array() > 0).all()) return best;
  // Edge-triangle: the segment against each edge, unless their bounding spheres are already farther than the best.
  const Eigen::Vector3d* v[3] = {&a, &b, &c};
  const Eigen::Vector3d m = 0.5 * (p0 + p1);
  const double hl = 0.5 * d.norm();
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d& e0 = *v[k];
    const Eigen::Vector3d& e1k = *v[(k + 1) % 3];
    const double reach = best + hl + 0.5 * (e1k - e0).norm();
    if ((m - 0.5 * (e0 + e1k)).squaredNorm() >= reach * reach) continue;
    double ss = 0, tt = 0;
    const double dd = segment_segment(p0, p1, *v[k], *v[(k + 1) % 3], ss, tt);
    if (dd < best) {
      best = dd;
      s = ss;
      bary.setZero();
      bary[k] = 1 - tt;
      bary[(k + 1) % 3] = tt;
    }
  }
  return best;
}

}  // namespace

double segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
                        const Eigen::Vector3d& b, const Eigen::Vector3d& c, double& s, Eigen::Vector3d& bary,
                        double bound) noexcept {
  if (bound < std::numeric_limits<double>::infinity()) {
    // Bounding spheres: segment about its middle, triangle about its centroid.
    const Eigen::Vector3d m = 0.5 * (p0 + p1), g = (a + b + c) / 3.0;
    const double rt = std::sqrt(std::max({(a - g).squaredNorm(), (b - g).squaredNorm(), (c - g).squaredNorm()}));
    if ((m - g).norm() - 0.5 * (p1 - p0).norm() - rt >= bound) return std::numeric_limits<double>::infinity();
    // The triangle's plane, when both ends are on the same side.
    if (plane_bound(p0, p1, a, b, c) >= bound) return std::numeric_limits<double>::infinity();
  }
  return segment_triangle_exact(p0, p1, a, b, c, s, bary);
}

void CollisionTopology::triangle(int t, int out[3]) const {
  const int cell = t / 2, r = cell / (cols - 1), c = cell % (cols - 1);
  if (t % 2 == 0) {
    out[0] = node(r, c);
    out[1] = node(r, c + 1);
    out[2] = node(r + 1, c + 1);
  } else {
    out[0] = node(r, c);
    out[1] = node(r + 1, c + 1);
    out[2] = node(r + 1, c);
  }
}

bool CollisionTopology::segments_tested(int a, int b) const {
  return a >= 0 && b >= 0 && a < segments() && b < segments() && std::abs(a - b) > segment_exclusion;
}

std::vector<char> CollisionTopology::cell_tested_table() const {
  const int nseg = segments(), ncell = cells();
  std::vector<char> ok(static_cast<std::size_t>(nseg) * static_cast<std::size_t>(ncell));
  for (int a = 0; a < nseg; ++a) {
    for (int c = 0; c < ncell; ++c) {
      ok[static_cast<std::size_t>(a) * static_cast<std::size_t>(ncell) + static_cast<std::size_t>(c)] =
          cell_tested(a, c);
    }
  }
  return ok;
}

bool CollisionTopology::cell_tested(int segment, int cell) const {
  if (segment < 0 || segment >= segments() || cell < 0 || cell >= cells()) return false;
  const int r = cell / (cols - 1), c = cell % (cols - 1);
  // Row 0, and every row in the tapered columns at either end (the tube lies on its narrowed mesentery there).
  const bool taper = c < taper_columns || c >= (cols - 1) - taper_columns;
  if ((r == 0 || taper) && std::abs(c - segment) <= cell_exclusion) return false;
  // Never a cell that shares a node with the segment.
  const int sa = node(0, segment), sb = node(0, segment + 1);
  for (int rr = r; rr <= r + 1; ++rr) {
    for (int cc = c; cc <= c + 1; ++cc) {
      const int n = node(rr, cc);
      if (n == sa || n == sb) return false;
    }
  }
  return true;
}

StochasticDetector::StochasticDetector(CollisionTopology topology, const StochasticParams& params)
    : topo_(std::move(topology)), params_(params) {
  if (topo_.rows < 2 || topo_.cols < 2 || topo_.grid.size() != static_cast<std::size_t>(topo_.rows * topo_.cols)) {
    throw_error("stochastic collision: the grid needs rows x cols >= 2 x 2 node indices");
  }
  if (!(topo_.intestine_radius > 0) || !(topo_.mesentery_half_thickness >= 0) || topo_.segment_exclusion < 0 ||
      topo_.cell_exclusion < 0) {
    throw_error("stochastic collision: radii must be positive and exclusions >= 0");
  }
  if (params_.capacity < 1 || params_.random_pairs < 0 || params_.random_mesentery_pairs < 0 ||
      params_.max_moves < 0 || params_.new_pair_moves < 0 || !(params_.drop_factor >= 1) || params_.zone_budget < 0) {
    throw_error("stochastic collision: capacity >= 1, random pairs >= 0, moves >= 0, drop_factor >= 1, "
                "zone_budget >= 0");
  }
  zone_.resize(static_cast<std::size_t>(params_.zone_budget) + 1);
  seg_pairs_.resize(static_cast<std::size_t>(params_.capacity));
  cell_pairs_.resize(static_cast<std::size_t>(params_.capacity));
  seg_owner_.assign(static_cast<std::size_t>(topo_.segments()) * static_cast<std::size_t>(topo_.segments()), 0);
  cell_owner_.assign(static_cast<std::size_t>(topo_.segments()) * static_cast<std::size_t>(topo_.cells()), 0);
  seg_reported_.assign(seg_owner_.size(), 0);
  cell_reported_.assign(cell_owner_.size(), 0);
  seg_clear_.assign(seg_owner_.size(), 0);
  cell_clear_.assign(cell_owner_.size(), 0);
  seg_memo_stamp_.assign(seg_owner_.size(), 0);
  cell_memo_stamp_.assign(cell_owner_.size(), 0);
  seg_memo_index_.assign(seg_owner_.size(), 0);
  cell_memo_index_.assign(cell_owner_.size(), 0);
  memo_pool_.resize(8192);
  // Element tables.
  nseg_ = topo_.segments();
  ncell_ = topo_.cells();
  nodes_ = *std::max_element(topo_.grid.begin(), topo_.grid.end()) + 1;
  if (*std::min_element(topo_.grid.begin(), topo_.grid.end()) < 0) throw_error("stochastic collision: negative node");
  seg_node_.resize(2 * static_cast<std::size_t>(nseg_));
  for (int a = 0; a < nseg_; ++a) {
    seg_node_[2 * static_cast<std::size_t>(a)] = topo_.node(0, a);
    seg_node_[2 * static_cast<std::size_t>(a) + 1] = topo_.node(0, a + 1);
  }
  tri_node_.resize(6 * static_cast<std::size_t>(ncell_));
  for (int t = 0; t < 2 * ncell_; ++t) topo_.triangle(t, &tri_node_[3 * static_cast<std::size_t>(t)]);
  cell_ok_ = topo_.cell_tested_table();
  seg_sphere_.resize(static_cast<std::size_t>(nseg_));
  tri_sphere_.resize(2 * static_cast<std::size_t>(ncell_));
  cell_sphere_.resize(static_cast<std::size_t>(ncell_));
  x_prev_.resize(3, nodes_);
  node_move_.resize(static_cast<std::size_t>(nodes_));
  seg_move_.resize(static_cast<std::size_t>(nseg_));
  seg_near_move_.resize(static_cast<std::size_t>(nseg_));
  cell_move_.resize(static_cast<std::size_t>(ncell_));
  cell_near_move_.resize(static_cast<std::size_t>(ncell_));
  seg_margin_.resize(static_cast<std::size_t>(params_.capacity));
  cell_margin_.resize(static_cast<std::size_t>(params_.capacity));
  seg_gap_.resize(static_cast<std::size_t>(params_.capacity));
  cell_gap_.resize(static_cast<std::size_t>(params_.capacity));
  reset(params_.seed);
}

void StochasticDetector::set_random_pairs(int segment_pairs, int mesentery_pairs) noexcept {
  params_.random_pairs = std::max(0, segment_pairs);
  params_.random_mesentery_pairs = std::max(0, mesentery_pairs);
}

void StochasticDetector::reset(std::uint64_t seed) noexcept {
  rng_ = seed;
  seg_count_ = cell_count_ = 0;
  clear_tables();
  stamp_ = 0;
  have_prev_ = false;
}

void StochasticDetector::clear_tables() noexcept {
  for (auto* t : {&seg_owner_, &cell_owner_, &seg_reported_, &cell_reported_, &seg_clear_, &cell_clear_,
                  &seg_memo_stamp_, &cell_memo_stamp_}) {
    std::fill(t->begin(), t->end(), 0u);
  }
}

void StochasticDetector::cache_step(const Eigen::Matrix3Xd& x) noexcept {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (int a = 0; a < nseg_; ++a) {
    const auto p0 = x.col(seg_node_[2 * static_cast<std::size_t>(a)]);
    const auto p1 = x.col(seg_node_[2 * static_cast<std::size_t>(a) + 1]);
    auto& sp = seg_sphere_[static_cast<std::size_t>(a)];
    sp.head<3>() = 0.5 * (p0 + p1);
    sp[3] = 0.5 * (p1 - p0).norm();
  }
  for (int t = 0; t < 2 * ncell_; ++t) {
    const int* n = &tri_node_[3 * static_cast<std::size_t>(t)];
    const auto a = x.col(n[0]), b = x.col(n[1]), c = x.col(n[2]);
    // As segment_triangle's bound: the centroid and the farthest corner.
    const Eigen::Vector3d g = (a + b + c) / 3.0;
    auto& sp = tri_sphere_[static_cast<std::size_t>(t)];
    sp.head<3>() = g;
    sp[3] = std::sqrt(std::max({(a - g).squaredNorm(), (b - g).squaredNorm(), (c - g).squaredNorm()}));
  }
  for (int c = 0; c < ncell_; ++c) {
    const int* n = &tri_node_[6 * static_cast<std::size_t>(c)];  // triangle 2c: (r,c) (r,c+1) (r+1,c+1)
    const int n3 = tri_node_[6 * static_cast<std::size_t>(c) + 5];  // triangle 2c+1: ..., (r+1,c)
    const Eigen::Vector3d g = 0.25 * (x.col(n[0]) + x.col(n[1]) + x.col(n[2]) + x.col(n3));
    auto& sp = cell_sphere_[static_cast<std::size_t>(c)];
    sp.head<3>() = g;
    sp[3] = std::sqrt(std::max({(x.col(n[0]) - g).squaredNorm(), (x.col(n[1]) - g).squaredNorm(),
                                (x.col(n[2]) - g).squaredNorm(), (x.col(n3) - g).squaredNorm()}));
  }
  // Displacements since the last step (infinite on the first): bound how much any element distance has changed.
  // node_move_ holds squares; the elements' are square roots of the largest.
  for (int n = 0; n < nodes_; ++n) {
    node_move_[static_cast<std::size_t>(n)] = have_prev_ ? (x.col(n) - x_prev_.col(n)).squaredNorm() : kInf;
  }
  x_prev_ = x.leftCols(nodes_);
  have_prev_ = true;
  for (int a = 0; a < nseg_; ++a) {
    const double m0 = node_move_[static_cast<std::size_t>(seg_node_[2 * static_cast<std::size_t>(a)])];
    const double m1 = node_move_[static_cast<std::size_t>(seg_node_[2 * static_cast<std::size_t>(a) + 1])];
    seg_move_[static_cast<std::size_t>(a)] = std::sqrt(std::max(m0, m1));
  }
  for (int a = 0; a < nseg_; ++a) {
    double m = seg_move_[static_cast<std::size_t>(a)];
    if (a > 0) m = std::max(m, seg_move_[static_cast<std::size_t>(a - 1)]);
    if (a + 1 < nseg_) m = std::max(m, seg_move_[static_cast<std::size_t>(a + 1)]);
    seg_near_move_[static_cast<std::size_t>(a)] = m;
  }
  for (int c = 0; c < ncell_; ++c) {
    const int* n = &tri_node_[6 * static_cast<std::size_t>(c)];
    const int n3 = tri_node_[6 * static_cast<std::size_t>(c) + 5];
    cell_move_[static_cast<std::size_t>(c)] =
        std::sqrt(std::max({node_move_[static_cast<std::size_t>(n[0])], node_move_[static_cast<std::size_t>(n[1])],
                            node_move_[static_cast<std::size_t>(n[2])], node_move_[static_cast<std::size_t>(n3)]}));
  }
  const int cw = topo_.cols - 1, cr = topo_.rows - 1;
  for (int r = 0; r < cr; ++r) {
    for (int c = 0; c < cw; ++c) {
      double m = 0;
      for (int rr = std::max(0, r - 1); rr <= std::min(cr - 1, r + 1); ++rr) {
        for (int cc = std::max(0, c - 1); cc <= std::min(cw - 1, c + 1); ++cc) {
          m = std::max(m, cell_move_[static_cast<std::size_t>(rr * cw + cc)]);
        }
      }
      cell_near_move_[static_cast<std::size_t>(r * cw + c)] = m;
    }
  }
}

// splitmix64: small state, fast, and identical on every platform (std distributions are not).
std::uint64_t StochasticDetector::next_random() noexcept {
  std::uint64_t z = (rng_ += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

int StochasticDetector::uniform(int n) noexcept {
  return static_cast<int>((next_random() >> 11) * (1.0 / 9007199254740992.0) * n);
}

double StochasticDetector::compute_segments(const Eigen::Matrix3Xd& x, int a, int b, double bound,
                                            ActivePair& out) noexcept {
  ++tests_;
  if (bound < std::numeric_limits<double>::infinity()) {
    // Bounding spheres: not closer than the bound, out unchanged; returns the lower bound.
    const auto& sa = seg_sphere_[static_cast<std::size_t>(a)];
    const auto& sb = seg_sphere_[static_cast<std::size_t>(b)];
    const double lb = (sa.head<3>() - sb.head<3>()).norm() - sa[3] - sb[3];
    if (lb >= bound) return lb;
  }
  const auto p0 = x.col(seg_node_[2 * static_cast<std::size_t>(a)]);
  const auto p1 = x.col(seg_node_[2 * static_cast<std::size_t>(a) + 1]);
  const auto q0 = x.col(seg_node_[2 * static_cast<std::size_t>(b)]);
  const auto q1 = x.col(seg_node_[2 * static_cast<std::size_t>(b) + 1]);
  double s = 0, t = 0;
  const double d = segment_segment(p0, p1, q0, q1, s, t);
  out.a = a;
  out.b = b;
  out.tri = 0;
  out.distance = d;
  out.s = s;
  out.wb = Eigen::Vector3d(1 - t, t, 0);
  if (d > kContactEps) {
    out.normal = ((p0 + s * (p1 - p0)) - (q0 + t * (q1 - q0))) / d;
  } else if (out.normal.squaredNorm() < 0.5) {
    out.normal = orthogonal(p1 - p0);
  }
  return d;
}

double StochasticDetector::eval_segments(const Eigen::Matrix3Xd& x, int a, int b, double bound,
                                         ActivePair& out) noexcept {
  return eval(x, false, a, b, bound, out);
}

double StochasticDetector::eval_cell(const Eigen::Matrix3Xd& x, int seg, int cell, double bound,
                                     ActivePair& out) noexcept {
  return eval(x, true, seg, cell, bound, out);
}

double StochasticDetector::eval(const Eigen::Matrix3Xd& x, bool mes, int a, int b, double bound,
                                ActivePair& out) noexcept {
  const std::size_t key =
      static_cast<std::size_t>(a) * static_cast<std::size_t>(mes ? ncell_ : nseg_) + static_cast<std::size_t>(b);
  auto& stamp = (mes ? cell_memo_stamp_ : seg_memo_stamp_)[key];
  auto& index = (mes ? cell_memo_index_ : seg_memo_index_)[key];
  Memo* m = nullptr;
  if (stamp == stamp_) {
    m = &memo_pool_[index];
    if (m->exact) {
      if (m->value < bound) {
        const Eigen::Vector3d side = out.normal;
        out = m->pair;
        // A membrane crossed (no direction from the closest points): on the caller's side, as computing it would.
        if (mes && m->value <= kContactEps && side.dot(out.normal) < 0) out.normal = -out.normal;
      }
      return m->value;
    }
    if (m->value >= bound) return m->value;
  } else if (memo_used_ < static_cast<int>(memo_pool_.size())) {
    stamp = stamp_;
    index = static_cast<std::uint32_t>(memo_used_++);
    m = &memo_pool_[index];
  }
  const double d = mes ? compute_cell(x, a, b, bound, out) : compute_segments(x, a, b, bound, out);
  if (m != nullptr) {
    m->value = d;
    m->exact = d < bound;
    if (m->exact) m->pair = out;
  }
  return d;
}

double StochasticDetector::compute_cell(const Eigen::Matrix3Xd& x, int seg, int cell, double bound,
                                        ActivePair& out) noexcept {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const auto p0 = x.col(seg_node_[2 * static_cast<std::size_t>(seg)]);
  const auto p1 = x.col(seg_node_[2 * static_cast<std::size_t>(seg) + 1]);
  const auto& ss = seg_sphere_[static_cast<std::size_t>(seg)];
  if (bound < kInf) {
    // Both triangles at once: the cell's bounding sphere.
    const auto& cs = cell_sphere_[static_cast<std::size_t>(cell)];
    const double lb = (ss.head<3>() - cs.head<3>()).norm() - ss[3] - cs[3];
    if (lb >= bound) {
      ++tests_;
      return lb;
    }
  }
  double best = kInf, lower = kInf;  // exact distance of the closer triangle; lower bound over both
  for (int t = 0; t < 2; ++t) {
    ++tests_;
    const int tri = 2 * cell + t;
    const int* n = &tri_node_[3 * static_cast<std::size_t>(tri)];
    const double bt = std::min(bound, best);
    if (bt < kInf) {
      const auto& ts = tri_sphere_[static_cast<std::size_t>(tri)];
      double lb = (ss.head<3>() - ts.head<3>()).norm() - ss[3] - ts[3];
      if (lb < bt) lb = std::max(lb, plane_bound(p0, p1, x.col(n[0]), x.col(n[1]), x.col(n[2])));
      if (lb >= bt) {
        lower = std::min(lower, lb);
        continue;
      }
    }
    double s = 0;
    Eigen::Vector3d bary;
    const double d = segment_triangle_exact(p0, p1, x.col(n[0]), x.col(n[1]), x.col(n[2]), s, bary);
    lower = std::min(lower, d);
    if (d < best) {
      best = d;
      out.tri = t;
      out.s = s;
      out.wb = bary;
    }
  }
  if (!(best < bound)) return lower;  // not closer than the bound: the lower bound (>= bound), out unused
  out.a = seg;
  out.b = cell;
  out.distance = best;
  const int* n = &tri_node_[3 * static_cast<std::size_t>(2 * cell + out.tri)];
  const Eigen::Vector3d pa = p0 + out.s * (p1 - p0);
  const Eigen::Vector3d pb = out.wb[0] * x.col(n[0]) + out.wb[1] * x.col(n[1]) + out.wb[2] * x.col(n[2]);
  if (best > kContactEps) {
    out.normal = (pa - pb) / best;
  } else {
    // The segment crosses the membrane: push along the triangle's normal, on the side the pair came from.
    Eigen::Vector3d nt = (x.col(n[1]) - x.col(n[0])).cross(x.col(n[2]) - x.col(n[0]));
    nt = nt.norm() > kTiny ? Eigen::Vector3d(nt.normalized()) : orthogonal(p1 - p0);
    out.normal = nt.dot(out.normal) < 0 ? Eigen::Vector3d(-nt) : nt;
  }
  return best;
}

double StochasticDetector::converge_segments(const Eigen::Matrix3Xd& x, ActivePair& p, int moves) noexcept {
  eval_segments(x, p.a, p.b, std::numeric_limits<double>::infinity(), p);
  for (int move = 0; move < moves; ++move) {
    // The 9-neighbour update: the closest of (a + {-1,0,1}, b + {-1,0,1}).
    ActivePair best = p, cand = p;
    double nearest = std::numeric_limits<double>::infinity();
    for (int da = -1; da <= 1; ++da) {
      for (int db = -1; db <= 1; ++db) {
        if (da == 0 && db == 0) continue;
        const int a = p.a + da, b = p.b + db;
        if (!topo_.segments_tested(a, b)) continue;
        cand.normal = p.normal;
        const double d = eval_segments(x, a, b, best.distance, cand);
        if (d < best.distance) best = cand;
        nearest = std::min(nearest, d);
      }
    }
    if (best.a == p.a && best.b == p.b) return nearest - p.distance;  // a local minimum, by this margin
    p = best;
  }
  return -std::numeric_limits<double>::infinity();
}

double StochasticDetector::converge_cell(const Eigen::Matrix3Xd& x, ActivePair& p, int moves) noexcept {
  const int cw = topo_.cols - 1;
  eval_cell(x, p.a, p.b, std::numeric_limits<double>::infinity(), p);
  int done = 0;
  while (done < moves) {
    bool moved = false;
    double nearest = std::numeric_limits<double>::infinity();
    // Step 1: along the intestine, the cell fixed.
    ActivePair best = p, cand = p;
    for (int ds = -1; ds <= 1; ds += 2) {
      if (!cell_ok(p.a + ds, p.b)) continue;
      cand.normal = p.normal;
      const double d = eval_cell(x, p.a + ds, p.b, best.distance, cand);
      if (d < best.distance) best = cand;
      nearest = std::min(nearest, d);
    }
    if (best.a != p.a) {
      p = best;
      moved = true;
      ++done;
    }
    // Step 2: over the mesentery, the segment fixed.
    const int r = p.b / cw, c = p.b % cw;
    best = p;
    for (int dr = -1; dr <= 1; ++dr) {
      for (int dc = -1; dc <= 1; ++dc) {
        if (dr == 0 && dc == 0) continue;
        const int rr = r + dr, cc = c + dc;
        if (rr < 0 || cc < 0 || rr >= topo_.rows - 1 || cc >= cw) continue;
        const int cell = rr * cw + cc;
        if (!cell_ok(p.a, cell)) continue;
        cand.normal = p.normal;
        const double d = eval_cell(x, p.a, cell, best.distance, cand);
        if (d < best.distance) best = cand;
        nearest = std::min(nearest, d);
      }
    }
    if (best.b != p.b && done < moves) {
      p = best;
      moved = true;
      ++done;
    }
    if (!moved) return nearest - p.distance;  // a local minimum of both steps, by this margin
  }
  return -std::numeric_limits<double>::infinity();
}

bool StochasticDetector::beyond_reach(bool mes, int a, int b, int moves, double drop) const noexcept {
  // Each move changes the segment by at most one and the other element by at most one (segment, or cell row and
  // column), so the pairs reached lie in these index ranges; each is farther than `drop` when its bounding spheres
  // are (centres farther apart than drop + both radii; squared, stopping at the first that is not).
  const int a0 = std::max(0, a - moves), a1 = std::min(nseg_ - 1, a + moves);
  auto far = [drop](const Eigen::Vector4d& u, const Eigen::Vector4d& v) {
    const double reach = drop + u[3] + v[3];
    return (u.head<3>() - v.head<3>()).squaredNorm() > reach * reach;
  };
  if (!mes) {
    const int b0 = std::max(0, b - moves), b1 = std::min(nseg_ - 1, b + moves);
    for (int i = a0; i <= a1; ++i) {
      for (int j = b0; j <= b1; ++j) {
        if (!far(seg_sphere_[static_cast<std::size_t>(i)], seg_sphere_[static_cast<std::size_t>(j)])) return false;
      }
    }
    return true;
  }
  const int cw = topo_.cols - 1, r = b / cw, c = b % cw;
  const int r0 = std::max(0, r - moves), r1 = std::min(topo_.rows - 2, r + moves);
  const int c0 = std::max(0, c - moves), c1 = std::min(cw - 1, c + moves);
  for (int i = a0; i <= a1; ++i) {
    for (int rr = r0; rr <= r1; ++rr) {
      for (int cc = c0; cc <= c1; ++cc) {
        if (!far(seg_sphere_[static_cast<std::size_t>(i)], cell_sphere_[static_cast<std::size_t>(rr * cw + cc)])) {
          return false;
        }
      }
    }
  }
  return true;
}

bool StochasticDetector::claim(std::vector<std::uint32_t>& owner, int key) noexcept {
  auto& o = owner[static_cast<std::size_t>(key)];
  if (o == stamp_) return false;
  o = stamp_;
  return true;
}

bool StochasticDetector::add_pair(int a, int b, bool mesentery) noexcept {
  if (mesentery) {
    if (!cell_ok(a, b) || cell_count_ >= params_.capacity) return false;
    cell_margin_[static_cast<std::size_t>(cell_count_)] = -std::numeric_limits<double>::infinity();
    cell_gap_[static_cast<std::size_t>(cell_count_)] = -std::numeric_limits<double>::infinity();
    ActivePair& p = cell_pairs_[static_cast<std::size_t>(cell_count_++)];
    p = ActivePair{};
    p.a = a;
    p.b = b;
    return true;
  }
  if (a > b) std::swap(a, b);
  if (!topo_.segments_tested(a, b) || seg_count_ >= params_.capacity) return false;
  seg_margin_[static_cast<std::size_t>(seg_count_)] = -std::numeric_limits<double>::infinity();
  seg_gap_[static_cast<std::size_t>(seg_count_)] = -std::numeric_limits<double>::infinity();
  ActivePair& p = seg_pairs_[static_cast<std::size_t>(seg_count_++)];
  p = ActivePair{};
  p.a = a;
  p.b = b;
  return true;
}

bool StochasticDetector::emit(const ActivePair& p, bool mesentery, ContactList& out, DetectStats& st) noexcept {
  const double contact =
      mesentery ? topo_.intestine_radius + topo_.mesentery_half_thickness : 2 * topo_.intestine_radius;
  if (!(p.distance < contact)) return false;
  const int key = mesentery ? p.a * topo_.cells() + p.b : p.a * topo_.segments() + p.b;
  auto& reported = (mesentery ? cell_reported_ : seg_reported_)[static_cast<std::size_t>(key)];
  if (reported == stamp_) return false;  // reported already (by a neighbouring minimum)
  reported = stamp_;
  CollisionContact c;
  if (mesentery) {
    const int* n = &tri_node_[3 * static_cast<std::size_t>(2 * p.b + p.tri)];
    c.kind = ContactKind::kSegmentTriangle;
    c.count_b = 3;
    c.nodes = {topo_.node(0, p.a), topo_.node(0, p.a + 1), n[0], n[1], n[2]};
    c.weights = {1 - p.s, p.s, p.wb[0], p.wb[1], p.wb[2]};
    c.element_b = 2 * p.b + p.tri;
  } else {
    c.kind = ContactKind::kSegmentSegment;
    c.count_b = 2;
    c.nodes = {topo_.node(0, p.a), topo_.node(0, p.a + 1), topo_.node(0, p.b), topo_.node(0, p.b + 1), -1};
    c.weights = {1 - p.s, p.s, p.wb[0], p.wb[1], 0};
    c.element_b = p.b;
  }
  c.count_a = 2;
  c.normal = p.normal;
  c.radius_sum = contact;
  c.distance = p.distance;
  c.element_a = p.a;
  if (out.push(c)) {
    ++st.contacts;
  } else {
    ++st.overflow;
  }
  return true;
}

void StochasticDetector::expand(const Eigen::Matrix3Xd& x, const ActivePair& start, bool mes, ContactList& out,
                                DetectStats& st) noexcept {
  const double contact = mes ? topo_.intestine_radius + topo_.mesentery_half_thickness : 2 * topo_.intestine_radius;
  const int cw = topo_.cols - 1;
  const auto& reported = mes ? cell_reported_ : seg_reported_;
  auto& clear = mes ? cell_clear_ : seg_clear_;
  auto key_of = [&](int a, int b) {
    return static_cast<std::size_t>(mes ? a * topo_.cells() + b : a * topo_.segments() + b);
  };
  // Reported already, or evaluated by another zone's fill this step and out of contact.
  auto seen = [&](int a, int b) {
    const std::size_t key = key_of(a, b);
    return reported[key] == stamp_ || clear[key] == stamp_;
  };
  // Flood fill from the minimum over colliding neighbouring pairs.
  int head = 0, tail = 0, added = 0;
  zone_[static_cast<std::size_t>(tail++)] = start;
  while (head < tail && added < params_.zone_budget) {
    const ActivePair q = zone_[static_cast<std::size_t>(head++)];
    ActivePair cand = q;
    auto visit = [&](int a, int b) {
      if (added >= params_.zone_budget || seen(a, b)) return;
      cand.normal = q.normal;
      const double d = mes ? eval_cell(x, a, b, contact, cand) : eval_segments(x, a, b, contact, cand);
      if (!(d < contact)) {
        clear[key_of(a, b)] = stamp_;
        return;
      }
      if (!emit(cand, mes, out, st)) return;
      ++added;
      if (tail < static_cast<int>(zone_.size())) zone_[static_cast<std::size_t>(tail++)] = cand;
    };
    if (mes) {
      for (int ds = -1; ds <= 1; ds += 2) {
        if (cell_ok(q.a + ds, q.b)) visit(q.a + ds, q.b);
      }
      const int r = q.b / cw, c = q.b % cw;
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int rr = r + dr, cc = c + dc;
          if ((dr == 0 && dc == 0) || rr < 0 || cc < 0 || rr >= topo_.rows - 1 || cc >= cw) continue;
          if (cell_ok(q.a, rr * cw + cc)) visit(q.a, rr * cw + cc);
        }
      }
    } else {
      for (int da = -1; da <= 1; ++da) {
        for (int db = -1; db <= 1; ++db) {
          if ((da == 0 && db == 0) || !topo_.segments_tested(q.a + da, q.b + db)) continue;
          visit(q.a + da, q.b + db);
        }
      }
    }
  }
}

DetectStats StochasticDetector::detect(const Eigen::Matrix3Xd& x, ContactList& out) noexcept {
  DetectStats st;
  tests_ = 0;
  if (++stamp_ == 0) {  // wrapped: clear the tables so that no stale stamp matches
    clear_tables();
    stamp_ = 1;
  }
  const int nseg = topo_.segments(), ncell = topo_.cells();
  cache_step(x);
  memo_used_ = 0;
  const double drop_seg = params_.drop_factor * 2 * topo_.intestine_radius;
  const double drop_cell = params_.drop_factor * (topo_.intestine_radius + topo_.mesentery_half_thickness);

  // Each kind: update the tracked minima (merging pairs that meet and dropping far ones), then n new random pairs;
  // contacts are emitted as each surviving pair is settled, with its colliding neighbours.
  for (int kind = 0; kind < 2; ++kind) {
    const bool mes = kind == 1;
    std::vector<ActivePair>& pairs = mes ? cell_pairs_ : seg_pairs_;
    std::vector<std::uint32_t>& owner = mes ? cell_owner_ : seg_owner_;
    int& count = mes ? cell_count_ : seg_count_;
    std::vector<double>& margin = mes ? cell_margin_ : seg_margin_;
    std::vector<double>& gap = mes ? cell_gap_ : seg_gap_;
    const double contact = mes ? topo_.intestine_radius + topo_.mesentery_half_thickness : 2 * topo_.intestine_radius;
    // After a convergence that reached a minimum (margin >= 0) every neighbour is at least as far as the pair: the
    // neighbourhood is this far from contact.
    auto gap_of = [&](const ActivePair& p, double m) {
      return m >= 0 ? p.distance - contact : -std::numeric_limits<double>::infinity();
    };
    const std::vector<double>& near_b = mes ? cell_near_move_ : seg_near_move_;
    const int width = mes ? ncell : nseg;
    const double drop = mes ? drop_cell : drop_seg;
    auto settle = [&](ActivePair& p, int moves) {
      return mes ? converge_cell(x, p, moves) : converge_segments(x, p, moves);
    };
    auto report = [&](const ActivePair& p) {
      if (emit(p, mes, out, st) && params_.zone_budget > 0) expand(x, p, mes, out, st);
    };
    int keep = 0;
    for (int i = 0; i < count; ++i) {
      ActivePair p = pairs[static_cast<std::size_t>(i)];
      // What is left of the margin of its last convergence once every distance near the pair may have changed by
      // the displacement of the nodes around it (own distance up, a neighbour's down): while positive, the pair is
      // still a local minimum and converging would only evaluate its neighbours to stay put.
      const double shrink =
          2 * (seg_near_move_[static_cast<std::size_t>(p.a)] + near_b[static_cast<std::size_t>(p.b)]);
      double left = margin[static_cast<std::size_t>(i)] - shrink;
      // No distance of the neighbourhood has come closer than the displacements of its nodes: half the shrink.
      double far = gap[static_cast<std::size_t>(i)] - 0.5 * shrink;
      if (far > kMarginEps) {
        // Its whole neighbourhood is still out of contact: the pair waits where it is (not evaluated, not reported).
        ++st.settled;
      } else if (left > kMarginEps && params_.max_moves > 0) {
        if (mes) {
          eval_cell(x, p.a, p.b, std::numeric_limits<double>::infinity(), p);
        } else {
          eval_segments(x, p.a, p.b, std::numeric_limits<double>::infinity(), p);
        }
        ++st.settled;
      } else {
        left = settle(p, params_.max_moves);
        far = gap_of(p, left);
      }
      if (p.distance > drop) {
        ++st.dropped;
      } else if (!claim(owner, p.a * width + p.b)) {
        ++st.merged;
      } else {
        margin[static_cast<std::size_t>(keep)] = left;
        gap[static_cast<std::size_t>(keep)] = far;
        pairs[static_cast<std::size_t>(keep++)] = p;
        report(p);
      }
    }
    count = keep;
    const int draws = mes ? params_.random_mesentery_pairs : params_.random_pairs;
    for (int k = 0; k < draws; ++k) {
      int a = 0, b = 0;
      bool ok = false;
      for (int attempt = 0; attempt < 8 && !ok; ++attempt) {
        a = uniform(nseg);
        b = uniform(mes ? ncell : nseg);
        if (!mes && a > b) std::swap(a, b);
        ok = mes ? cell_ok(a, b) : topo_.segments_tested(a, b);
      }
      if (!ok || owner[static_cast<std::size_t>(a * width + b)] == stamp_) continue;  // tracked already
      // Every pair its convergence could reach is farther than the drop distance: it would be dropped.
      if (beyond_reach(mes, a, b, params_.new_pair_moves, drop)) continue;
      ActivePair p;
      p.a = a;
      p.b = b;
      const double left = settle(p, params_.new_pair_moves);
      if (p.distance > drop || !claim(owner, p.a * width + p.b)) continue;
      if (count >= params_.capacity) {
        ++st.overflow;
        continue;
      }
      margin[static_cast<std::size_t>(count)] = left;
      gap[static_cast<std::size_t>(count)] = gap_of(p, left);
      pairs[static_cast<std::size_t>(count++)] = p;
      ++st.new_pairs;
      report(p);
    }
  }
  st.segment_pairs = seg_count_;
  st.cell_pairs = cell_count_;
  st.distance_tests = tests_;
  return st;
}

bool segment_contact(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, int a, int b, double margin,
                     CollisionContact& c) noexcept {
  const Eigen::Vector3d p0 = x.col(topo.node(0, a)), p1 = x.col(topo.node(0, a + 1));
  const Eigen::Vector3d q0 = x.col(topo.node(0, b)), q1 = x.col(topo.node(0, b + 1));
  double s = 0, t = 0;
  const double d = segment_segment(p0, p1, q0, q1, s, t);
  if (d >= 2 * topo.intestine_radius + margin) return false;
  segment_contact_at(topo, x, a, b, d, s, t, c);
  return true;
}

void segment_contact_at(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, int a, int b, double d, double s,
                        double t, CollisionContact& c) noexcept {
  const double rr = 2 * topo.intestine_radius;
  const Eigen::Vector3d p0 = x.col(topo.node(0, a)), p1 = x.col(topo.node(0, a + 1));
  const Eigen::Vector3d q0 = x.col(topo.node(0, b)), q1 = x.col(topo.node(0, b + 1));
  c = CollisionContact{};
  c.kind = ContactKind::kSegmentSegment;
  c.nodes = {topo.node(0, a), topo.node(0, a + 1), topo.node(0, b), topo.node(0, b + 1), -1};
  c.weights = {1 - s, s, 1 - t, t, 0};
  const Eigen::Vector3d diff = (p0 + s * (p1 - p0)) - (q0 + t * (q1 - q0));
  c.normal = d > kContactEps ? Eigen::Vector3d(diff / d) : orthogonal(p1 - p0);
  c.radius_sum = rr;
  c.distance = d;
  c.element_a = a;
  c.element_b = b;
}

bool triangle_contact(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, int a, int tri, double margin,
                      CollisionContact& c, bool cull) noexcept {
  const double rm = topo.intestine_radius + topo.mesentery_half_thickness;
  const Eigen::Vector3d p0 = x.col(topo.node(0, a)), p1 = x.col(topo.node(0, a + 1));
  int n[3];
  topo.triangle(tri, n);
  const Eigen::Vector3d A = x.col(n[0]), B = x.col(n[1]), C = x.col(n[2]);
  double s = 0;
  Eigen::Vector3d bary;
  // The bounded test: bounding spheres and the triangle's plane reject most pairs before the exact distance.
  const double d = segment_triangle(p0, p1, A, B, C, s, bary,
                                   cull ? rm + margin : std::numeric_limits<double>::infinity());
  if (!(d < rm + margin)) return false;
  triangle_contact_at(topo, x, a, tri, d, s, bary, c);
  return true;
}

void triangle_contact_at(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, int a, int tri, double d, double s,
                         const Eigen::Vector3d& bary, CollisionContact& c) noexcept {
  const double rm = topo.intestine_radius + topo.mesentery_half_thickness;
  const Eigen::Vector3d p0 = x.col(topo.node(0, a)), p1 = x.col(topo.node(0, a + 1));
  int n[3];
  topo.triangle(tri, n);
  const Eigen::Vector3d A = x.col(n[0]), B = x.col(n[1]), C = x.col(n[2]);
  c = CollisionContact{};
  c.kind = ContactKind::kSegmentTriangle;
  c.count_b = 3;
  c.nodes = {topo.node(0, a), topo.node(0, a + 1), n[0], n[1], n[2]};
  c.weights = {1 - s, s, bary[0], bary[1], bary[2]};
  const Eigen::Vector3d diff = (p0 + s * (p1 - p0)) - (bary[0] * A + bary[1] * B + bary[2] * C);
  if (d > kContactEps) {
    c.normal = diff / d;
  } else {
    const Eigen::Vector3d nt = (B - A).cross(C - A);
    c.normal = nt.norm() > kTiny ? Eigen::Vector3d(nt.normalized()) : orthogonal(p1 - p0);
  }
  c.radius_sum = rm;
  c.distance = d;
  c.element_a = a;
  c.element_b = tri;
}

void detect_brute_force(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, ContactList& out,
                        double margin) noexcept {
  const int nseg = topo.segments();
  const double rr = 2 * topo.intestine_radius, rm = topo.intestine_radius + topo.mesentery_half_thickness;
  auto box_gap = [](const Eigen::Vector3d& lo1, const Eigen::Vector3d& hi1, const Eigen::Vector3d& lo2,
                    const Eigen::Vector3d& hi2, double r) {
    return (lo1.array() > hi2.array() + r).any() || (lo2.array() > hi1.array() + r).any();
  };
  CollisionContact c;
  for (int a = 0; a < nseg; ++a) {
    const Eigen::Vector3d p0 = x.col(topo.node(0, a)), p1 = x.col(topo.node(0, a + 1));
    const Eigen::Vector3d plo = p0.cwiseMin(p1), phi = p0.cwiseMax(p1);
    // Intestine-intestine.
    for (int b = a + 1; b < nseg; ++b) {
      if (!topo.segments_tested(a, b)) continue;
      const Eigen::Vector3d q0 = x.col(topo.node(0, b)), q1 = x.col(topo.node(0, b + 1));
      if (box_gap(plo, phi, q0.cwiseMin(q1), q0.cwiseMax(q1), rr + margin)) continue;
      if (segment_contact(topo, x, a, b, margin, c)) out.push(c);
    }
    // Intestine-mesentery: the segment's ends against the triangle (point-triangle), the segment against its edges
    // (edge-triangle) and the segment crossing it.
    for (int tri = 0; tri < 2 * topo.cells(); ++tri) {
      if (!topo.cell_tested(a, tri / 2)) continue;
      int n[3];
      topo.triangle(tri, n);
      const Eigen::Vector3d A = x.col(n[0]), B = x.col(n[1]), C = x.col(n[2]);
      if (box_gap(plo, phi, A.cwiseMin(B).cwiseMin(C), A.cwiseMax(B).cwiseMax(C), rm + margin)) continue;
      if (triangle_contact(topo, x, a, tri, margin, c)) out.push(c);
    }
  }
}

RecallStats& RecallStats::operator+=(const RecallStats& o) {
  truth += o.truth;
  found += o.found;
  depth_truth += o.depth_truth;
  depth_found += o.depth_found;
  max_missed = std::max(max_missed, o.max_missed);
  regions += o.regions;
  regions_found += o.regions_found;
  return *this;
}

RecallStats compare_with_reference(const CollisionTopology& topo, const ContactList& found,
                                   const ContactList& truth) {
  // Identity of a contact: (kind, segment, segment or cell).
  auto key = [](const CollisionContact& c) {
    const int b = c.kind == ContactKind::kSegmentSegment ? c.element_b : c.element_b / 2;
    return std::tuple<int, int, int>(static_cast<int>(c.kind), c.element_a, b);
  };
  std::set<std::tuple<int, int, int>> reported;
  for (const auto& c : found) reported.insert(key(c));
  RecallStats st;
  const int n = truth.size();
  std::vector<char> hit(static_cast<std::size_t>(n), 0);
  for (int i = 0; i < n; ++i) {
    const bool h = reported.count(key(truth[i])) > 0;
    const double depth = truth[i].radius_sum - truth[i].distance;
    hit[static_cast<std::size_t>(i)] = h;
    ++st.truth;
    st.found += h;
    st.depth_truth += depth;
    if (h) {
      st.depth_found += depth;
    } else {
      st.max_missed = std::max(st.max_missed, depth);
    }
  }
  // Contact zones: union-find over neighbouring reference contacts of the same kind.
  std::vector<int> parent(static_cast<std::size_t>(n));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[static_cast<std::size_t>(i)] != i) {
      parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
      i = parent[static_cast<std::size_t>(i)];
    }
    return i;
  };
  const int cw = topo.cols - 1;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const auto& a = truth[i];
      const auto& b = truth[j];
      if (a.kind != b.kind || std::abs(a.element_a - b.element_a) > 1) continue;
      bool near = false;
      if (a.kind == ContactKind::kSegmentSegment) {
        near = std::abs(a.element_b - b.element_b) <= 1;
      } else {
        const int ca = a.element_b / 2, cb = b.element_b / 2;
        near = std::abs(ca / cw - cb / cw) <= 1 && std::abs(ca % cw - cb % cw) <= 1;
      }
      if (near) parent[static_cast<std::size_t>(find(i))] = find(j);
    }
  }
  std::vector<char> root_hit(static_cast<std::size_t>(n), 0), is_root(static_cast<std::size_t>(n), 0);
  for (int i = 0; i < n; ++i) {
    const int r = find(i);
    is_root[static_cast<std::size_t>(r)] = 1;
    if (hit[static_cast<std::size_t>(i)]) root_hit[static_cast<std::size_t>(r)] = 1;
  }
  for (int i = 0; i < n; ++i) {
    st.regions += is_root[static_cast<std::size_t>(i)];
    st.regions_found += is_root[static_cast<std::size_t>(i)] && root_hit[static_cast<std::size_t>(i)];
  }
  return st;
}

}  // namespace surgsim::intestine
