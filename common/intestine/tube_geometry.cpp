#include "intestine/tube_geometry.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim::intestine {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTiny = 1e-12;

// Angle between two vectors (0 if either vanishes), robust near 0 and pi.
double angle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

Eigen::Vector3d orthogonal(const Eigen::Vector3d& d) {
  const Eigen::Vector3d helper = std::abs(d.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d o = helper.cross(d);
  const double n = o.norm();
  return n > kTiny ? Eigen::Vector3d(o / n) : Eigen::Vector3d::UnitY();
}

// The unit vector at angle `a` from unit u towards unit v (a plane rotation; v may not be orthogonal to u).
Eigen::Vector3d rotate_towards(const Eigen::Vector3d& u, const Eigen::Vector3d& v, double a) {
  Eigen::Vector3d w = v - v.dot(u) * u;
  const double n = w.norm();
  w = n > kTiny ? Eigen::Vector3d(w / n) : orthogonal(u);
  return std::cos(a) * u + std::sin(a) * w;
}

void put(std::vector<float>& v, int i, const Eigen::Vector3d& p) {
  const auto k = static_cast<std::size_t>(3 * i);
  v[k] = static_cast<float>(p.x());
  v[k + 1] = static_cast<float>(p.y());
  v[k + 2] = static_cast<float>(p.z());
}

// The triangles of an end cap into `out` (no allocation): the cap's ring is `sides` vertices from `ring`, its own
// vertices follow from `interior` ((cap_rings - 1) rings, then the pole). Counter-clockwise seen from outside: the
// last ring's cap (`end`) bulges along the tube's direction like the tube's own quads run, the first ring's against
// it, so its triangles are flipped. Returns the number of indices written.
int write_cap_indices(std::uint32_t* out, std::uint32_t ring, std::uint32_t interior, int sides, int cap_rings,
                      bool end) noexcept {
  int n = 0;
  auto tri = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    out[n++] = a;
    out[n++] = end ? b : c;
    out[n++] = end ? c : b;
  };
  const auto s = static_cast<std::uint32_t>(sides);
  auto ring_start = [&](int i) { return i == 0 ? ring : interior + static_cast<std::uint32_t>(i - 1) * s; };
  for (int i = 0; i + 1 < cap_rings; ++i) {
    const std::uint32_t r0 = ring_start(i), r1 = ring_start(i + 1);
    for (std::uint32_t k = 0; k < s; ++k) {
      const std::uint32_t a = r0 + k, b = r0 + (k + 1) % s, c = r1 + k, d = r1 + (k + 1) % s;
      tri(a, b, c);
      tri(b, d, c);
    }
  }
  const std::uint32_t last = ring_start(cap_rings - 1), pole = ring_start(cap_rings);
  for (std::uint32_t k = 0; k < s; ++k) tri(last + k, last + (k + 1) % s, pole);
  return n;
}

}  // namespace

TubeLod tube_lod(int lod) {
  // The coarsest level is still round (16 sides, 2 rings an interval; see the header).
  static constexpr int kSides[kTubeMaxLod + 1] = {16, 24, 24, 32, 32, 40, 48};
  static constexpr int kRings[kTubeMaxLod + 1] = {2, 2, 4, 4, 8, 8, 8};
  lod = std::clamp(lod, 0, kTubeMaxLod);
  const int sides = kSides[lod];
  return TubeLod{sides, kRings[lod], std::max(1, sides / 4)};
}

int tube_cap_vertices(const TubeLod& lod) { return (lod.cap_rings - 1) * lod.sides + 1; }
int tube_cap_triangles(const TubeLod& lod) { return lod.sides * (2 * lod.cap_rings - 1); }

double skin_weight(double t) { return t * t * (3.0 - 2.0 * t); }

void cardinal_tangents(const Eigen::Vector3d* p, int n, double tension, Eigen::Vector3d* m) {
  const double k = 1.0 - tension;
  for (int i = 0; i < n; ++i) {
    if (i == 0) {
      m[i] = k * (p[1] - p[0]);
    } else if (i == n - 1) {
      m[i] = k * (p[n - 1] - p[n - 2]);
    } else {
      m[i] = 0.5 * k * (p[i + 1] - p[i - 1]);
    }
  }
}

