#include "tube_geometry.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "error.h"

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

// Projection of unit t into the cone of axis d (unit) and half-angle phi.
Eigen::Vector3d into_cone(const Eigen::Vector3d& t, const Eigen::Vector3d& d, double phi) {
  return angle(t, d) <= phi ? t : rotate_towards(d, t, phi);
}

void put(std::vector<float>& v, int i, const Eigen::Vector3d& p) {
  const auto k = static_cast<std::size_t>(3 * i);
  v[k] = static_cast<float>(p.x());
  v[k + 1] = static_cast<float>(p.y());
  v[k + 2] = static_cast<float>(p.z());
}

}  // namespace

TubeLod tube_lod(int lod) {
  lod = std::clamp(lod, 0, kTubeMaxLod);
  return TubeLod{4 << ((lod + 1) / 2), 1 << (lod / 2)};
}

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

void rotation_minimizing_frames(const Eigen::Vector3d* x, const Eigen::Vector3d* t, int n, const Eigen::Vector3d& r0,
                                Eigen::Vector3d* r, Eigen::Vector3d* s) {
  if (n <= 0) return;
  r[0] = r0;
  s[0] = t[0].cross(r[0]);
  for (int i = 0; i + 1 < n; ++i) {
    // Reflection in the bisecting plane of x_i, x_{i+1}, then in the plane that maps the reflected tangent onto
    // t_{i+1}: the composition rotates the frame with (to fourth order) no twist about the tangent.
    const Eigen::Vector3d v1 = x[i + 1] - x[i];
    const double c1 = v1.squaredNorm();
    Eigen::Vector3d rl = r[i], tl = t[i];
    if (c1 > kTiny * kTiny) {
      rl = r[i] - (2.0 / c1) * v1.dot(r[i]) * v1;
      tl = t[i] - (2.0 / c1) * v1.dot(t[i]) * v1;
    }
    const Eigen::Vector3d v2 = t[i + 1] - tl;
    const double c2 = v2.squaredNorm();
    Eigen::Vector3d rn = c2 > kTiny * kTiny ? Eigen::Vector3d(rl - (2.0 / c2) * v2.dot(rl) * v2) : rl;
    // Re-orthonormalize against round-off (and tangents the guard turned).
    rn -= rn.dot(t[i + 1]) * t[i + 1];
    const double len = rn.norm();
    r[i + 1] = len > kTiny ? Eigen::Vector3d(rn / len) : orthogonal(t[i + 1]);
    s[i + 1] = t[i + 1].cross(r[i + 1]);
  }
}

TubeBuilder::TubeBuilder(const TubeParams& params, int max_points) : params_(params), max_points_(max_points) {
  if (max_points < 2) throw_error("tube: max_points must be >= 2 (got ", max_points, ")");
  if (!(params.radius > 0) || !(params.tension >= 0 && params.tension < 1) || !(params.flag_turn > 0) ||
      params.max_extra_samples < 0 || params.max_extra_samples > 8 || !(params.fold_safety >= 1.5)) {
    throw_error("tube: radius > 0, tension in [0, 1), flag_turn > 0, max_extra_samples in 0..8, fold_safety >= 1.5");
  }
  const auto np = static_cast<std::size_t>(max_points);
  points_.resize(np);
  tangents_.resize(np);
  curvature_.assign(np, 0.0);
  const auto ns = static_cast<std::size_t>(max_intervals() + 1);
  samples_.resize(ns);
  centers_.resize(ns);
  ring_tangents_.resize(ns);
  normals_.resize(ns);
  binormals_.resize(ns);
  // Primitives: (rings + 1) x sides vertices (cos a, sin a, t, w(t)).
  for (int lod = 0; lod <= kTubeMaxLod; ++lod) {
    TubePrimitive prim;
    prim.lod = tube_lod(lod);
    const int s = prim.lod.sides, q = prim.lod.rings;
    for (int j = 0; j <= q; ++j) {
      const double t = static_cast<double>(j) / q;
      for (int k = 0; k < s; ++k) {
        const double a = 2 * kPi * k / s;
        prim.vertices.insert(prim.vertices.end(), {static_cast<float>(std::cos(a)), static_cast<float>(std::sin(a)),
                                                   static_cast<float>(t), static_cast<float>(skin_weight(t))});
      }
    }
    for (int j = 0; j < q; ++j) {
      for (int k = 0; k < s; ++k) {
        const auto a = static_cast<std::uint32_t>(j * s + k), b = static_cast<std::uint32_t>(j * s + (k + 1) % s);
        const auto c = a + static_cast<std::uint32_t>(s), d = b + static_cast<std::uint32_t>(s);
        prim.indices.insert(prim.indices.end(), {a, b, c, b, d, c});
      }
    }
    primitives_.push_back(std::move(prim));
  }
}

