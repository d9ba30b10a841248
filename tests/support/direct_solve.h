// A reference for the contact solve of several instruments, built from geometry alone: the rest mesh, its tets, the
// material, the fixed nodes and each tool point's position, radius and shaft direction. Nothing here reads the state
// of the contact code it checks (ToolContacts' patches, offsets, near fields) nor calls the project's contact, tool,
// FEM or CHOLMOD code, so a wrong patch in the code under test cannot pass as its own reference. Used by the liver
// two-hands test and two_hands_bench.
//
// What it codes, from the contact model's description (README, "The liver's contact"; contact/contact_surface.h and
// contact/near_field.h document the definitions):
//  - the boundary of the tet mesh (faces of one tet, outward) and its area-weighted vertex normals;
//  - the contact point: the closest point of the rest surface to the tool point among the faces turned towards the
//    instrument (a brute-force search), its normal the vertex normals interpolated there;
//  - the footprint: node i's weight is its shape function integrated against the flat punch's pressure
//    p(rho) = 1 / (2 pi a sqrt(a^2 - rho^2)) over the tip's disc (radius a, in the plane normal to the contact
//    normal), projected along that normal onto the surface; the model's quadrature rule, 4 rings at
//    rho = a sqrt(1 - u^2) with u the 4-point Gauss-Legendre nodes on [0, 1] (in u the pressure's load is uniform),
//    12 angles per ring, odd rings turned by half a step, angle 0 along x (y when the normal is nearly along x)
//    made normal; fixed nodes left out, the rest normalized to sum 1;
//  - the patch normal (sum w_i n_i, normalized), the depth (contact point - tool point along it) and the imposed
//    offset: -depth along the normal for a sliding contact, the tool point less the grasped contact point (where the
//    tool point was when the jaw closed) for a grasp, three Cartesian rows;
//  - the near field in series (Boussinesq's punch k pi / (2a), k = (1 - nu^2) / (pi E), less the mesh's own local
//    compliance within one ring and the half-space kernel beyond; tangential rows (2 - nu) / (2 (1 - nu)) times it),
//    with the mesh's compliance G taken from this file's own stiffness, the hat-function interactions by the same
//    rule as the model's (4 x 4 sub-triangles, a sub-triangle's self term that of a disc of its area, two
//    sub-triangles as two discs to second order: contact/near_field.*), whose accuracy near_field_test checks;
//  - K_ff of P1 linear elasticity assembled tet by tet here, factored by Eigen's SparseLU; the constraints imposed
//    by Lagrange multipliers, S = A K_ff^-1 A^T + near field, mu = S^-1 b.
// The quadrature rules are reproduced (not approximated differently) so that the comparison can be exact to 1e-9;
// that the footprint rule integrates the punch's pressure is checked against a fine quadrature in the two-hands test.
#pragma once
#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <utility>
#include <vector>

namespace surgsim::test {

/// One tool point in contact, as the instrument's geometry gives it.
struct ReferenceContact {
  int instrument = 0;
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();        // m, the tool point now
  Eigen::Vector3d axis = -Eigen::Vector3d::UnitZ();     // unit, the shaft from trocar to tip: only faces turned
                                                        // towards the instrument (n . axis < 0) are touched
  double radius = 0.0025;                               // m, the tip's radius
  bool grasp = false;                                   // a grasp: 3-D hold of the grasped contact point
  Eigen::Vector3d grasp_tip = Eigen::Vector3d::Zero();  // m, where the tool point was when the jaw closed
};

/// The constraint the reference derives for one contact.
struct ReferencePatch {
  int instrument = 0;
  bool three_d = false;
  std::vector<int> nodes;                            // ascending
  std::vector<double> weights;                       // sum 1
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // m, the footprint's centre on the rest surface
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // m, imposed patch displacement
  double depth = 0;                                  // m, below the rest surface along the normal
  double near_normal = 0, near_tangent = 0;          // m/N
};

class DirectReference {
 public:
  static constexpr int kRings = 4, kAngles = 12;  // the footprint's quadrature
  static constexpr int kSplit = 4;                // sub-triangles per edge in the hat-function integrals