Eigen::Vector3d hermite(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& m0,
                        const Eigen::Vector3d& m1, double t) {
  const double t2 = t * t, t3 = t2 * t;
  return (2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * m0 + (-2 * t3 + 3 * t2) * p1 + (t3 - t2) * m1;
}

Eigen::Vector3d hermite_d1(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& m0,
                           const Eigen::Vector3d& m1, double t) {
  const double t2 = t * t;
  return (6 * t2 - 6 * t) * p0 + (3 * t2 - 4 * t + 1) * m0 + (-6 * t2 + 6 * t) * p1 + (3 * t2 - 2 * t) * m1;
}

Eigen::Vector3d hermite_d2(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& m0,
                           const Eigen::Vector3d& m1, double t) {
  return (12 * t - 6) * p0 + (6 * t - 4) * m0 + (-12 * t + 6) * p1 + (6 * t - 2) * m1;
}

namespace {

// One double-reflection step: the normal at (x1, t1) transported from (x0, t0, r0). Reflection in the bisecting
// plane of x0, x1, then in the plane that maps the reflected tangent onto t1: the composition rotates the frame with
// (to fourth order) no twist about the tangent.
Eigen::Vector3d rmf_step(const Eigen::Vector3d& x0, const Eigen::Vector3d& t0, const Eigen::Vector3d& r0,
                         const Eigen::Vector3d& x1, const Eigen::Vector3d& t1) {
  const Eigen::Vector3d v1 = x1 - x0;
  const double c1 = v1.squaredNorm();
  Eigen::Vector3d rl = r0, tl = t0;
  if (c1 > kTiny * kTiny) {
    rl = r0 - (2.0 / c1) * v1.dot(r0) * v1;
    tl = t0 - (2.0 / c1) * v1.dot(t0) * v1;
  }
  const Eigen::Vector3d v2 = t1 - tl;
  const double c2 = v2.squaredNorm();
  Eigen::Vector3d rn = c2 > kTiny * kTiny ? Eigen::Vector3d(rl - (2.0 / c2) * v2.dot(rl) * v2) : rl;
  // Re-orthonormalize against round-off (and tangents the guard turned).
  rn -= rn.dot(t1) * t1;
  const double len = rn.norm();
  return len > kTiny ? Eigen::Vector3d(rn / len) : orthogonal(t1);
}

}  // namespace

void rotation_minimizing_frames(const Eigen::Vector3d* x, const Eigen::Vector3d* t, int n, const Eigen::Vector3d& r0,
                                Eigen::Vector3d* r, Eigen::Vector3d* s) {
  if (n <= 0) return;
  r[0] = r0;
  s[0] = t[0].cross(r[0]);
  for (int i = 0; i + 1 < n; ++i) {
    r[i + 1] = rmf_step(x[i], t[i], r[i], x[i + 1], t[i + 1]);
    s[i + 1] = t[i + 1].cross(r[i + 1]);
  }
}

TubeBuilder::TubeBuilder(const TubeParams& params, int max_points) : params_(params), max_points_(max_points) {
  if (max_points < 2) throw_error("tube: max_points must be >= 2 (got ", max_points, ")");
  if (!(params.radius > 0) || !(params.tension >= 0 && params.tension < 1) || !(params.flag_turn > 0) ||
      params.max_extra_samples < 0 || params.max_extra_samples > 8 || !(params.ring_clearance >= 0) ||
      !(params.min_radius_fraction > 0 && params.min_radius_fraction <= 1)) {
    throw_error("tube: radius > 0, tension in [0, 1), flag_turn > 0, max_extra_samples in 0..8, ring_clearance >= 0, "
                "min_radius_fraction in (0, 1]");
  }
  const auto np = static_cast<std::size_t>(max_points);
  points_.resize(np);
  tangents_.resize(np);
  curvature_.assign(np, 0.0);
  const auto ns = static_cast<std::size_t>(max_intervals() + 1);
  samples_.resize(ns);
  // Primitives: one interval, (rings + 1) x sides vertices (cos a, sin a, t, 0), then the two caps' own vertices
  // (cos(phi) cos a, cos(phi) sin a, 0 or 1, -+sin(phi)) over the interval's first and last rings.
  for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
    TubePrimitive prim;
    prim.lod = tube_lod(lod);
    const int s = prim.lod.sides, q = prim.lod.rings, m = prim.lod.cap_rings;
    auto vertex = [&](double x, double y, double t, double z) {
      prim.vertices.insert(prim.vertices.end(), {static_cast<float>(x), static_cast<float>(y), static_cast<float>(t),
                                                 static_cast<float>(z)});
    };
    for (int j = 0; j <= q; ++j) {
      for (int k = 0; k < s; ++k) vertex(std::cos(2 * kPi * k / s), std::sin(2 * kPi * k / s), double(j) / q, 0);
    }
    for (int j = 0; j < q; ++j) {
      for (int k = 0; k < s; ++k) {
        const auto a = static_cast<std::uint32_t>(j * s + k), b = static_cast<std::uint32_t>(j * s + (k + 1) % s);
        const auto c = a + static_cast<std::uint32_t>(s), d = b + static_cast<std::uint32_t>(s);
        prim.indices.insert(prim.indices.end(), {a, b, c, b, d, c});
      }
    }
    prim.body_vertex_count = (q + 1) * s;
    prim.body_index_count = static_cast<int>(prim.indices.size());
    prim.cap_vertex_count = tube_cap_vertices(prim.lod);
    prim.cap_index_count = 3 * tube_cap_triangles(prim.lod);
    for (const bool end : {false, true}) {
      const double t = end ? 1.0 : 0.0, sign = end ? 1.0 : -1.0;
      for (int i = 1; i < m; ++i) {
        const double phi = 0.5 * kPi * i / m;
        for (int k = 0; k < s; ++k) {
          const double a = 2 * kPi * k / s;
          vertex(std::cos(phi) * std::cos(a), std::cos(phi) * std::sin(a), t, sign * std::sin(phi));
        }
      }
      vertex(0, 0, t, sign);  // the pole
      const auto ring = static_cast<std::uint32_t>(end ? q * s : 0);
      const auto interior = static_cast<std::uint32_t>(prim.body_vertex_count + (end ? prim.cap_vertex_count : 0));
      const std::size_t at = prim.indices.size();
      prim.indices.resize(at + static_cast<std::size_t>(prim.cap_index_count));
      write_cap_indices(prim.indices.data() + at, ring, interior, s, m, end);
    }
    primitives_.push_back(std::move(prim));
  }
}