TubeMesh TubeBuilder::make_mesh(int lod) const {
  lod = std::clamp(lod, 0, kTubeMaxLod);
  const TubeLod l = tube_lod(lod);
  const auto rings = static_cast<std::size_t>(max_intervals()) * static_cast<std::size_t>(l.rings) + 1;
  const auto verts = rings * static_cast<std::size_t>(l.sides);
  TubeMesh m;
  m.lod = lod;
  m.positions.assign(3 * verts, 0.0f);
  m.normals.assign(3 * verts, 0.0f);
  m.indices.assign((rings - 1) * static_cast<std::size_t>(l.sides) * 6, 0u);
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
    s.tangent = d.normalized();
    s.segment = seg;
    s.t = t;
    s.extra = extra;
    s.tilted = false;
    ++k;
  };
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
    constexpr int kProbe = 16;
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
    // Extra samples clustered around t*: more for a larger turn.
    const int extra = std::min(params_.max_extra_samples,
                               std::max(1, static_cast<int>(std::ceil(ci / params_.flag_turn)) - 1));
    const double tc = std::clamp(tstar, 0.1, 0.9);
    const double span = std::min(0.7, 1.8 * std::min(tc, 1 - tc));
    for (int j = 0; j < extra; ++j) {
      const double t = extra == 1 ? tc : tc + span * (static_cast<double>(j) / (extra - 1) - 0.5);
      push(i, std::clamp(t, 0.02, 0.98), true);
      ++stats_.extra_samples;
    }
  }
  push(count - 2, 1.0, false);
  sample_count_ = k;
  return true;
}

void TubeBuilder::guard() noexcept {
  const double r = params_.radius, kappa = params_.fold_safety;
  auto phi = [&](double l) { return std::min(0.25 * kPi, std::asin(std::min(1.0, l / (2 * kappa * r)))); };
  auto erase = [&](int k) {
    for (int i = k; i + 1 < sample_count_; ++i) {
      samples_[static_cast<std::size_t>(i)] = samples_[static_cast<std::size_t>(i + 1)];
    }
    --sample_count_;
    ++stats_.removed_samples;
  };
  bool changed = true;
  for (int pass = 0; changed && pass < 4 * max_intervals() + 4; ++pass) {
    changed = false;
    for (int k = 0; k < sample_count_ && sample_count_ >= 2; ++k) {
      TubeSample& s = samples_[static_cast<std::size_t>(k)];
      const bool first = k == 0, last = k == sample_count_ - 1;
      Eigen::Vector3d dp = Eigen::Vector3d::Zero(), dn = Eigen::Vector3d::Zero();
      double lp = 0, ln = 0;
      if (!first) {
        dp = s.center - samples_[static_cast<std::size_t>(k - 1)].center;
        lp = dp.norm();
      }
      if (!last) {
        dn = samples_[static_cast<std::size_t>(k + 1)].center - s.center;
        ln = dn.norm();
      }
      // Coincident rings: remove the interior one of the pair.
      if ((!first && lp < 1e-9) || (!last && ln < 1e-9)) {
        if (sample_count_ <= 2) return;
        erase(!last ? (first ? k + 1 : k) : k - 1);
        changed = true;
        break;
      }
      Eigen::Vector3d t = s.tangent;
      if (first) {
        t = into_cone(t, dn / ln, phi(ln));
      } else if (last) {
        t = into_cone(t, dp / lp, phi(lp));
      } else {
        const Eigen::Vector3d up = dp / lp, un = dn / ln;
        const double fp = phi(lp), fn = phi(ln), beta = angle(up, un);
        if (beta > fp + fn) {  // the two cones are disjoint: a kink the tube cannot follow
          erase(k);
          changed = true;
          break;
        }
        // Alternating projections onto the two (convex) caps, then a point of the arc between the axes that lies in
        // both if they have not converged.
        for (int it = 0; it < 8 && (angle(t, up) > fp + 1e-12 || angle(t, un) > fn + 1e-12); ++it) {
          t = into_cone(into_cone(t, up, fp), un, fn);
        }
        if (angle(t, up) > fp + 1e-9 || angle(t, un) > fn + 1e-9) {
          const double lo = std::max(0.0, beta - fn), hi = std::min(beta, fp);
          t = rotate_towards(up, un, 0.5 * (lo + hi));
        }
      }
      if (angle(t, s.tangent) > 1e-12) {
        s.tangent = t.normalized();
        s.tilted = true;
      }
    }
  }
  for (int k = 0; k < sample_count_; ++k) stats_.tilted_rings += samples_[static_cast<std::size_t>(k)].tilted ? 1 : 0;
}

