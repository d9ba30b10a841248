#include "imaging/surface_decimation.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <array>
#include <iterator>
#include <map>
#include <queue>
#include <set>
#include <tuple>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::imaging {
namespace {

constexpr double kPi = 3.14159265358979323846;

double triangle_quality(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double l2 = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
  return l2 > 0.0 ? 2.0 * std::sqrt(3.0) * (b - a).cross(c - a).norm() / l2 : 0.0;
}

// A candidate collapse of edge (a, b) into point `at`.
struct Candidate {
  double cost;
  Eigen::Vector3d at;
};

// Queue entry; ties broken by the vertex pair so that the order (and the result) is deterministic.
struct Entry {
  double cost;
  int a, b;
  int version_a, version_b;
  bool operator>(const Entry& o) const { return std::tie(cost, a, b) > std::tie(o.cost, o.a, o.b); }
};

class Decimator {
 public:
  Decimator(TriSurface& mesh, const VoxelBoundaryDistance* boundary, const DecimationOptions& options)
      : mesh_(mesh), boundary_(boundary), options_(options) {
    const int nv = static_cast<int>(mesh.vertices.rows());
    const int nf = static_cast<int>(mesh.tris.rows());
    pos_.resize(static_cast<std::size_t>(nv));
    for (int v = 0; v < nv; ++v) pos_[static_cast<std::size_t>(v)] = mesh.vertices.row(v).transpose();
    faces_.resize(static_cast<std::size_t>(nf));
    face_alive_.assign(static_cast<std::size_t>(nf), 1);
    vertex_faces_.resize(static_cast<std::size_t>(nv));
    quadric_.assign(static_cast<std::size_t>(nv), Eigen::Matrix4d::Zero());
    weight_.assign(static_cast<std::size_t>(nv), 0.0);
    alive_.assign(static_cast<std::size_t>(nv), 0);
    version_.assign(static_cast<std::size_t>(nv), 0);
    for (int f = 0; f < nf; ++f) {
      faces_[static_cast<std::size_t>(f)] = mesh.tris.row(f).transpose();
      const auto& t = faces_[static_cast<std::size_t>(f)];
      const Eigen::Vector3d a = pos_[t[0]], b = pos_[t[1]], c = pos_[t[2]];
      Eigen::Vector3d n = (b - a).cross(c - a);
      const double area = 0.5 * n.norm();
      if (area > 0.0) n.normalize();
      Eigen::Vector4d plane;
      plane << n, -n.dot(a);
      const Eigen::Matrix4d q = area * plane * plane.transpose();
      for (int k = 0; k < 3; ++k) {
        const auto v = static_cast<std::size_t>(t[k]);
        vertex_faces_[v].push_back(f);
        quadric_[v] += q;
        weight_[v] += area;
        alive_[v] = 1;
      }
    }
    live_vertices_ = static_cast<int>(std::count(alive_.begin(), alive_.end(), 1));
    init_curvature();
    cos_turn_ = std::cos(options.max_normal_turn_deg * kPi / 180.0);
  }

  DecimationReport run() {
    for (std::size_t f = 0; f < faces_.size(); ++f)
      for (int k = 0; k < 3; ++k) push(faces_[f][k], faces_[f][(k + 1) % 3]);
    while (!heap_.empty()) {
      if (options_.target_vertices > 0 && live_vertices_ <= options_.target_vertices) break;
      if (live_vertices_ <= 4) break;
      const Entry e = heap_.top();
      heap_.pop();
      const auto a = static_cast<std::size_t>(e.a), b = static_cast<std::size_t>(e.b);
      if (!alive_[a] || !alive_[b] || version_[a] != e.version_a || version_[b] != e.version_b) continue;
      std::vector<Candidate> candidates = evaluate(e.a, e.b);
      // A neighbour moved since the entry was queued and the collapse got dearer: queue it again at its cost.
      if (candidates.front().cost > e.cost * (1.0 + 1e-9) + 1e-30) {
        heap_.push({candidates.front().cost, e.a, e.b, e.version_a, e.version_b});
        continue;
      }
      if (options_.max_error > 0.0 && std::sqrt(candidates.front().cost) > options_.max_error) break;
      for (const Candidate& c : candidates) {
        if (options_.max_error > 0.0 && std::sqrt(c.cost) > options_.max_error) break;
        if (!allowed(e.a, e.b, c.at)) continue;
        collapse(e.a, e.b, c.at);
        report_.last_error = std::sqrt(c.cost);
        break;
      }
    }
    return finish();
  }