TubeMesh TubeBuilder::make_mesh(int lod) const {
  lod = std::clamp(lod, 0, kTubeMaxLod);
  const TubeLod l = tube_lod(lod);
  const auto rings = static_cast<std::size_t>(max_intervals()) * static_cast<std::size_t>(l.rings) + 1;
  const auto verts = rings * static_cast<std::size_t>(l.sides) + 2 * static_cast<std::size_t>(tube_cap_vertices(l));
  TubeMesh m;
  m.lod = lod;
  m.positions.assign(3 * verts, 0.0f);
  m.normals.assign(3 * verts, 0.0f);
  m.indices.assign((rings - 1) * static_cast<std::size_t>(l.sides) * 6 +
                       6 * static_cast<std::size_t>(tube_cap_triangles(l)), 0u);
  m.skin.assign(static_cast<std::size_t>(max_intervals()) * 24, 0.0f);
  return m;
}

const TubePrimitive& TubeBuilder::primitive(int lod) const {
  return primitives_[static_cast<std::size_t>(std::clamp(lod, 0, kTubeMaxLod))];
}

bool TubeBuilder::sample_spline(int count) noexcept {
  cardinal_tangents(points_.data(), count, params_.tension, tangents_.data());
  int k = 0;
  stats_ = TubeStats{};
  auto push = [&](int seg, double t, bool extra) {
    const Eigen::Vector3d &p0 = points_[static_cast<std::size_t>(seg)], &p1 = points_[static_cast<std::size_t>(seg + 1)];
    const Eigen::Vector3d &m0 = tangents_[static_cast<std::size_t>(seg)], &m1 = tangents_[static_cast<std::size_t>(seg + 1)];
    TubeSample& s = samples_[static_cast<std::size_t>(k)];
    s.center = hermite(p0, p1, m0, m1, t);
    Eigen::Vector3d d = hermite_d1(p0, p1, m0, m1, t);
    if (d.norm() < kTiny) d = p1 - p0;
    if (d.norm() < kTiny && k > 0) d = samples_[static_cast<std::size_t>(k - 1)].tangent;
    if (d.norm() < kTiny) d = Eigen::Vector3d::UnitX();
    s.tangent = s.spline_tangent = d.normalized();
    s.segment = seg;
    s.t = t;
    s.extra = extra;
    s.tilt = 0;
    s.radius = params_.radius;
    ++k;
  };
  constexpr int kProbe = 16;
  for (int i = 0; i + 1 < count; ++i) {
    const Eigen::Vector3d &p0 = points_[static_cast<std::size_t>(i)], &p1 = points_[static_cast<std::size_t>(i + 1)];
    const Eigen::Vector3d &m0 = tangents_[static_cast<std::size_t>(i)], &m1 = tangents_[static_cast<std::size_t>(i + 1)];
    // Curvature indicator: turning of the tangent over the segment, through its middle.
    const Eigen::Vector3d d0 = hermite_d1(p0, p1, m0, m1, 0), dh = hermite_d1(p0, p1, m0, m1, 0.5),
                          d1 = hermite_d1(p0, p1, m0, m1, 1);
    const double ci = angle(d0, dh) + angle(dh, d1);
    curvature_[static_cast<std::size_t>(i)] = ci;
    push(i, 0.0, false);
    if (!(ci > params_.flag_turn) || params_.max_extra_samples == 0) continue;
    ++stats_.flagged_segments;
    // Parameter of maximal curvature on 16 samples, refined by a parabola through the best and its neighbours.
    double kap[kProbe];
    int best = 0;
    for (int j = 0; j < kProbe; ++j) {
      const double t = (j + 0.5) / kProbe;
      const Eigen::Vector3d a = hermite_d1(p0, p1, m0, m1, t), b = hermite_d2(p0, p1, m0, m1, t);
      const double an = std::max(a.norm(), kTiny);
      kap[j] = a.cross(b).norm() / (an * an * an);
      if (kap[j] > kap[best]) best = j;
    }
    double tstar = (best + 0.5) / kProbe;
    if (best > 0 && best < kProbe - 1) {
      const double den = kap[best - 1] - 2 * kap[best] + kap[best + 1];
      if (den < 0) tstar += std::clamp(0.5 * (kap[best - 1] - kap[best + 1]) / den, -0.5, 0.5) / kProbe;
    }
    tstar = std::clamp(tstar, 0.05, 0.95);
    // Turning accumulated along the segment (on the probes) and at t*.
    double cum[kProbe + 1];
    cum[0] = 0;
    Eigen::Vector3d prev = hermite_d1(p0, p1, m0, m1, 0);
    for (int j = 1; j <= kProbe; ++j) {
      const Eigen::Vector3d cur = hermite_d1(p0, p1, m0, m1, static_cast<double>(j) / kProbe);
      cum[j] = cum[j - 1] + angle(prev, cur);
      prev = cur;
    }
    auto turning_at = [&](double t) {
      const double f = t * kProbe;
      const int j = std::min(kProbe - 1, static_cast<int>(f));
      return cum[j] + (f - j) * (cum[j + 1] - cum[j]);
    };
    auto param_of = [&](double a) {  // inverse of turning_at
      int j = 0;
      while (j < kProbe - 1 && cum[j + 1] < a) ++j;
      const double span = cum[j + 1] - cum[j];
      return (j + (span > kTiny ? std::clamp((a - cum[j]) / span, 0.0, 1.0) : 0.5)) / kProbe;
    };
    const double total = cum[kProbe], at_star = turning_at(tstar);
    // One extra sample at t*, the others on either side in proportion to the turning there, at equal steps of it.
    const int extra = std::min(params_.max_extra_samples,
                               std::max(1, static_cast<int>(std::ceil(ci / params_.flag_turn)) - 1));
    const int rest = extra - 1;
    const int left = total > kTiny ? static_cast<int>(std::lround(rest * at_star / total)) : rest / 2;
    const int right = rest - left;
    double ts[9];
    int nt = 0;
    for (int m = 1; m <= left; ++m) ts[nt++] = param_of(at_star * m / (left + 1));
    ts[nt++] = tstar;
    for (int m = 1; m <= right; ++m) ts[nt++] = param_of(at_star + (total - at_star) * m / (right + 1));
    // Keep them ordered and at least 0.04 apart (and from the segment's ends).
    double last = 0;
    for (int m = 0; m < nt; ++m) {
      if (ts[m] < last + 0.04 || ts[m] > 0.96) continue;
      push(i, ts[m], true);
      ++stats_.extra_samples;
      last = ts[m];
    }
  }
  push(count - 2, 1.0, false);
  sample_count_ = k;
  return true;
}