  /// `nodes` #V x 3 (m), `tets` #T x 4, E (Pa), nu, the fixed (whole) nodes.
  DirectReference(const Eigen::MatrixX3d& nodes, const Eigen::MatrixX4i& tets, double young, double poisson,
                  const std::vector<int>& fixed_nodes)
      : x_(nodes), young_(young), poisson_(poisson) {
    const auto nv = static_cast<std::size_t>(nodes.rows());
    fixed_.assign(nv, 0);
    for (int n : fixed_nodes) fixed_[static_cast<std::size_t>(n)] = 1;
    boundary(tets);
    assemble(tets);
  }

  bool ok() const { return ok_; }
  int free_dofs() const { return static_cast<int>(k_ff_.rows()); }
  const std::vector<std::array<int, 3>>& triangles() const { return tris_; }
  const Eigen::Vector3d& vertex_normal(int n) const { return vnormal_[static_cast<std::size_t>(n)]; }
  double kernel() const { return (1 - poisson_ * poisson_) / (kPi * young_); }

  /// The footprint's weights at contact point `centre` with normal `n`, radius a, over free nodes (sum 1; empty when
  /// no free node is under the tip): (node, weight) ascending by node. `rings` x `angles` quadrature points: the
  /// model's rule by default; a finer rule integrates the same weights more exactly.
  std::vector<std::pair<int, double>> footprint(const Eigen::Vector3d& centre, const Eigen::Vector3d& n, double a,
                                                int rings = kRings, int angles = kAngles) const {
    std::vector<double> gx, gw;
    gauss_legendre(rings, gx, gw);
    Eigen::Vector3d t1 = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    t1 = (t1 - t1.dot(n) * n).normalized();
    const Eigen::Vector3d t2 = n.cross(t1);
    std::map<int, double> w;
    for (int r = 0; r < rings; ++r) {
      const auto sr = static_cast<std::size_t>(r);
      const double u = 0.5 * (gx[sr] + 1), rho = a * std::sqrt(1 - u * u), share = 0.5 * gw[sr] / angles;
      for (int k = 0; k < angles; ++k) {
        const double theta = 2 * kPi * (k + 0.5 * (r % 2)) / angles;
        const Eigen::Vector3d q = centre + rho * (std::cos(theta) * t1 + std::sin(theta) * t2);
        int tri = -1;
        Eigen::Vector3d bary;
        if (!project(q, n, t1, t2, tri, bary)) continue;
        for (int v = 0; v < 3; ++v)
          w[tris_[static_cast<std::size_t>(tri)][static_cast<std::size_t>(v)]] += share * std::max(bary[v], 0.0);
      }
    }
    std::vector<std::pair<int, double>> out;
    double sum = 0;
    for (const auto& [node, weight] : w)
      if (fixed_[static_cast<std::size_t>(node)] == 0 && weight > 0) {
        out.emplace_back(node, weight);
        sum += weight;
      }
    if (!(sum > 0)) return {};
    for (auto& e : out) e.second /= sum;
    return out;
  }

  /// The closest point of the rest surface to p among the faces with normal . axis < 0, and its interpolated normal.
  bool contact_point(const Eigen::Vector3d& p, const Eigen::Vector3d& axis, Eigen::Vector3d& point,
                     Eigen::Vector3d& normal) const {
    double best = HUGE_VAL;
    for (std::size_t f = 0; f < tris_.size(); ++f) {
      if (!(fnormal_[f].dot(axis) < 0)) continue;
      const Eigen::Vector3d a = node(tris_[f][0]), b = node(tris_[f][1]), c = node(tris_[f][2]);
      Eigen::Vector3d bary;
      const Eigen::Vector3d q = closest_on_triangle(p, a, b, c, bary);
      const double d = (q - p).norm();
      if (d < best - 1e-12) {
        best = d;
        point = q;
        normal = Eigen::Vector3d::Zero();
        for (int v = 0; v < 3; ++v) normal += bary[v] * vertex_normal(tris_[f][static_cast<std::size_t>(v)]);
        normal.normalize();
      }
    }
    return best < HUGE_VAL;
  }