 private:
  // Largest principal curvature per vertex, estimated from the circles through a vertex and each neighbour that
  // are tangent to the vertex normal's plane (1/m), then averaged once with the neighbours to calm the noise.
  void init_curvature() {
    const std::size_t nv = pos_.size();
    std::vector<Eigen::Vector3d> normal(nv, Eigen::Vector3d::Zero());
    for (const auto& t : faces_) {
      const Eigen::Vector3d n = (pos_[t[1]] - pos_[t[0]]).cross(pos_[t[2]] - pos_[t[0]]);
      for (int k = 0; k < 3; ++k) normal[static_cast<std::size_t>(t[k])] += n;
    }
    std::vector<double> raw(nv, 0.0);
    for (std::size_t v = 0; v < nv; ++v) {
      if (!alive_[v]) continue;
      const double len = normal[v].norm();
      if (len > 0.0) normal[v] /= len;
      ring(static_cast<int>(v), ring_a_);
      for (int w : ring_a_) {
        const Eigen::Vector3d d = pos_[static_cast<std::size_t>(w)] - pos_[v];
        const double d2 = d.squaredNorm();
        if (d2 > 0.0) raw[v] = std::max(raw[v], 2.0 * std::fabs(normal[v].dot(d)) / d2);
      }
    }
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
    for (std::size_t v = 0; v < nv; ++v) {
      if (!alive_[v]) continue;
      lo = lo.cwiseMin(pos_[v]);
      hi = hi.cwiseMax(pos_[v]);
    }
    const double floor = options_.min_curvature > 0.0 ? options_.min_curvature : 4.0 / std::max((hi - lo).norm(), 1e-12);
    curvature_.assign(nv, floor);
    for (std::size_t v = 0; v < nv; ++v) {
      if (!alive_[v]) continue;
      ring(static_cast<int>(v), ring_a_);
      double mean = 0.0;
      for (int w : ring_a_) mean += raw[static_cast<std::size_t>(w)];
      if (!ring_a_.empty()) mean /= static_cast<double>(ring_a_.size());
      curvature_[v] = std::max(floor, 0.5 * (raw[v] + mean));
    }
  }