void TubeBuilder::erase(int k) noexcept {
  for (int i = k; i + 1 < sample_count_; ++i) {
    samples_[static_cast<std::size_t>(i)] = samples_[static_cast<std::size_t>(i + 1)];
  }
  --sample_count_;
  ++stats_.removed_samples;
}

void TubeBuilder::first_frame(const Eigen::Vector3d& r0) noexcept {
  TubeSample& s = samples_[0];
  Eigen::Vector3d r = r0 - r0.dot(s.tangent) * s.tangent;
  r = r.norm() > 1e-6 ? Eigen::Vector3d(r.normalized()) : orthogonal(s.tangent);
  s.normal = r;
  s.binormal = s.tangent.cross(r);
}

void TubeBuilder::frame_step(int k) noexcept {
  const TubeSample& a = samples_[static_cast<std::size_t>(k)];
  TubeSample& b = samples_[static_cast<std::size_t>(k + 1)];
  b.normal = rmf_step(a.center, a.tangent, a.normal, b.center, b.tangent);
  b.binormal = b.tangent.cross(b.normal);
}

double TubeBuilder::interval_fit(int k) const noexcept {
  // The rings the skinning makes at t = j / 8 (every LOD's rings are among them): centre, plane normal, radius.
  constexpr int kFine = 8;
  const TubeSample &a = samples_[static_cast<std::size_t>(k)], &b = samples_[static_cast<std::size_t>(k + 1)];
  const double len = (b.center - a.center).norm();
  if (!(len > 1e-9)) return 0;
  Eigen::Vector3d c[kFine + 1], n[kFine + 1];
  double rho[kFine + 1];
  for (int j = 0; j <= kFine; ++j) {
    const double t = static_cast<double>(j) / kFine, w = skin_weight(t);
    c[j] = (1 - w) * (a.center + (t * len) * a.tangent) + w * (b.center + ((t - 1) * len) * b.tangent);
    const Eigen::Vector3d u = (1 - w) * a.radius * a.normal + w * b.radius * b.normal;
    const Eigen::Vector3d v = (1 - w) * a.radius * a.binormal + w * b.radius * b.binormal;
    const Eigen::Vector3d nn = u.cross(v);
    const double l = nn.norm();
    if (!(l > 1e-12)) return 0;
    n[j] = nn / l;
    // The ellipse's largest radius: sqrt of the larger eigenvalue of the Gram matrix of (u, v).
    const double guu = u.squaredNorm(), gvv = v.squaredNorm(), guv = u.dot(v);
    const double half = 0.5 * (guu - gvv);
    rho[j] = std::sqrt(0.5 * (guu + gvv) + std::sqrt(half * half + guv * guv));
  }
  // Ring j passes when the other ring's plane meets its own farther than rho_j + e from its centre:
  // d.n_other / sin(theta) >= rho_j + e. The fit is the largest factor on every rho that keeps all pairs passing.
  const double e = params_.ring_clearance;
  double fit = 1e300;
  for (int stride = 1; stride <= kFine; stride *= 2) {
    for (int j = 0; j + stride <= kFine; j += stride) {
      const int i = j + stride;
      const Eigen::Vector3d d = c[i] - c[j];
      const double st = n[j].cross(n[i]).norm();
      const double dj = d.dot(n[i]), di = d.dot(n[j]);
      if (dj <= e * st || di <= e * st) return 0;  // behind, or closer than the clearance alone allows
      if (st < 1e-12) continue;                    // parallel rings ahead of each other
      fit = std::min({fit, (dj / st - e) / rho[j], (di / st - e) / rho[i]});
    }
  }
  return fit;
}