  /// The constraint of one contact (nodes empty: nothing free under the tip).
  ReferencePatch patch(const ReferenceContact& c) const {
    ReferencePatch p;
    p.instrument = c.instrument;
    p.three_d = c.grasp;
    Eigen::Vector3d anchor = Eigen::Vector3d::Zero(), anchor_normal = Eigen::Vector3d::UnitZ();
    if (!contact_point(c.tip, c.axis, anchor, anchor_normal)) return p;
    Eigen::Vector3d centre = anchor, n0 = anchor_normal;
    if (c.grasp && !contact_point(c.grasp_tip, c.axis, centre, n0)) return p;
    p.centre = centre;
    for (const auto& [node, weight] : footprint(centre, n0, c.radius)) {
      p.nodes.push_back(node);
      p.weights.push_back(weight);
    }
    if (p.nodes.empty()) return p;
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (std::size_t e = 0; e < p.nodes.size(); ++e) n += p.weights[e] * vertex_normal(p.nodes[e]);
    p.normal = n.normalized();
    p.depth = (anchor - c.tip).dot(p.normal);
    p.offset = c.grasp ? Eigen::Vector3d(c.tip - centre) : Eigen::Vector3d(-p.depth * p.normal);
    p.near_normal = near_normal(p.nodes, p.weights, c.radius);
    p.near_tangent = (2 - poisson_) / (2 * (1 - poisson_)) * p.near_normal;
    return p;
  }

  /// Minimum energy with every patch's rows imposed (one along the normal, or three Cartesian for a grasp): the
  /// force on each of `instruments` instruments, minus its rows' forces on the organ.
  std::vector<Eigen::Vector3d> forces(const std::vector<ReferencePatch>& patches, int instruments) const {
    struct Row {
      std::size_t patch;
      Eigen::Vector3d d;
    };
    std::vector<Row> rows;
    for (std::size_t q = 0; q < patches.size(); ++q) {
      if (patches[q].nodes.empty()) continue;
      if (patches[q].three_d)
        for (int r = 0; r < 3; ++r) rows.push_back({q, Eigen::Vector3d::Unit(r)});
      else
        rows.push_back({q, patches[q].normal});
    }
    const auto m = static_cast<Eigen::Index>(rows.size());
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(k_ff_.rows(), m);
    Eigen::VectorXd b(m);
    for (Eigen::Index r = 0; r < m; ++r) {
      const Row& row = rows[static_cast<std::size_t>(r)];
      const ReferencePatch& p = patches[row.patch];
      for (std::size_t e = 0; e < p.nodes.size(); ++e)
        for (int k = 0; k < 3; ++k) {
          const int f = free_index_[static_cast<std::size_t>(3 * p.nodes[e] + k)];
          if (f >= 0) a(f, r) += p.weights[e] * row.d[k];
        }
      b[r] = row.d.dot(p.offset);
    }
    const Eigen::MatrixXd x = lu_->solve(a);
    Eigen::MatrixXd s = a.transpose() * x;
    for (Eigen::Index r = 0; r < m; ++r)
      for (Eigen::Index l = 0; l < m; ++l) {
        const Row &x_r = rows[static_cast<std::size_t>(r)], &x_l = rows[static_cast<std::size_t>(l)];
        if (x_r.patch != x_l.patch) continue;
        const ReferencePatch& p = patches[x_r.patch];
        const Eigen::Matrix3d near = p.near_tangent * Eigen::Matrix3d::Identity() +
                                     (p.near_normal - p.near_tangent) * p.normal * p.normal.transpose();
        s(r, l) += x_r.d.dot(near * x_l.d);
      }
    const Eigen::VectorXd mu = s.fullPivLu().solve(b);
    std::vector<Eigen::Vector3d> force(static_cast<std::size_t>(instruments), Eigen::Vector3d::Zero());
    for (Eigen::Index r = 0; r < m; ++r) {
      const Row& row = rows[static_cast<std::size_t>(r)];
      force[static_cast<std::size_t>(patches[row.patch].instrument)] -= mu[r] * row.d;
    }
    return force;
  }
  /// The displacement (m) of every node (#V x 3; fixed nodes 0) under forces (N) on nodes: K_ff u = f solved with
  /// this file's own stiffness (another organ's known loads: the bowel resting on the liver).
  Eigen::MatrixX3d displacements(const std::vector<std::pair<int, Eigen::Vector3d>>& loads) const {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(k_ff_.rows());
    for (const auto& [node, force] : loads)
      for (int k = 0; k < 3; ++k) {
        const int d = free_index_[static_cast<std::size_t>(3 * node + k)];
        if (d >= 0) f[d] += force[k];  // a fixed node's share goes to the support
      }
    const Eigen::VectorXd u = lu_->solve(f);
    Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(x_.rows(), 3);
    for (Eigen::Index j = 0; j < x_.rows(); ++j)
      for (int k = 0; k < 3; ++k) {
        const int d = free_index_[static_cast<std::size_t>(3 * j + k)];
        if (d >= 0) out(j, k) = u[d];
      }
    return out;
  }
  std::vector<Eigen::Vector3d> forces(const std::vector<ReferenceContact>& contacts, int instruments) const {
    std::vector<ReferencePatch> patches;
    for (const ReferenceContact& c : contacts) patches.push_back(patch(c));
    return forces(patches, instruments);
  }