  // Sorted unique neighbours of v.
  void ring(int v, std::vector<int>& out) const {
    out.clear();
    for (int f : vertex_faces_[static_cast<std::size_t>(v)]) {
      for (int k = 0; k < 3; ++k) {
        const int w = faces_[static_cast<std::size_t>(f)][k];
        if (w != v) out.push_back(w);
      }
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

  void push(int a, int b) {
    if (a == b) return;
    if (a > b) std::swap(a, b);
    const std::vector<Candidate> c = evaluate(a, b);
    heap_.push({c.front().cost, a, b, version_[static_cast<std::size_t>(a)], version_[static_cast<std::size_t>(b)]});
  }

  // Candidate points (quadric optimum when well conditioned, midpoint, either end), cheapest first.
  std::vector<Candidate> evaluate(int a, int b) {
    const auto ia = static_cast<std::size_t>(a), ib = static_cast<std::size_t>(b);
    const Eigen::Matrix4d q = quadric_[ia] + quadric_[ib];
    const double w = std::max(weight_[ia] + weight_[ib], 1e-300);
    const double kappa = std::max(curvature_[ia], curvature_[ib]);
    ring(a, ring_a_);
    ring(b, ring_b_);
    std::vector<Eigen::Vector3d> points = {0.5 * (pos_[ia] + pos_[ib]), pos_[ia], pos_[ib]};
    const Eigen::Matrix3d m = q.topLeftCorner<3, 3>();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(m);
    const Eigen::Vector3d ev = eig.eigenvalues();
    if (ev.maxCoeff() > 0.0 && ev.minCoeff() > 1e-6 * ev.maxCoeff()) {
      const Eigen::Vector3d opt = m.ldlt().solve(-q.topRightCorner<3, 1>());
      // Only near the edge: a far optimum of a nearly flat patch is numerically meaningless.
      const double len = (pos_[ia] - pos_[ib]).norm();
      if (opt.allFinite() && (opt - points[0]).norm() <= len) points.insert(points.begin(), opt);
    }
    std::vector<Candidate> out;
    out.reserve(points.size());
    for (const Eigen::Vector3d& p : points) {
      Eigen::Vector4d h;
      h << p, 1.0;
      const double e_q = std::max(0.0, h.dot(q * h)) / w;
      double longest2 = 0.0;
      for (const auto* r : {&ring_a_, &ring_b_})
        for (int x : *r)
          if (x != a && x != b) longest2 = std::max(longest2, (pos_[static_cast<std::size_t>(x)] - p).squaredNorm());
      const double sag = longest2 * kappa / 8.0;
      out.push_back({e_q + sag * sag, p});
    }
    std::stable_sort(out.begin(), out.end(), [](const Candidate& x, const Candidate& y) { return x.cost < y.cost; });
    return out;
  }

  // The checks of the header: link condition, normal turn, quality, distance.
  bool allowed(int a, int b, const Eigen::Vector3d& at) {
    ring(a, ring_a_);
    ring(b, ring_b_);
    common_.clear();
    std::set_intersection(ring_a_.begin(), ring_a_.end(), ring_b_.begin(), ring_b_.end(), std::back_inserter(common_));
    if (common_.size() != 2) {
      ++report_.refused_topology;
      return false;
    }
    // Shape: every triangle that keeps its place (has a or b, not both) with the end moved to `at`.
    double worst_before = 1.0;
    for (int end : {a, b}) {
      for (int f : vertex_faces_[static_cast<std::size_t>(end)]) {
        const auto& t = faces_[static_cast<std::size_t>(f)];
        worst_before = std::min(worst_before, triangle_quality(pos_[t[0]], pos_[t[1]], pos_[t[2]]));
      }
    }
    const double min_quality = std::min(options_.min_quality, worst_before);
    const double d = options_.max_distance;
    const bool check_distance = boundary_ != nullptr && d > 0.0;
    if (check_distance && !boundary_->within(at, d)) {
      ++report_.refused_distance;
      return false;
    }
    for (int end : {a, b}) {
      const int other = end == a ? b : a;
      for (int f : vertex_faces_[static_cast<std::size_t>(end)]) {
        const auto& t = faces_[static_cast<std::size_t>(f)];
        if (t[0] == other || t[1] == other || t[2] == other) continue;  // removed by the collapse
        std::array<Eigen::Vector3d, 3> p;
        for (int k = 0; k < 3; ++k) p[static_cast<std::size_t>(k)] = t[k] == end ? at : pos_[static_cast<std::size_t>(t[k])];
        const Eigen::Vector3d n_old = (pos_[t[1]] - pos_[t[0]]).cross(pos_[t[2]] - pos_[t[0]]);
        const Eigen::Vector3d n_new = (p[1] - p[0]).cross(p[2] - p[0]);
        if (n_new.dot(n_old) <= cos_turn_ * n_new.norm() * n_old.norm() || triangle_quality(p[0], p[1], p[2]) < min_quality) {
          ++report_.refused_shape;
          return false;
        }
        if (check_distance) {
          const Eigen::Vector3d centroid = (p[0] + p[1] + p[2]) / 3.0;
          bool ok = boundary_->within(centroid, d);
          for (int k = 0; ok && k < 3; ++k) {
            if (t[k] != end) ok = boundary_->within(0.5 * (at + p[static_cast<std::size_t>(k)]), d);
          }
          if (!ok) {
            ++report_.refused_distance;
            return false;
          }
        }
      }
    }
    return true;
  }

  // Merges b into a at `at`.
  void collapse(int a, int b, const Eigen::Vector3d& at) {
    const auto ia = static_cast<std::size_t>(a), ib = static_cast<std::size_t>(b);
    for (int f : vertex_faces_[ib]) {
      auto& t = faces_[static_cast<std::size_t>(f)];
      if (t[0] == a || t[1] == a || t[2] == a) {
        face_alive_[static_cast<std::size_t>(f)] = 0;
        for (int k = 0; k < 3; ++k) {
          if (t[k] == b) continue;
          auto& list = vertex_faces_[static_cast<std::size_t>(t[k])];
          list.erase(std::find(list.begin(), list.end(), f));
        }
        continue;
      }
      for (int k = 0; k < 3; ++k)
        if (t[k] == b) t[k] = a;
      vertex_faces_[ia].push_back(f);
    }
    vertex_faces_[ib].clear();
    pos_[ia] = at;
    quadric_[ia] += quadric_[ib];
    weight_[ia] += weight_[ib];
    curvature_[ia] = std::max(curvature_[ia], curvature_[ib]);
    alive_[ib] = 0;
    ++version_[ia];
    ++version_[ib];
    --live_vertices_;
    ++report_.collapses;
    ring(a, ring_scratch_);
    const std::vector<int> neighbours = ring_scratch_;
    for (int x : neighbours) push(a, x);
  }

  DecimationReport finish() {
    TriSurface out;
    out.vertices.resize(static_cast<Eigen::Index>(pos_.size()), 3);
    for (std::size_t v = 0; v < pos_.size(); ++v) out.vertices.row(static_cast<Eigen::Index>(v)) = pos_[v].transpose();
    const auto live_faces = std::count(face_alive_.begin(), face_alive_.end(), 1);
    out.tris.resize(static_cast<Eigen::Index>(live_faces), 3);
    Eigen::Index n = 0;
    for (std::size_t f = 0; f < faces_.size(); ++f)
      if (face_alive_[f]) out.tris.row(n++) = faces_[f].transpose();
    compact_tri_surface(out);
    mesh_ = std::move(out);
    report_.vertices = static_cast<int>(mesh_.vertices.rows());
    report_.triangles = static_cast<int>(mesh_.tris.rows());
    return report_;
  }

  TriSurface& mesh_;
  const VoxelBoundaryDistance* boundary_;
  DecimationOptions options_;
  double cos_turn_ = 0.0;
  std::vector<Eigen::Vector3d> pos_;
  std::vector<Eigen::Vector3i> faces_;
  std::vector<char> face_alive_;
  std::vector<std::vector<int>> vertex_faces_;
  std::vector<Eigen::Matrix4d> quadric_;
  std::vector<double> weight_;
  std::vector<double> curvature_;
  std::vector<char> alive_;
  std::vector<int> version_;
  int live_vertices_ = 0;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> heap_;
  std::vector<int> ring_a_, ring_b_, common_, ring_scratch_;
  DecimationReport report_;
};

// Flips and relaxation on a closed manifold surface (see the header).
class Improver {
 public:
  Improver(TriSurface& mesh, const VoxelBoundaryDistance* boundary, const ImprovementOptions& options)
      : mesh_(mesh), boundary_(boundary), options_(options) {
    cos_flip_ = std::cos(options.max_flip_angle_deg * kPi / 180.0);
    cos_turn_ = std::cos(options.max_normal_turn_deg * kPi / 180.0);
  }

  ImprovementReport run() {
    ImprovementReport report;
    report.min_quality_before = tri_surface_min_quality(mesh_);
    for (int round = 0; round < options_.rounds; ++round) {
      const int flips = flip_pass();
      const int moves = relax_pass();
      report.flips += flips;
      report.moves += moves;
      if (flips == 0 && moves == 0) break;
    }
    report.min_quality_after = tri_surface_min_quality(mesh_);
    return report;
  }

 private:
  Eigen::Vector3d p(int v) const { return mesh_.vertices.row(v).transpose(); }
  Eigen::Vector3d normal(int a, int b, int c) const { return (p(b) - p(a)).cross(p(c) - p(a)); }
  double quality(int a, int b, int c) const { return triangle_quality(p(a), p(b), p(c)); }
  bool within(const Eigen::Vector3d& x) const {
    return boundary_ == nullptr || options_.max_distance <= 0.0 || boundary_->within(x, options_.max_distance);
  }
  bool turned(const Eigen::Vector3d& n_old, const Eigen::Vector3d& n_new) const {
    return n_new.dot(n_old) <= cos_turn_ * n_new.norm() * n_old.norm();
  }

  // One sweep over the edges in a fixed order; returns the number of flips.
  int flip_pass() {
    const int nf = static_cast<int>(mesh_.tris.rows());
    // Half-edge (a, b) -> face; the twin of (a, b) is (b, a).
    std::map<std::pair<int, int>, int> face_of;
    for (int f = 0; f < nf; ++f)
      for (int k = 0; k < 3; ++k) face_of[{mesh_.tris(f, k), mesh_.tris(f, (k + 1) % 3)}] = f;
    std::set<std::pair<int, int>> edges;
    for (const auto& [e, f] : face_of) edges.insert(std::minmax(e.first, e.second));
    int flips = 0;
    for (const auto& [a, b] : edges) {
      const auto f1_it = face_of.find({a, b}), f2_it = face_of.find({b, a});
      if (f1_it == face_of.end() || f2_it == face_of.end()) continue;
      const int f1 = f1_it->second, f2 = f2_it->second;
      const int c = third(f1, a, b), d = third(f2, b, a);
      if (c < 0 || d < 0 || c == d || face_of.count({c, d}) != 0 || face_of.count({d, c}) != 0) continue;
      // Faces (a, b, c), (b, a, d) -> (a, d, c), (d, b, c).
      const Eigen::Vector3d n1 = normal(a, b, c), n2 = normal(b, a, d);
      if (n1.dot(n2) <= cos_flip_ * n1.norm() * n2.norm()) continue;
      const double before = std::min(quality(a, b, c), quality(b, a, d));
      const double after = std::min(quality(a, d, c), quality(d, b, c));
      if (after <= before + 1e-3) continue;
      const Eigen::Vector3d m1 = normal(a, d, c), m2 = normal(d, b, c);
      const Eigen::Vector3d n = n1 + n2;
      if (turned(n, m1) || turned(n, m2) || !within(0.5 * (p(c) + p(d)))) continue;
      mesh_.tris.row(f1) << a, d, c;
      mesh_.tris.row(f2) << d, b, c;
      face_of.erase({a, b});
      face_of.erase({b, a});
      face_of[{a, d}] = f1;
      face_of[{d, c}] = f1;
      face_of[{c, a}] = f1;
      face_of[{d, b}] = f2;
      face_of[{b, c}] = f2;
      face_of[{c, d}] = f2;
      ++flips;
    }
    return flips;
  }

  int third(int f, int a, int b) const {
    for (int k = 0; k < 3; ++k)
      if (mesh_.tris(f, k) == a && mesh_.tris(f, (k + 1) % 3) == b) return mesh_.tris(f, (k + 2) % 3);
    return -1;
  }

  // One Gauss-Seidel sweep of tangential relaxation; returns the number of vertices moved.
  int relax_pass() {
    const int nv = static_cast<int>(mesh_.vertices.rows());
    std::vector<std::vector<int>> faces(static_cast<std::size_t>(nv));
    for (int f = 0; f < mesh_.tris.rows(); ++f)
      for (int k = 0; k < 3; ++k) faces[static_cast<std::size_t>(mesh_.tris(f, k))].push_back(f);
    int moves = 0;
    for (int v = 0; v < nv; ++v) {
      const auto& around = faces[static_cast<std::size_t>(v)];
      if (around.empty()) continue;
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
      double area = 0.0, worst = 1.0;
      for (int f : around) {
        const Eigen::Vector3d nf = normal(mesh_.tris(f, 0), mesh_.tris(f, 1), mesh_.tris(f, 2));
        const double a = 0.5 * nf.norm();
        centroid += a * (p(mesh_.tris(f, 0)) + p(mesh_.tris(f, 1)) + p(mesh_.tris(f, 2))) / 3.0;
        area += a;
        n += nf;
        worst = std::min(worst, quality(mesh_.tris(f, 0), mesh_.tris(f, 1), mesh_.tris(f, 2)));
      }
      if (!(area > 0.0) || !(n.norm() > 0.0)) continue;
      centroid /= area;
      n.normalize();
      Eigen::Vector3d step = 0.5 * (centroid - p(v));
      step -= step.dot(n) * n;
      const Eigen::Vector3d to = p(v) + step;
      if (!within(to)) continue;
      // Accept when the worst triangle around v gets better and none turns or leaves the bound.
      const Eigen::Vector3d from = p(v);
      mesh_.vertices.row(v) = to.transpose();
      bool ok = true;
      double worst_after = 1.0;
      for (int f : around) {
        const int a = mesh_.tris(f, 0), b = mesh_.tris(f, 1), c = mesh_.tris(f, 2);
        worst_after = std::min(worst_after, quality(a, b, c));
        Eigen::Vector3d old_corner[3] = {p(a), p(b), p(c)};
        for (auto& x : old_corner)
          if (x == to) x = from;
        const Eigen::Vector3d n_old = (old_corner[1] - old_corner[0]).cross(old_corner[2] - old_corner[0]);
        if (turned(n_old, normal(a, b, c)) || !within((p(a) + p(b) + p(c)) / 3.0)) {
          ok = false;
          break;
        }
      }
      if (!ok || worst_after <= worst + 1e-4) {
        mesh_.vertices.row(v) = from.transpose();
        continue;
      }
      ++moves;
    }
    return moves;
  }

  TriSurface& mesh_;
  const VoxelBoundaryDistance* boundary_;
  ImprovementOptions options_;
  double cos_flip_ = 0.0, cos_turn_ = 0.0;
};

}  // namespace

ImprovementReport improve_surface(TriSurface& mesh, const VoxelBoundaryDistance* boundary,
                                  const ImprovementOptions& options) {
  if (options.rounds < 0) throw_error("surface improvement: rounds must be >= 0");
  if (options.max_distance > 0.0 && boundary == nullptr)
    throw_error("surface improvement: a distance bound needs the voxel boundary");
  Improver improver(mesh, boundary, options);
  return improver.run();
}

DecimationReport decimate_surface(TriSurface& mesh, const VoxelBoundaryDistance* boundary,
                                  const DecimationOptions& options) {
  if (options.target_vertices < 0) throw_error("surface reduction: the vertex target must be >= 0");
  if (options.max_error < 0.0) throw_error("surface reduction: the error bound must be >= 0");
  if (options.max_distance < 0.0) throw_error("surface reduction: the distance bound must be >= 0");
  if (options.max_distance > 0.0 && boundary == nullptr)
    throw_error("surface reduction: a distance bound needs the voxel boundary");
  if (!(options.min_quality >= 0.0 && options.min_quality < 1.0))
    throw_error("surface reduction: the minimum triangle quality must be in [0, 1)");
  if (!(options.max_normal_turn_deg > 0.0 && options.max_normal_turn_deg < 180.0))
    throw_error("surface reduction: the normal turn limit must be in (0, 180) degrees");
  if (mesh.tris.rows() == 0) throw_error("surface reduction: the surface has no triangles");
  Decimator decimator(mesh, boundary, options);
  return decimator.run();
}

}  // namespace surgsim::imaging
