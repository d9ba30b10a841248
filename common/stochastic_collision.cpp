#include "stochastic_collision.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <utility>

#include "collision.h"
#include "error.h"

namespace surgsim::intestine {

namespace {

constexpr double kTiny = 1e-12;
constexpr double kContactEps = 1e-9;  // m: below this the closest points give no direction

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

double segment_triangle(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& a,
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
  Eigen::Vector3d bb;
  double best = (closest_point_triangle(p0, a, b, c, bb) - p0).norm();
  s = 0;
  bary = bb;
  double dd = (closest_point_triangle(p1, a, b, c, bb) - p1).norm();
  if (dd < best) {
    best = dd;
    s = 1;
    bary = bb;
  }
  // Edge-triangle: the segment against each edge.
  const Eigen::Vector3d* v[3] = {&a, &b, &c};
  for (int k = 0; k < 3; ++k) {
    double ss = 0, tt = 0;
    dd = segment_segment(p0, p1, *v[k], *v[(k + 1) % 3], ss, tt);
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

bool CollisionTopology::cell_tested(int segment, int cell) const {
  if (segment < 0 || segment >= segments() || cell < 0 || cell >= cells()) return false;
  const int r = cell / (cols - 1), c = cell % (cols - 1);
  if (r == 0 && std::abs(c - segment) <= cell_exclusion) return false;
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
      params_.max_moves < 0 || !(params_.drop_distance > 0)) {
    throw_error("stochastic collision: capacity >= 1, random pairs >= 0, max_moves >= 0, drop_distance > 0");
  }
  seg_pairs_.resize(static_cast<std::size_t>(params_.capacity));
  cell_pairs_.resize(static_cast<std::size_t>(params_.capacity));
  seg_owner_.assign(static_cast<std::size_t>(topo_.segments()) * static_cast<std::size_t>(topo_.segments()), 0);
  cell_owner_.assign(static_cast<std::size_t>(topo_.segments()) * static_cast<std::size_t>(topo_.cells()), 0);
  reset(params_.seed);
}

void StochasticDetector::set_random_pairs(int segment_pairs, int mesentery_pairs) noexcept {
  params_.random_pairs = std::max(0, segment_pairs);
  params_.random_mesentery_pairs = std::max(0, mesentery_pairs);
}

void StochasticDetector::reset(std::uint64_t seed) noexcept {
  rng_ = seed;
  seg_count_ = cell_count_ = 0;
  std::fill(seg_owner_.begin(), seg_owner_.end(), 0u);
  std::fill(cell_owner_.begin(), cell_owner_.end(), 0u);
  stamp_ = 0;
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

double StochasticDetector::eval_segments(const Eigen::Matrix3Xd& x, int a, int b, ActivePair& out) noexcept {
  ++tests_;
  const auto p0 = x.col(topo_.node(0, a)), p1 = x.col(topo_.node(0, a + 1));
  const auto q0 = x.col(topo_.node(0, b)), q1 = x.col(topo_.node(0, b + 1));
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

double StochasticDetector::eval_cell(const Eigen::Matrix3Xd& x, int seg, int cell, ActivePair& out) noexcept {
  const auto p0 = x.col(topo_.node(0, seg)), p1 = x.col(topo_.node(0, seg + 1));
  double best = 1e300;
  for (int t = 0; t < 2; ++t) {
    ++tests_;
    int n[3];
    topo_.triangle(2 * cell + t, n);
    double s = 0;
    Eigen::Vector3d bary;
    const double d = segment_triangle(p0, p1, x.col(n[0]), x.col(n[1]), x.col(n[2]), s, bary);
    if (d < best) {
      best = d;
      out.tri = t;
      out.s = s;
      out.wb = bary;
    }
  }
  out.a = seg;
  out.b = cell;
  out.distance = best;
  int n[3];
  topo_.triangle(2 * cell + out.tri, n);
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

void StochasticDetector::converge_segments(const Eigen::Matrix3Xd& x, ActivePair& p) noexcept {
  eval_segments(x, p.a, p.b, p);
  for (int move = 0; move < params_.max_moves; ++move) {
    ActivePair best = p, cand = p;
    for (int da = -1; da <= 1; ++da) {
      for (int db = -1; db <= 1; ++db) {
        if (da == 0 && db == 0) continue;
        const int a = p.a + da, b = p.b + db;
        if (!topo_.segments_tested(a, b)) continue;
        cand.normal = p.normal;
        if (eval_segments(x, a, b, cand) < best.distance) best = cand;
      }
    }
    if (best.a == p.a && best.b == p.b) break;
    p = best;
  }
}

void StochasticDetector::converge_cell(const Eigen::Matrix3Xd& x, ActivePair& p) noexcept {
  const int cw = topo_.cols - 1;
  eval_cell(x, p.a, p.b, p);
  int moves = 0;
  while (moves < params_.max_moves) {
    bool moved = false;
    // Step 1: along the intestine, the cell fixed.
    ActivePair best = p, cand = p;
    for (int ds = -1; ds <= 1; ds += 2) {
      if (!topo_.cell_tested(p.a + ds, p.b)) continue;
      cand.normal = p.normal;
      if (eval_cell(x, p.a + ds, p.b, cand) < best.distance) best = cand;
    }
    if (best.a != p.a) {
      p = best;
      moved = true;
      ++moves;
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
        if (!topo_.cell_tested(p.a, cell)) continue;
        cand.normal = p.normal;
        if (eval_cell(x, p.a, cell, cand) < best.distance) best = cand;
      }
    }
    if (best.b != p.b) {
      p = best;
      moved = true;
      ++moves;
    }
    if (!moved) break;
  }
}

bool StochasticDetector::claim(std::vector<std::uint32_t>& owner, int key) noexcept {
  auto& o = owner[static_cast<std::size_t>(key)];
  if (o == stamp_) return false;
  o = stamp_;
  return true;
}

bool StochasticDetector::add_pair(int a, int b, bool mesentery) noexcept {
  if (mesentery) {
    if (!topo_.cell_tested(a, b) || cell_count_ >= params_.capacity) return false;
    ActivePair& p = cell_pairs_[static_cast<std::size_t>(cell_count_++)];
    p = ActivePair{};
    p.a = a;
    p.b = b;
    return true;
  }
  if (a > b) std::swap(a, b);
  if (!topo_.segments_tested(a, b) || seg_count_ >= params_.capacity) return false;
  ActivePair& p = seg_pairs_[static_cast<std::size_t>(seg_count_++)];
  p = ActivePair{};
  p.a = a;
  p.b = b;
  return true;
}

DetectStats StochasticDetector::detect(const Eigen::Matrix3Xd& x, ContactList& out) noexcept {
  DetectStats st;
  tests_ = 0;
  if (++stamp_ == 0) {  // wrapped: clear the tables so that no stale stamp matches
    std::fill(seg_owner_.begin(), seg_owner_.end(), 0u);
    std::fill(cell_owner_.begin(), cell_owner_.end(), 0u);
    stamp_ = 1;
  }
  const int nseg = topo_.segments(), ncell = topo_.cells();
  const double drop = params_.drop_distance;

  // Intestine-intestine: update the tracked minima, then merge and drop.
  int keep = 0;
  for (int i = 0; i < seg_count_; ++i) {
    ActivePair p = seg_pairs_[static_cast<std::size_t>(i)];
    converge_segments(x, p);
    if (p.distance > drop) {
      ++st.dropped;
    } else if (!claim(seg_owner_, p.a * nseg + p.b)) {
      ++st.merged;
    } else {
      seg_pairs_[static_cast<std::size_t>(keep++)] = p;
    }
  }
  seg_count_ = keep;
  // n new random pairs, converged at once; kept if they found a minimum nobody tracks.
  for (int k = 0; k < params_.random_pairs; ++k) {
    int a = 0, b = 0;
    bool ok = false;
    for (int attempt = 0; attempt < 8 && !ok; ++attempt) {
      a = uniform(nseg);
      b = uniform(nseg);
      if (a > b) std::swap(a, b);
      ok = topo_.segments_tested(a, b);
    }
    if (!ok || seg_owner_[static_cast<std::size_t>(a * nseg + b)] == stamp_) continue;
    ActivePair p;
    p.a = a;
    p.b = b;
    converge_segments(x, p);
    if (p.distance > drop || !claim(seg_owner_, p.a * nseg + p.b)) continue;
    if (seg_count_ >= params_.capacity) {
      ++st.overflow;
      continue;
    }
    seg_pairs_[static_cast<std::size_t>(seg_count_++)] = p;
    ++st.new_pairs;
  }

  // Intestine-mesentery, the same with the two-step convergence.
  keep = 0;
  for (int i = 0; i < cell_count_; ++i) {
    ActivePair p = cell_pairs_[static_cast<std::size_t>(i)];
    converge_cell(x, p);
    if (p.distance > drop) {
      ++st.dropped;
    } else if (!claim(cell_owner_, p.a * ncell + p.b)) {
      ++st.merged;
    } else {
      cell_pairs_[static_cast<std::size_t>(keep++)] = p;
    }
  }
  cell_count_ = keep;
  for (int k = 0; k < params_.random_mesentery_pairs; ++k) {
    int s = 0, cell = 0;
    bool ok = false;
    for (int attempt = 0; attempt < 8 && !ok; ++attempt) {
      s = uniform(nseg);
      cell = uniform(ncell);
      ok = topo_.cell_tested(s, cell);
    }
    if (!ok || cell_owner_[static_cast<std::size_t>(s * ncell + cell)] == stamp_) continue;
    ActivePair p;
    p.a = s;
    p.b = cell;
    converge_cell(x, p);
    if (p.distance > drop || !claim(cell_owner_, p.a * ncell + p.b)) continue;
    if (cell_count_ >= params_.capacity) {
      ++st.overflow;
      continue;
    }
    cell_pairs_[static_cast<std::size_t>(cell_count_++)] = p;
    ++st.new_pairs;
  }

  // Contacts: the pairs closer than the sum of the radii.
  const double rr = 2 * topo_.intestine_radius, rm = topo_.intestine_radius + topo_.mesentery_half_thickness;
  for (int i = 0; i < seg_count_; ++i) {
    const ActivePair& p = seg_pairs_[static_cast<std::size_t>(i)];
    if (p.distance >= rr) continue;
    CollisionContact c;
    c.kind = ContactKind::kSegmentSegment;
    c.count_a = 2;
    c.count_b = 2;
    c.nodes = {topo_.node(0, p.a), topo_.node(0, p.a + 1), topo_.node(0, p.b), topo_.node(0, p.b + 1), -1};
    c.weights = {1 - p.s, p.s, p.wb[0], p.wb[1], 0};
    c.normal = p.normal;
    c.radius_sum = rr;
    c.distance = p.distance;
    c.element_a = p.a;
    c.element_b = p.b;
    if (out.push(c)) {
      ++st.contacts;
    } else {
      ++st.overflow;
    }
  }
  for (int i = 0; i < cell_count_; ++i) {
    const ActivePair& p = cell_pairs_[static_cast<std::size_t>(i)];
    if (p.distance >= rm) continue;
    int n[3];
    topo_.triangle(2 * p.b + p.tri, n);
    CollisionContact c;
    c.kind = ContactKind::kSegmentTriangle;
    c.count_a = 2;
    c.count_b = 3;
    c.nodes = {topo_.node(0, p.a), topo_.node(0, p.a + 1), n[0], n[1], n[2]};
    c.weights = {1 - p.s, p.s, p.wb[0], p.wb[1], p.wb[2]};
    c.normal = p.normal;
    c.radius_sum = rm;
    c.distance = p.distance;
    c.element_a = p.a;
    c.element_b = 2 * p.b + p.tri;
    if (out.push(c)) {
      ++st.contacts;
    } else {
      ++st.overflow;
    }
  }
  st.segment_pairs = seg_count_;
  st.cell_pairs = cell_count_;
  st.distance_tests = tests_;
  return st;
}

void detect_brute_force(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, ContactList& out,
                        double margin) noexcept {
  const int nseg = topo.segments();
  const double rr = 2 * topo.intestine_radius, rm = topo.intestine_radius + topo.mesentery_half_thickness;
  auto box_gap = [](const Eigen::Vector3d& lo1, const Eigen::Vector3d& hi1, const Eigen::Vector3d& lo2,
                    const Eigen::Vector3d& hi2, double r) {
    return (lo1.array() > hi2.array() + r).any() || (lo2.array() > hi1.array() + r).any();
  };
  for (int a = 0; a < nseg; ++a) {
    const Eigen::Vector3d p0 = x.col(topo.node(0, a)), p1 = x.col(topo.node(0, a + 1));
    const Eigen::Vector3d plo = p0.cwiseMin(p1), phi = p0.cwiseMax(p1);
    // Intestine-intestine.
    for (int b = a + 1; b < nseg; ++b) {
      if (!topo.segments_tested(a, b)) continue;
      const Eigen::Vector3d q0 = x.col(topo.node(0, b)), q1 = x.col(topo.node(0, b + 1));
      if (box_gap(plo, phi, q0.cwiseMin(q1), q0.cwiseMax(q1), rr + margin)) continue;
      double s = 0, t = 0;
      const double d = segment_segment(p0, p1, q0, q1, s, t);
      if (d >= rr + margin) continue;
      CollisionContact c;
      c.kind = ContactKind::kSegmentSegment;
      c.nodes = {topo.node(0, a), topo.node(0, a + 1), topo.node(0, b), topo.node(0, b + 1), -1};
      c.weights = {1 - s, s, 1 - t, t, 0};
      const Eigen::Vector3d diff = (p0 + s * (p1 - p0)) - (q0 + t * (q1 - q0));
      c.normal = d > kContactEps ? Eigen::Vector3d(diff / d) : orthogonal(p1 - p0);
      c.radius_sum = rr;
      c.distance = d;
      c.element_a = a;
      c.element_b = b;
      out.push(c);
    }
    // Intestine-mesentery.
    for (int tri = 0; tri < 2 * topo.cells(); ++tri) {
      if (!topo.cell_tested(a, tri / 2)) continue;
      int n[3];
      topo.triangle(tri, n);
      const Eigen::Vector3d A = x.col(n[0]), B = x.col(n[1]), C = x.col(n[2]);
      if (box_gap(plo, phi, A.cwiseMin(B).cwiseMin(C), A.cwiseMax(B).cwiseMax(C), rm + margin)) continue;
      double s = 0;
      Eigen::Vector3d bary;
      const double d = segment_triangle(p0, p1, A, B, C, s, bary);
      if (d >= rm + margin) continue;
      CollisionContact c;
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
      out.push(c);
    }
  }
}

}  // namespace surgsim::intestine