int TubeBuilder::repair(int k, double fit) noexcept {
  const int a = k, b = k + 1, last = sample_count_ - 1;
  // 1. Turn the end rings towards their miters, half way then all the way.
  auto target = [&](int i) {
    const Eigen::Vector3d& ci = samples_[static_cast<std::size_t>(i)].center;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    if (i > 0) m += (ci - samples_[static_cast<std::size_t>(i - 1)].center).normalized();
    if (i < last) m += (samples_[static_cast<std::size_t>(i + 1)].center - ci).normalized();
    return m.norm() > kTiny ? Eigen::Vector3d(m.normalized()) : samples_[static_cast<std::size_t>(i)].spline_tangent;
  };
  bool changed_a = false, changed = false;
  for (int i : {a, b}) {
    TubeSample& s = samples_[static_cast<std::size_t>(i)];
    if (s.tilt >= 4) continue;
    const Eigen::Vector3d m = target(i);
    const double off = angle(s.spline_tangent, m);
    if (off < 0.02) {  // the spline already runs along the miter: turning cannot help
      s.tilt = 4;
      continue;
    }
    s.tilt = std::min(4, s.tilt + 2);  // half way, then all the way
    s.tangent = rotate_towards(s.spline_tangent, m, 0.25 * s.tilt * off);
    changed = true;
    changed_a = changed_a || i == a;
  }
  // 2. Narrow both end rings by the fit the check found (a fold tighter than the tube drawn pinched).
  if (!changed) {
    const double floor = params_.min_radius_fraction * params_.radius;
    const double factor = std::clamp(0.995 * fit, 0.0, 0.95);
    for (int i : {a, b}) {
      TubeSample& s = samples_[static_cast<std::size_t>(i)];
      if (s.radius <= floor * (1 + 1e-9)) continue;
      s.radius = std::max(floor, factor * s.radius);
      changed = true;
      changed_a = changed_a || i == a;
    }
  }
  if (changed) return changed_a ? std::max(0, k - 1) : k;
  // 3. Cut the kink: remove an extra sample at the interval's ends, else the end where the chords turn most (the
  // tube's ends stay).
  if (samples_[static_cast<std::size_t>(b)].extra && b != last) {
    erase(b);
    return k;
  }
  if (samples_[static_cast<std::size_t>(a)].extra && a != 0) {
    erase(a);
    return k - 1;
  }
  auto turn = [&](int i) {
    if (i <= 0 || i >= last) return -1.0;
    const Eigen::Vector3d& ci = samples_[static_cast<std::size_t>(i)].center;
    return angle(ci - samples_[static_cast<std::size_t>(i - 1)].center,
                 samples_[static_cast<std::size_t>(i + 1)].center - ci);
  };
  const double ta = turn(a), tb = turn(b);
  if (tb >= 0 && tb >= ta) {
    erase(b);
    return k;
  }
  if (ta >= 0) {
    erase(a);
    return k - 1;
  }
  return k + 1;  // two samples left: nothing more to do
}

void TubeBuilder::guard(const Eigen::Vector3d& r0) noexcept {
  first_frame(r0);
  int budget = 64 * (max_intervals() + 1);
  int k = 0;
  while (k + 1 < sample_count_ && budget-- > 0) {
    frame_step(k);
    const double fit = interval_fit(k);
    if (fit >= 1) {
      ++k;
      continue;
    }
    const int restart = repair(k, fit);
    if (restart == 0 && k == 0) first_frame(r0);  // sample 0 turned: its frame again
    k = restart;
  }
  // Frames after the last check (budget exhausted or the final interval accepted): complete them.
  for (int i = std::max(0, k); i + 1 < sample_count_; ++i) frame_step(i);
  stats_.min_radius = params_.radius;
  for (int i = 0; i < sample_count_; ++i) {
    const TubeSample& s = samples_[static_cast<std::size_t>(i)];
    stats_.tilted_rings += angle(s.tangent, s.spline_tangent) > 1e-9;
    stats_.narrowed_rings += s.radius < params_.radius;
    stats_.min_radius = std::min(stats_.min_radius, s.radius);
  }
}