  /// The near field in series with a patch of radius a (m/N), clamped at >= 0.
  double near_normal(const std::vector<int>& nodes, const std::vector<double>& weights, double a) const {
    const double k = kernel();
    double sum = 0;
    for (std::size_t p = 0; p < nodes.size(); ++p)
      for (std::size_t q = 0; q < nodes.size(); ++q) sum += weights[p] * weights[q] * local(nodes[p], nodes[q]);
    const double d = k * kPi / (2 * a) - sum;
    return std::isfinite(d) && d > 0 ? d : 0.0;
  }

 private:
  static constexpr double kPi = 3.14159265358979323846;

  Eigen::Vector3d node(int n) const { return x_.row(n).transpose(); }

  // Gauss-Legendre nodes and weights on [-1, 1]: the tabled 4-point rule (the model's), Newton on P_m otherwise.
  static void gauss_legendre(int m, std::vector<double>& x, std::vector<double>& w) {
    if (m == 4) {
      x = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526};
      w = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538};
      return;
    }
    x.assign(static_cast<std::size_t>(m), 0.0);
    w.assign(static_cast<std::size_t>(m), 0.0);
    for (int i = 0; i < m; ++i) {
      double z = std::cos(kPi * (i + 0.75) / (m + 0.5)), dp = 1;
      for (int it = 0; it < 100; ++it) {
        double p0 = 1, p1 = z;  // P_0, P_1, then up to P_m
        for (int k = 2; k <= m; ++k) {
          const double p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k;
          p0 = p1;
          p1 = p2;
        }
        dp = m * (z * p1 - p0) / (z * z - 1);
        const double step = p1 / dp;
        z -= step;
        if (std::abs(step) < 1e-15) break;
      }
      x[static_cast<std::size_t>(m - 1 - i)] = z;
      w[static_cast<std::size_t>(m - 1 - i)] = 2 / ((1 - z * z) * dp * dp);
    }
  }
  bool has_column(int n) const {
    return fixed_[static_cast<std::size_t>(n)] == 0 && on_surface_[static_cast<std::size_t>(n)] != 0;
  }
  bool neighbours(int i, int j) const {
    const auto& r = ring_[static_cast<std::size_t>(i)];
    return std::binary_search(r.begin(), r.end(), j);
  }

  // Faces of exactly one tet, turned away from that tet's fourth node; vertex normals and areas; rings.
  void boundary(const Eigen::MatrixX4i& tets) {
    std::map<std::array<int, 3>, std::pair<int, std::array<int, 4>>> faces;  // sorted face -> count, (face, opposite)
    static const int kFace[4][4] = {{1, 2, 3, 0}, {0, 2, 3, 1}, {0, 1, 3, 2}, {0, 1, 2, 3}};
    for (Eigen::Index t = 0; t < tets.rows(); ++t)
      for (const auto& f : kFace) {
        std::array<int, 4> v = {tets(t, f[0]), tets(t, f[1]), tets(t, f[2]), tets(t, f[3])};
        std::array<int, 3> key = {v[0], v[1], v[2]};
        std::sort(key.begin(), key.end());
        auto& e = faces[key];
        ++e.first;
        e.second = v;
      }
    const auto nv = static_cast<std::size_t>(x_.rows());
    vnormal_.assign(nv, Eigen::Vector3d::Zero());
    area_.assign(nv, 0.0);
    on_surface_.assign(nv, 0);
    ring_.assign(nv, {});
    node_tris_.assign(nv, {});
    for (const auto& [key, e] : faces) {
      if (e.first != 1) continue;
      std::array<int, 3> f = {e.second[0], e.second[1], e.second[2]};
      Eigen::Vector3d n2 = (node(f[1]) - node(f[0])).cross(node(f[2]) - node(f[0]));
      if (n2.dot(node(e.second[3]) - node(f[0])) > 0) {
        std::swap(f[1], f[2]);
        n2 = -n2;
      }
      const int index = static_cast<int>(tris_.size());
      tris_.push_back(f);
      fnormal_.push_back(n2.normalized());
      for (int v = 0; v < 3; ++v) {
        const auto sv = static_cast<std::size_t>(f[static_cast<std::size_t>(v)]);
        vnormal_[sv] += n2;
        area_[sv] += n2.norm() / 6;
        on_surface_[sv] = 1;
        node_tris_[sv].push_back(index);
        for (int w = 0; w < 3; ++w)
          if (w != v) ring_[sv].push_back(f[static_cast<std::size_t>(w)]);
      }
    }
    for (auto& n : vnormal_)
      if (n.norm() > 0) n.normalize();
    for (auto& r : ring_) {
      std::sort(r.begin(), r.end());
      r.erase(std::unique(r.begin(), r.end()), r.end());
    }
  }

  // K_ff of P1 linear elasticity: K_e = V B^T D B per tet (Voigt xx, yy, zz, xy, yz, xz, engineering shear).
  void assemble(const Eigen::MatrixX4i& tets) {
    const auto ndof = static_cast<std::size_t>(3 * x_.rows());
    free_index_.assign(ndof, -1);
    int free = 0;
    for (std::size_t d = 0; d < ndof; ++d)
      if (fixed_[d / 3] == 0) free_index_[d] = free++;
    const double e = young_, nu = poisson_;
    const double lambda = e * nu / ((1 + nu) * (1 - 2 * nu)), mu = e / (2 * (1 + nu));
    Eigen::Matrix<double, 6, 6> dm = Eigen::Matrix<double, 6, 6>::Zero();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) dm(i, j) = lambda;
      dm(i, i) = lambda + 2 * mu;
      dm(3 + i, 3 + i) = mu;
    }
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(static_cast<std::size_t>(tets.rows()) * 144);
    for (Eigen::Index t = 0; t < tets.rows(); ++t) {
      Eigen::Matrix3d j;
      for (int c = 0; c < 3; ++c) j.col(c) = node(tets(t, c + 1)) - node(tets(t, 0));
      const double volume = std::abs(j.determinant()) / 6;
      const Eigen::Matrix3d inv = j.inverse();  // row c: gradient of shape function c + 1
      std::array<Eigen::Vector3d, 4> g;
      for (int c = 0; c < 3; ++c) g[static_cast<std::size_t>(c + 1)] = inv.row(c).transpose();
      g[0] = -(g[1] + g[2] + g[3]);
      Eigen::Matrix<double, 6, 12> bm = Eigen::Matrix<double, 6, 12>::Zero();
      for (int v = 0; v < 4; ++v) {
        const Eigen::Vector3d& gv = g[static_cast<std::size_t>(v)];
        bm(0, 3 * v) = gv.x();
        bm(1, 3 * v + 1) = gv.y();
        bm(2, 3 * v + 2) = gv.z();
        bm(3, 3 * v) = gv.y();
        bm(3, 3 * v + 1) = gv.x();
        bm(4, 3 * v + 1) = gv.z();
        bm(4, 3 * v + 2) = gv.y();
        bm(5, 3 * v) = gv.z();
        bm(5, 3 * v + 2) = gv.x();
      }
      const Eigen::Matrix<double, 12, 12> ke = volume * bm.transpose() * dm * bm;
      for (int r = 0; r < 12; ++r) {
        const int fr = free_index_[static_cast<std::size_t>(3 * tets(t, r / 3) + r % 3)];
        if (fr < 0) continue;
        for (int c = 0; c < 12; ++c) {
          const int fc = free_index_[static_cast<std::size_t>(3 * tets(t, c / 3) + c % 3)];
          if (fc >= 0) trip.emplace_back(fr, fc, ke(r, c));
        }
      }
    }
    k_ff_.resize(free, free);
    k_ff_.setFromTriplets(trip.begin(), trip.end());
    k_ff_.makeCompressed();
    lu_ = std::make_unique<Eigen::SparseLU<Eigen::SparseMatrix<double>>>();
    lu_->analyzePattern(k_ff_);
    lu_->factorize(k_ff_);
    ok_ = lu_->info() == Eigen::Success;
  }

  // Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5), with its barycentrics.
  static Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                             const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                             Eigen::Vector3d& bary) {
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) {
      bary = Eigen::Vector3d(1, 0, 0);
      return a;
    }
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) {
      bary = Eigen::Vector3d(0, 1, 0);
      return b;
    }
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
      const double v = d1 / (d1 - d3);
      bary = Eigen::Vector3d(1 - v, v, 0);
      return a + v * ab;
    }
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) {
      bary = Eigen::Vector3d(0, 0, 1);
      return c;
    }
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
      const double w = d2 / (d2 - d6);
      bary = Eigen::Vector3d(1 - w, 0, w);
      return a + w * ac;
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
      const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
      bary = Eigen::Vector3d(0, 1 - w, w);
      return b + w * (c - b);
    }
    const double denom = 1 / (va + vb + vc), v = vb * denom, w = vc * denom;
    bary = Eigen::Vector3d(1 - v - w, v, w);
    return a + v * ab + w * ac;
  }

  // The surface triangle that q projects onto along n (faces within about 78 degrees of n; of several, the nearest
  // along n), with q's barycentrics in the plane (t1, t2).
  bool project(const Eigen::Vector3d& q, const Eigen::Vector3d& n, const Eigen::Vector3d& t1, const Eigen::Vector3d& t2,
               int& tri, Eigen::Vector3d& bary) const {
    double best = HUGE_VAL;
    for (std::size_t f = 0; f < tris_.size(); ++f) {
      if (!(fnormal_[f].dot(n) > 0.2)) continue;
      Eigen::Vector2d p[3];
      for (int v = 0; v < 3; ++v) {
        const Eigen::Vector3d d = node(tris_[f][static_cast<std::size_t>(v)]) - q;
        p[v] = Eigen::Vector2d(d.dot(t1), d.dot(t2));
      }
      const auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
        return a.x() * b.y() - a.y() * b.x();
      };
      const double area = cross(p[1] - p[0], p[2] - p[0]);
      if (!(area > 0)) continue;
      const Eigen::Vector3d bc(cross(p[1], p[2]) / area, cross(p[2], p[0]) / area, cross(p[0], p[1]) / area);
      if (bc.minCoeff() < -1e-12) continue;
      const double along = std::abs((node(tris_[f][0]) - q).dot(fnormal_[f]) / n.dot(fnormal_[f]));
      if (along < best) {
        best = along;
        tri = static_cast<int>(f);
        bary = bc;
      }
    }
    return tri >= 0;
  }

  // n_j . u_j under a unit force along n_i at node i, for every node j (zero at fixed nodes): one solve, cached.
  const Eigen::VectorXd& normal_response(int i) const {
    auto it = response_.find(i);
    if (it != response_.end()) return it->second;
    Eigen::VectorXd f = Eigen::VectorXd::Zero(k_ff_.rows());
    for (int k = 0; k < 3; ++k) f[free_index_[static_cast<std::size_t>(3 * i + k)]] = vertex_normal(i)[k];
    const Eigen::VectorXd u = lu_->solve(f);
    Eigen::VectorXd out = Eigen::VectorXd::Zero(x_.rows());
    for (Eigen::Index j = 0; j < x_.rows(); ++j)
      for (int k = 0; k < 3; ++k) {
        const int d = free_index_[static_cast<std::size_t>(3 * j + k)];
        if (d >= 0) out[j] += vertex_normal(static_cast<int>(j))[k] * u[d];
      }
    return response_.emplace(i, std::move(out)).first->second;
  }
  double g(int i, int j) const { return normal_response(i)[j]; }

  // A node's hat function normalized to unit integral as weighted sub-triangle centroids (and the radius of a disc
  // of each sub-triangle's area).
  struct Cloud {
    std::vector<Eigen::Vector3d> x;
    std::vector<double> w, r;
  };
  const Cloud& cloud(int node_index) const {
    auto it = clouds_.find(node_index);
    if (it != clouds_.end()) return it->second;
    Cloud out;
    double total = 0;
    const int n = kSplit;
    for (int f : node_tris_[static_cast<std::size_t>(node_index)]) {
      const auto& t = tris_[static_cast<std::size_t>(f)];
      int v = 0;
      while (t[static_cast<std::size_t>(v)] != node_index) ++v;
      const Eigen::Vector3d p0 = node(t[0]), p1 = node(t[1]), p2 = node(t[2]);
      const double a = 0.5 * (p1 - p0).cross(p2 - p0).norm();
      total += a / 3;
      const double sub = a / (n * n), radius = std::sqrt(sub / kPi);
      const auto add = [&](double b1, double b2) {
        const Eigen::Vector3d b(1 - b1 - b2, b1, b2);
        out.x.push_back(b[0] * p0 + b[1] * p1 + b[2] * p2);
        out.w.push_back(b[v] * sub);
        out.r.push_back(radius);
      };
      for (int i = 0; i < n; ++i)
        for (int j = 0; i + j < n; ++j) {
          add((i + 1.0 / 3) / n, (j + 1.0 / 3) / n);
          if (i + j < n - 1) add((i + 2.0 / 3) / n, (j + 2.0 / 3) / n);
        }
    }
    for (double& w : out.w) w /= total;
    return clouds_.emplace(node_index, std::move(out)).first->second;
  }
  // I_ij = int int phi_i phi_j / |x - y| of the two normalized hats: a disc's mean 1/|x - y| for one sub-triangle,
  // 1/d + (r_a^2 + r_b^2) / (8 d^3) (two discs to second order) between two.
  double interaction(int i, int j) const {
    const auto key = std::make_pair(std::min(i, j), std::max(i, j));
    auto it = interactions_.find(key);
    if (it != interactions_.end()) return it->second;
    const Cloud &a = cloud(key.first), &b = cloud(key.second);
    double s = 0;
    for (std::size_t p = 0; p < a.x.size(); ++p)
      for (std::size_t q = 0; q < b.x.size(); ++q) {
        const double d = (a.x[p] - b.x[q]).norm();
        s += a.w[p] * b.w[q] *
             (d < 1e-9 * a.r[p] ? 16.0 / (3 * kPi * a.r[p])
                                : 1.0 / d + (a.r[p] * a.r[p] + b.r[q] * b.r[q]) / (8 * d * d * d));
      }
    interactions_.emplace(key, s);
    return s;
  }
  // The smooth part of the mesh's normal compliance at node i: the area-weighted mean of G_ij - k I_ij over i and its
  // ring (nodes with a column); NaN when i has none.
  double smooth(int i) const {
    if (!has_column(i)) return std::nan("");
    const double k = kernel();
    double num = area_[static_cast<std::size_t>(i)] * (g(i, i) - k * interaction(i, i)),
           den = area_[static_cast<std::size_t>(i)];
    for (int j : ring_[static_cast<std::size_t>(i)]) {
      if (!has_column(j)) continue;
      num += area_[static_cast<std::size_t>(j)] * (g(i, j) - k * interaction(i, j));
      den += area_[static_cast<std::size_t>(j)];
    }
    return den > 0 ? num / den : std::nan("");
  }
  // The mesh's own local compliance less its smooth part for a node and itself or its ring (the hat picture k I_ij
  // where a node has no column); the half-space kernel k / r beyond.
  double local(int i, int j) const {
    const double k = kernel();
    if (i != j && !neighbours(i, j)) return k / (node(i) - node(j)).norm();
    const double si = smooth(i), sj = smooth(j);
    if (std::isnan(si) || std::isnan(sj)) return k * interaction(i, j);
    return g(i, j) - 0.5 * (si + sj);
  }

  Eigen::MatrixX3d x_;
  double young_, poisson_;
  std::vector<std::uint8_t> fixed_, on_surface_;
  std::vector<std::array<int, 3>> tris_;
  std::vector<Eigen::Vector3d> fnormal_, vnormal_;
  std::vector<double> area_;
  std::vector<std::vector<int>> ring_, node_tris_;
  std::vector<int> free_index_;
  Eigen::SparseMatrix<double> k_ff_;
  std::unique_ptr<Eigen::SparseLU<Eigen::SparseMatrix<double>>> lu_;
  bool ok_ = false;
  mutable std::map<int, Eigen::VectorXd> response_;
  mutable std::map<int, Cloud> clouds_;
  mutable std::map<std::pair<int, int>, double> interactions_;
};

}  // namespace surgsim::test