void TubeBuilder::skin(int lod, TubeMesh& mesh) const noexcept {
  const TubeLod l = tube_lod(lod);
  const TubePrimitive& prim = primitives_[static_cast<std::size_t>(lod)];
  const int sides = l.sides, q = l.rings, intervals = sample_count_ - 1;
  const double r = params_.radius;
  int ring = 0;
  for (int k = 0; k < intervals; ++k) {
    const TubeSample &a = samples_[static_cast<std::size_t>(k)], &b = samples_[static_cast<std::size_t>(k + 1)];
    const double len = (b.center - a.center).norm();
    // Skinning matrices for a vertex shader: A = [r N_a, r B_a, l T_a, c_a], B = [r N_b, r B_b, l T_b, c_b - l T_b].
    float* m = &mesh.skin[static_cast<std::size_t>(24 * k)];
    for (int row = 0; row < 3; ++row) {
      m[4 * row + 0] = static_cast<float>(r * a.normal[row]);
      m[4 * row + 1] = static_cast<float>(r * a.binormal[row]);
      m[4 * row + 2] = static_cast<float>(len * a.tangent[row]);
      m[4 * row + 3] = static_cast<float>(a.center[row]);
      m[12 + 4 * row + 0] = static_cast<float>(r * b.normal[row]);
      m[12 + 4 * row + 1] = static_cast<float>(r * b.binormal[row]);
      m[12 + 4 * row + 2] = static_cast<float>(len * b.tangent[row]);
      m[12 + 4 * row + 3] = static_cast<float>(b.center[row] - len * b.tangent[row]);
    }
    const int last_ring = k + 1 == intervals ? q : q - 1;
    for (int j = 0; j <= last_ring; ++j, ++ring) {
      const double t = static_cast<double>(j) / q, w = skin_weight(t);
      const Eigen::Vector3d center =
          (1 - w) * (a.center + (t * len) * a.tangent) + w * (b.center + ((t - 1) * len) * b.tangent);
      const Eigen::Vector3d u = (1 - w) * a.normal + w * b.normal, v = (1 - w) * a.binormal + w * b.binormal;
      for (int i = 0; i < sides; ++i) {
        const auto pi = static_cast<std::size_t>(4 * i);
        const double ca = prim.vertices[pi], sa = prim.vertices[pi + 1];
        Eigen::Vector3d radial = ca * u + sa * v;
        const int vi = ring * sides + i;
        put(mesh.positions, vi, center + r * radial);
        const double rn = radial.norm();
        put(mesh.normals, vi, rn > kTiny ? Eigen::Vector3d(radial / rn) : a.tangent);
      }
    }
  }
  mesh.ring_count = ring;
  mesh.vertex_count = ring * sides;
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
  mesh.index_count = static_cast<int>(idx);
}

bool TubeBuilder::build(const double* points, int count, int lod, TubeMesh& mesh) noexcept {
  mesh.intervals = mesh.ring_count = mesh.vertex_count = mesh.index_count = 0;
  lod = std::clamp(lod, 0, kTubeMaxLod);
  mesh.lod = lod;
  const TubeLod l = tube_lod(lod);
  mesh.sides = l.sides;
  sample_count_ = 0;
  if (!points || count < 2 || count > max_points_) return false;
  for (int i = 0; i < count; ++i) {
    points_[static_cast<std::size_t>(i)] = Eigen::Vector3d(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
    if (!points_[static_cast<std::size_t>(i)].allFinite()) return false;
  }
  sample_spline(count);
  guard();
  if (sample_count_ < 2) {
    sample_count_ = 0;
    return false;
  }
  const int intervals = sample_count_ - 1;
  const auto verts = (static_cast<std::size_t>(intervals) * static_cast<std::size_t>(l.rings) + 1) *
                     static_cast<std::size_t>(l.sides);
  if (mesh.positions.size() < 3 * verts || mesh.normals.size() < 3 * verts ||
      mesh.indices.size() < (verts - static_cast<std::size_t>(l.sides)) * 6 ||
      mesh.skin.size() < static_cast<std::size_t>(24 * intervals)) {
    return false;
  }
  // Frames: the first normal continues the previous build's, so the tube does not spin from frame to frame.
  for (int k = 0; k < sample_count_; ++k) {
    centers_[static_cast<std::size_t>(k)] = samples_[static_cast<std::size_t>(k)].center;
    ring_tangents_[static_cast<std::size_t>(k)] = samples_[static_cast<std::size_t>(k)].tangent;
  }
  const Eigen::Vector3d& t0 = ring_tangents_[0];
  Eigen::Vector3d r0 = has_previous_normal_ ? Eigen::Vector3d(previous_normal_ - previous_normal_.dot(t0) * t0)
                                            : Eigen::Vector3d::Zero();
  r0 = r0.norm() > 1e-6 ? Eigen::Vector3d(r0.normalized()) : orthogonal(t0);
  rotation_minimizing_frames(centers_.data(), ring_tangents_.data(), sample_count_, r0, normals_.data(),
                             binormals_.data());
  for (int k = 0; k < sample_count_; ++k) {
    samples_[static_cast<std::size_t>(k)].normal = normals_[static_cast<std::size_t>(k)];
    samples_[static_cast<std::size_t>(k)].binormal = binormals_[static_cast<std::size_t>(k)];
  }
  previous_normal_ = normals_[0];
  has_previous_normal_ = true;
  stats_.samples = sample_count_;
  mesh.intervals = intervals;
  skin(lod, mesh);
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

}  // namespace surgsim::intestine