void TubeBuilder::skin(int lod, TubeSkinning skinning, TubeMesh& mesh) const noexcept {
  const TubeLod l = tube_lod(lod);
  const TubePrimitive& prim = primitives_[static_cast<std::size_t>(lod)];
  const int sides = l.sides, q = l.rings, intervals = sample_count_ - 1;
  const bool cpu = skinning == TubeSkinning::kCpu;
  int ring = 0;
  for (int k = 0; k < intervals; ++k) {
    const TubeSample &a = samples_[static_cast<std::size_t>(k)], &b = samples_[static_cast<std::size_t>(k + 1)];
    const double len = (b.center - a.center).norm();
    // Skinning matrices for a vertex shader: A = [r_a N_a, r_a B_a, l T_a, c_a], B = [r_b N_b, r_b B_b, l T_b,
    // c_b - l T_b].
    float* m = &mesh.skin[static_cast<std::size_t>(24 * k)];
    for (int row = 0; row < 3; ++row) {
      m[4 * row + 0] = static_cast<float>(a.radius * a.normal[row]);
      m[4 * row + 1] = static_cast<float>(a.radius * a.binormal[row]);
      m[4 * row + 2] = static_cast<float>(len * a.tangent[row]);
      m[4 * row + 3] = static_cast<float>(a.center[row]);
      m[12 + 4 * row + 0] = static_cast<float>(b.radius * b.normal[row]);
      m[12 + 4 * row + 1] = static_cast<float>(b.radius * b.binormal[row]);
      m[12 + 4 * row + 2] = static_cast<float>(len * b.tangent[row]);
      m[12 + 4 * row + 3] = static_cast<float>(b.center[row] - len * b.tangent[row]);
    }
    const int last_ring = k + 1 == intervals ? q : q - 1;
    if (!cpu) {
      ring += last_ring + 1;
      continue;
    }
    for (int j = 0; j <= last_ring; ++j, ++ring) {
      const double t = static_cast<double>(j) / q, w = skin_weight(t);
      const Eigen::Vector3d center =
          (1 - w) * (a.center + (t * len) * a.tangent) + w * (b.center + ((t - 1) * len) * b.tangent);
      const double ra = (1 - w) * a.radius, rb = w * b.radius;
      const Eigen::Vector3d u = ra * a.normal + rb * b.normal, v = ra * a.binormal + rb * b.binormal;
      const Eigen::Vector3d un = (1 - w) * a.normal + w * b.normal, vn = (1 - w) * a.binormal + w * b.binormal;
      for (int i = 0; i < sides; ++i) {
        const auto pi = static_cast<std::size_t>(4 * i);
        const double ca = prim.vertices[pi], sa = prim.vertices[pi + 1];
        const int vi = ring * sides + i;
        put(mesh.positions, vi, center + ca * u + sa * v);
        const Eigen::Vector3d radial = ca * un + sa * vn;
        const double rn = radial.norm();
        put(mesh.normals, vi, rn > kTiny ? Eigen::Vector3d(radial / rn) : a.tangent);
      }
    }
  }
  const int cap_vertices = tube_cap_vertices(l), cap_indices = 3 * tube_cap_triangles(l);
  mesh.ring_count = ring;
  mesh.body_vertex_count = ring * sides;
  mesh.vertex_count = mesh.body_vertex_count + 2 * cap_vertices;
  mesh.body_index_count = (ring - 1) * sides * 6;
  mesh.index_count = mesh.body_index_count + 2 * cap_indices;
  if (!cpu) return;
  // End caps: the primitive's cap vertices on the first and the last ring's frame (z along the ring's tangent).
  for (const bool end : {false, true}) {
    const TubeSample& r = samples_[static_cast<std::size_t>(end ? intervals : 0)];
    const int from = prim.body_vertex_count + (end ? cap_vertices : 0);
    const int to = mesh.body_vertex_count + (end ? cap_vertices : 0);
    for (int i = 0; i < cap_vertices; ++i) {
      const float* v = &prim.vertices[static_cast<std::size_t>(4 * (from + i))];
      const Eigen::Vector3d dir = v[0] * r.normal + v[1] * r.binormal + v[3] * r.tangent;
      put(mesh.positions, to + i, r.center + r.radius * dir);
      put(mesh.normals, to + i, dir.normalized());
    }
  }
  std::size_t idx = 0;
  for (int i = 0; i + 1 < ring; ++i) {
    for (int j = 0; j < sides; ++j) {
      const auto a = static_cast<std::uint32_t>(i * sides + j), b = static_cast<std::uint32_t>(i * sides + (j + 1) % sides);
      const auto c = a + static_cast<std::uint32_t>(sides), d = b + static_cast<std::uint32_t>(sides);
      mesh.indices[idx++] = a;
      mesh.indices[idx++] = b;
      mesh.indices[idx++] = c;
      mesh.indices[idx++] = b;
      mesh.indices[idx++] = d;
      mesh.indices[idx++] = c;
    }
  }
  for (const bool end : {false, true}) {
    const auto cap_ring = static_cast<std::uint32_t>(end ? (ring - 1) * sides : 0);
    const auto interior = static_cast<std::uint32_t>(mesh.body_vertex_count + (end ? cap_vertices : 0));
    idx += static_cast<std::size_t>(write_cap_indices(&mesh.indices[idx], cap_ring, interior, sides, l.cap_rings, end));
  }
}

bool TubeBuilder::build(const double* points, int count, int lod, TubeMesh& mesh, TubeSkinning skinning) noexcept {
  mesh.intervals = mesh.ring_count = mesh.vertex_count = mesh.index_count = 0;
  mesh.body_vertex_count = mesh.body_index_count = 0;
  lod = std::clamp(lod, 0, kTubeMaxLod);
  mesh.lod = lod;
  const TubeLod l = tube_lod(lod);
  mesh.sides = l.sides;
  sample_count_ = 0;
  if (!points || count < 2 || count > max_points_) return false;
  double spread = 0;
  for (int i = 0; i < count; ++i) {
    points_[static_cast<std::size_t>(i)] = Eigen::Vector3d(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
    if (!points_[static_cast<std::size_t>(i)].allFinite()) return false;
    spread = std::max(spread, (points_[static_cast<std::size_t>(i)] - points_[0]).norm());
  }
  if (!(spread > 1e-9)) return false;  // all points in one place: no axis
  sample_spline(count);
  // Frames and ring guard: the first normal continues the previous build's, so the tube does not spin from frame to
  // frame.
  const Eigen::Vector3d r0 = has_previous_normal_ ? previous_normal_ : orthogonal(samples_[0].tangent);
  guard(r0);
  if (sample_count_ < 2) {
    sample_count_ = 0;
    return false;
  }
  const int intervals = sample_count_ - 1;
  const auto body = (static_cast<std::size_t>(intervals) * static_cast<std::size_t>(l.rings) + 1) *
                    static_cast<std::size_t>(l.sides);
  const auto verts = body + 2 * static_cast<std::size_t>(tube_cap_vertices(l));
  const auto indices = (body - static_cast<std::size_t>(l.sides)) * 6 + 6 * static_cast<std::size_t>(tube_cap_triangles(l));
  const bool cpu = skinning == TubeSkinning::kCpu;
  if ((cpu && (mesh.positions.size() < 3 * verts || mesh.normals.size() < 3 * verts || mesh.indices.size() < indices)) ||
      mesh.skin.size() < static_cast<std::size_t>(24 * intervals)) {
    return false;
  }
  previous_normal_ = samples_[0].normal;
  has_previous_normal_ = true;
  stats_.samples = sample_count_;
  mesh.intervals = intervals;
  skin(lod, skinning, mesh);
  return true;
}

MesenteryMesh make_mesentery_mesh(int rows, int cols) {
  if (rows < 2 || cols < 2) throw_error("mesentery mesh: rows and cols must be >= 2 (got ", rows, " x ", cols, ")");
  MesenteryMesh m;
  m.rows = rows;
  m.cols = cols;
  m.vertex_count = rows * cols;
  m.positions.assign(static_cast<std::size_t>(3 * m.vertex_count), 0.0f);
  m.normals.assign(static_cast<std::size_t>(3 * m.vertex_count), 0.0f);
  for (int r = 0; r + 1 < rows; ++r) {
    if (r > 0) {  // degenerate join: repeat the last index and the next strip's first
      m.strip.push_back(m.strip.back());
      m.strip.push_back(static_cast<std::uint32_t>(r * cols));
    }
    for (int c = 0; c < cols; ++c) {
      m.strip.push_back(static_cast<std::uint32_t>(r * cols + c));
      m.strip.push_back(static_cast<std::uint32_t>((r + 1) * cols + c));
    }
  }
  m.index_count = static_cast<int>(m.strip.size());
  return m;
}

bool mesentery_strip(const double* points, MesenteryMesh& m) noexcept {
  const int rows = m.rows, cols = m.cols;
  if (!points || rows < 2 || cols < 2 || m.positions.size() < static_cast<std::size_t>(3 * rows * cols) ||
      m.normals.size() < static_cast<std::size_t>(3 * rows * cols)) {
    return false;
  }
  auto p = [&](int r, int c) {
    const double* q = points + 3 * (r * cols + c);
    return Eigen::Vector3d(q[0], q[1], q[2]);
  };
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const Eigen::Vector3d x = p(r, c);
      if (!x.allFinite()) return false;
      put(m.positions, r * cols + c, x);
      // Grid normal from central differences (one-sided on the borders).
      const Eigen::Vector3d du = p(r, std::min(c + 1, cols - 1)) - p(r, std::max(c - 1, 0));
      const Eigen::Vector3d dv = p(std::min(r + 1, rows - 1), c) - p(std::max(r - 1, 0), c);
      const Eigen::Vector3d n = du.cross(dv);
      const double nn = n.norm();
      put(m.normals, r * cols + c, nn > kTiny ? Eigen::Vector3d(n / nn) : Eigen::Vector3d::UnitZ());
    }
  }
  return true;
}

namespace {

// Catmull-Rom tangent (tension 0) of point i of a sequence of n >= 2, one-sided at the ends (cardinal_tangents).
template <typename At>
Eigen::Vector3d catmull_rom_tangent(const At& at, int i, int n) {
  if (i == 0) return at(1) - at(0);
  if (i == n - 1) return at(n - 1) - at(n - 2);
  return 0.5 * (at(i + 1) - at(i - 1));
}

// Grid interval and parameter in it of refined index k (steps per interval, n grid points).
void refined(int k, int steps, int n, int& interval, double& t) {
  interval = std::min(k / steps, n - 2);
  t = static_cast<double>(k - interval * steps) / steps;
}

}  // namespace

MesenterySurface make_mesentery_surface(int rows, int cols, int row_steps, int col_steps) {
  if (rows < 2 || cols < 2 || row_steps < 1 || row_steps > 16 || col_steps < 1 || col_steps > 16) {
    throw_error("mesentery surface: rows and cols must be >= 2 and steps in 1..16 (got ", rows, " x ", cols,
                ", steps ", row_steps, " x ", col_steps, ")");
  }
  MesenterySurface s;
  s.rows = rows;
  s.cols = cols;
  s.row_steps = row_steps;
  s.col_steps = col_steps;
  s.vertex_rows = (rows - 1) * row_steps + 1;
  s.vertex_cols = (cols - 1) * col_steps + 1;
  s.vertex_count = s.vertex_rows * s.vertex_cols;
  const auto n = static_cast<std::size_t>(s.vertex_count);
  s.positions.assign(3 * n, 0.0f);
  s.normals.assign(3 * n, 0.0f);
  s.coords.resize(2 * n);
  for (int i = 0; i < s.vertex_rows; ++i) {
    for (int j = 0; j < s.vertex_cols; ++j) {
      const auto k = static_cast<std::size_t>(i * s.vertex_cols + j);
      s.coords[2 * k] = static_cast<float>(j) / static_cast<float>(col_steps);
      s.coords[2 * k + 1] = static_cast<float>(i) / static_cast<float>(s.vertex_rows - 1);
    }
  }
  s.indices.reserve(static_cast<std::size_t>(6 * (s.vertex_rows - 1) * (s.vertex_cols - 1)));
  for (int i = 0; i + 1 < s.vertex_rows; ++i) {
    for (int j = 0; j + 1 < s.vertex_cols; ++j) {
      const auto a = static_cast<std::uint32_t>(i * s.vertex_cols + j), b = a + 1,
                 c = a + static_cast<std::uint32_t>(s.vertex_cols), d = c + 1;
      s.indices.insert(s.indices.end(), {a, b, d, a, d, c});  // (b - a) x (d - a) along dS/du x dS/dv
    }
  }
  s.along.resize(static_cast<std::size_t>(rows * s.vertex_cols));
  s.along_du.resize(s.along.size());
  return s;
}

bool mesentery_surface(const double* points, MesenterySurface& s) noexcept {
  const int rows = s.rows, cols = s.cols, vc = s.vertex_cols;
  if (!points || rows < 2 || cols < 2 || s.vertex_count != s.vertex_rows * vc ||
      s.positions.size() < 3 * static_cast<std::size_t>(s.vertex_count) ||
      s.normals.size() < 3 * static_cast<std::size_t>(s.vertex_count) ||
      s.along.size() < static_cast<std::size_t>(rows * vc) || s.along_du.size() < s.along.size()) {
    return false;
  }
  for (int i = 0; i < 3 * rows * cols; ++i) {
    if (!std::isfinite(points[i])) return false;
  }
  // 1. Each grid row refined along u (the cardinal spline of the tube's axis for row 0): point and d/du.
  for (int r = 0; r < rows; ++r) {
    const auto grid = [&](int c) {
      const double* q = points + 3 * (r * cols + c);
      return Eigen::Vector3d(q[0], q[1], q[2]);
    };
    for (int j = 0; j < vc; ++j) {
      int c = 0;
      double t = 0;
      refined(j, s.col_steps, cols, c, t);
      const Eigen::Vector3d p0 = grid(c), p1 = grid(c + 1);
      const Eigen::Vector3d m0 = catmull_rom_tangent(grid, c, cols), m1 = catmull_rom_tangent(grid, c + 1, cols);
      const auto k = static_cast<std::size_t>(r * vc + j);
      s.along[k] = hermite(p0, p1, m0, m1, t);
      s.along_du[k] = hermite_d1(p0, p1, m0, m1, t);
    }
  }
  // 2. Across the rows: the same spline of the refined points (S, dS/dv) and of their u-derivatives (dS/du; the
  //    tensor product is linear in the grid, so interpolating the derivatives is differentiating the patch).
  s.degenerate_normals = 0;
  for (int j = 0; j < vc; ++j) {
    const auto a = [&](int r) { return s.along[static_cast<std::size_t>(r * vc + j)]; };
    const auto d = [&](int r) { return s.along_du[static_cast<std::size_t>(r * vc + j)]; };
    for (int i = 0; i < s.vertex_rows; ++i) {
      int r = 0;
      double t = 0;
      refined(i, s.row_steps, rows, r, t);
      const Eigen::Vector3d p = hermite(a(r), a(r + 1), catmull_rom_tangent(a, r, rows),
                                        catmull_rom_tangent(a, r + 1, rows), t);
      const Eigen::Vector3d dv = hermite_d1(a(r), a(r + 1), catmull_rom_tangent(a, r, rows),
                                            catmull_rom_tangent(a, r + 1, rows), t);
      const Eigen::Vector3d du = hermite(d(r), d(r + 1), catmull_rom_tangent(d, r, rows),
                                         catmull_rom_tangent(d, r + 1, rows), t);
      const int v = i * vc + j;
      put(s.positions, v, p);
      const Eigen::Vector3d n = du.cross(dv);
      const double nn = n.norm();
      if (nn > 1e-9 * du.norm() * dv.norm() && nn > 1e-14) {
        put(s.normals, v, n / nn);
      } else {
        put(s.normals, v, Eigen::Vector3d::Zero());  // filled below
        ++s.degenerate_normals;
      }
    }
  }
  // 3. Degenerate normals (a point the rows converge to): the nearest valid one of the vertex row, then of the column.
  if (s.degenerate_normals > 0) {
    const auto valid = [&](int v) {
      const auto k = static_cast<std::size_t>(3 * v);
      return s.normals[k] != 0.0f || s.normals[k + 1] != 0.0f || s.normals[k + 2] != 0.0f;
    };
    const auto copy = [&](int to, int from) {
      for (std::size_t c = 0; c < 3; ++c) {
        s.normals[static_cast<std::size_t>(3 * to) + c] = s.normals[static_cast<std::size_t>(3 * from) + c];
      }
    };
    for (int i = 0; i < s.vertex_rows; ++i) {
      for (int j = 0; j < vc; ++j) {
        const int v = i * vc + j;
        if (valid(v)) continue;
        int from = -1;
        for (int k = 1; from < 0 && k < vc; ++k) {
          if (j + k < vc && valid(v + k)) from = v + k;
          else if (j - k >= 0 && valid(v - k)) from = v - k;
        }
        for (int k = 1; from < 0 && k < s.vertex_rows; ++k) {
          if (i + k < s.vertex_rows && valid(v + k * vc)) from = v + k * vc;
          else if (i - k >= 0 && valid(v - k * vc)) from = v - k * vc;
        }
        if (from >= 0) {
          copy(v, from);
        } else {
          put(s.normals, v, Eigen::Vector3d::UnitZ());
        }
      }
    }
  }
  return true;
}

}  // namespace surgsim::intestine
