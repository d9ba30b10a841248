#include "mesher/organ_mesher.h"

#include <gmsh.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <mutex>
#include <ostream>
#include <sstream>
#include <system_error>
#include <utility>

#include "core/error.h"
#include "core/hash.h"
#include "mesh/tri_surface.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

namespace surgsim::mesher {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Plate: 0.20 x 0.20 x 0.01 box centred at the origin (m).
constexpr double kPlateSide = 0.20;
constexpr double kPlateThickness = 0.01;
// Cylinder: radius, height (m); axis z, base at z = 0.
constexpr double kCylinderRadius = 0.025;
constexpr double kCylinderHeight = 0.10;

// Node-count control: accept an attempt within this relative error, else re-mesh (at most kMaxCountAttempts
// meshings for the count). An attempt whose worst tet is below kMinQuality is discarded and re-meshed at a 1 %
// different size (at most kMaxQualityRetries times).
constexpr double kAcceptRelError = 0.08;
constexpr int kMaxCountAttempts = 3;
constexpr double kMinQuality = 0.05;
constexpr int kMaxQualityRetries = 2;

// Node-count model n(h) = kNodesPerVolume * V / h^3 + kNodesPerArea * A / h^2 for characteristic length h,
// fitted on Gmsh 4.8 (Frontal-Delaunay 2D, Delaunay 3D, optimized) for the three shapes at 500..20000 nodes. It
// only makes the first guess; each attempt then rescales it by the measured ratio.
constexpr double kNodesPerVolume = 0.55;
constexpr double kNodesPerArea = 1.25;

// ---------------------------------------------------------------------------------------------------------------
// Liver: an implicit smooth solid {p : field(p) > 0}, a sum of anisotropic Gaussian blobs (one negative, carving
// the notch) divided by a logistic step in z that flattens the underside. The parameters were tuned (and the solid
// checked star-shaped from kLiverCentre: one crossing along each of 80 000 rays) so that the lobes, notch and flat
// underside fall where scenes expect them; organ_mesher.h gives the resulting extents. liver_surface() checks
// star-shapedness along every ray it casts.

struct Blob {
  std::array<double, 3> centre;  // m
  std::array<double, 3> radius;  // m, semi-axes of the 1/e ellipsoid
  double weight;                 // dimensionless; negative carves
};

constexpr std::array<Blob, 5> kLiverBlobs = {{
    {{0.045, -0.006, -0.008}, {0.082, 0.080, 0.050}, 1.0},  // right lobe, large and thick
    {{0.055, 0.025, -0.010}, {0.060, 0.050, 0.042}, 0.6},   // right lobe, posterior bulk
    {{-0.045, 0.004, 0.000}, {0.060, 0.060, 0.030}, 0.9},   // left lobe, thinner
    {{-0.095, 0.012, 0.000}, {0.040, 0.035, 0.016}, 0.8},   // left lobe tip, tapering to -x
    {{0.000, -0.094, 0.000}, {0.020, 0.040, 0.080}, -1.5},  // notch on the front edge between the lobes
}};
constexpr double kLiverIso = 0.45;          // level of the surface
constexpr double kLiverFloorZ = -0.035;     // m, the underside flattens at this height
constexpr double kLiverFloorWidth = 0.003;  // m, width of the logistic step (rounds the underside's rim)
constexpr std::array<double, 3> kLiverCentre = {0.01, 0.0, 0.0};      // m, rays are cast from here
constexpr std::array<double, 3> kLiverRayScale = {0.13, 0.08, 0.04};  // m, spreads the rays evenly on the solid
// Cube-sphere resolution (cells per cube face edge, even): about one sample per h along the liver's length, within
// these bounds (the finest costs about 3 s of Gmsh reparametrization).
constexpr int kLiverMinCells = 32;
constexpr int kLiverMaxCells = 96;

double liver_field(double x, double y, double z) {
  double f = 0.0;
  for (const Blob& b : kLiverBlobs) {
    const double u = (x - b.centre[0]) / b.radius[0];
    const double v = (y - b.centre[1]) / b.radius[1];
    const double w = (z - b.centre[2]) / b.radius[2];
    f += b.weight * std::exp(-(u * u + v * v + w * w));
  }
  f /= 1.0 + std::exp(-(z - kLiverFloorZ) / kLiverFloorWidth);
  return f - kLiverIso;
}

// The liver's closed triangle surface, handed to Gmsh as discrete entities split into an upper and a lower disk
// along a closed loop of edges.
struct SplitSurface {
  TriSurface surface;     // counter-clockwise seen from outside
  std::vector<int> side;  // #V: +1 upper disk, -1 lower disk, 0 on the loop between them
  std::vector<int> loop;  // the loop's vertices in order (closed: the last connects back to the first)
};

// The liver's boundary sampled on a cube-sphere: each face of a cube is an n x n grid (equal-angle, so cells are
// even on the sphere); a vertex's direction, stretched by kLiverRayScale, gives a ray from kLiverCentre cut where
// the field crosses zero. The grid row at cube height 0 is the loop splitting the surface into two disks (upper
// and lower), each nearly a graph over the xy-plane, which Gmsh reparametrizes robustly. (Letting Gmsh split the
// closed surface itself, classifySurfaces(forReparametrization), gave patches on which Frontal-Delaunay failed at
// some sizes and fell back to MeshAdapt, taking a minute.)
SplitSurface liver_surface(int n) {
  SplitSurface s;
  std::vector<double> xyz;  // #V x 3 row-major, m
  std::vector<int> tris;    // #F x 3
  std::map<std::array<int, 3>, int> index;  // integer cube coordinates in [-n/2, n/2]^3 -> vertex
  const int half = n / 2;
  auto vertex = [&](int i, int j, int k) {
    const std::array<int, 3> key = {i, j, k};
    const auto it = index.find(key);
    if (it != index.end()) return it->second;
    const int id = static_cast<int>(s.side.size());
    index.emplace(key, id);
    // Equal-angle cube-sphere direction, then stretched to the liver's proportions.
    std::array<double, 3> d;
    double norm = 0.0;
    for (int c = 0; c < 3; ++c) {
      d[c] = std::tan(kPi / 4 * key[c] / half) * kLiverRayScale[c];
      norm += d[c] * d[c];
    }
    norm = std::sqrt(norm);
    for (double& c : d) c /= norm;
    auto f = [&d](double r) {
      return liver_field(kLiverCentre[0] + r * d[0], kLiverCentre[1] + r * d[1], kLiverCentre[2] + r * d[2]);
    };
    // Bracket the crossing by marching out, then bisect.
    constexpr double kStep = 0.001;    // m
    constexpr double kMaxReach = 0.3;  // m, no part of the liver is farther from the centre
    double lo = 0.0, hi = kStep;
    while (f(hi) > 0.0) {
      lo = hi;
      hi += kStep;
      if (hi > kMaxReach) throw_error("liver surface: a ray does not leave the solid (internal error)");
    }
    for (int it = 0; it < 60; ++it) {
      const double m = 0.5 * (lo + hi);
      (f(m) > 0.0 ? lo : hi) = m;
    }
    const double r = 0.5 * (lo + hi);
    // Guard for edits of the blobs: the ray must not re-enter the solid (else it is not star-shaped from the
    // centre and the sampled surface would jump between layers).
    for (double t = hi + kStep; t <= kMaxReach; t += 4 * kStep) {
      if (f(t) > 0.0) throw_error("liver surface: not star-shaped from its centre (internal error)");
    }
    for (int c = 0; c < 3; ++c) xyz.push_back(kLiverCentre[c] + r * d[c]);
    s.side.push_back(k > 0 ? 1 : (k < 0 ? -1 : 0));
    return id;
  };
  // Six faces: normal axis `ax`, sign `sg`; (u, v) along the next two axes, cells split along one diagonal.
  for (int ax = 0; ax < 3; ++ax) {
    for (int sg = -1; sg <= 1; sg += 2) {
      for (int u = -half; u < half; ++u) {
        for (int v = -half; v < half; ++v) {
          auto at = [&](int uu, int vv) {
            std::array<int, 3> p;
            p[ax] = sg * half;
            p[(ax + 1) % 3] = uu;
            p[(ax + 2) % 3] = vv;
            return vertex(p[0], p[1], p[2]);
          };
          const int a = at(u, v), b = at(u + 1, v), c = at(u + 1, v + 1), d = at(u, v + 1);
          if (sg > 0) {
            tris.insert(tris.end(), {a, b, c, a, c, d});
          } else {
            tris.insert(tris.end(), {a, c, b, a, d, c});
          }
        }
      }
    }
  }
  // The loop: the ring at cube height 0, walked counter-clockwise seen from above, starting on the +x face.
  for (int j = 0; j < half; ++j) s.loop.push_back(vertex(half, j, 0));
  for (int i = half; i > -half; --i) s.loop.push_back(vertex(i, half, 0));
  for (int j = half; j > -half; --j) s.loop.push_back(vertex(-half, j, 0));
  for (int i = -half; i < half; ++i) s.loop.push_back(vertex(i, -half, 0));
  for (int j = -half; j < 0; ++j) s.loop.push_back(vertex(half, j, 0));
  s.surface.vertices = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(
      xyz.data(), static_cast<Eigen::Index>(xyz.size() / 3), 3);
  s.surface.tris = Eigen::Map<const Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>>(
      tris.data(), static_cast<Eigen::Index>(tris.size() / 3), 3);
  s.surface.source = "generated liver surface";
  return s;
}

// Cube-sphere resolution for characteristic length h (m).
int liver_cells(double h) {
  // A face spans a quarter turn over the liver's half-length; aim for one cell per h along it.
  const int cells = static_cast<int>(std::ceil(kLiverRayScale[0] * kPi / h));
  return std::clamp(cells + cells % 2, kLiverMinCells, kLiverMaxCells);
}

// Volume (divergence theorem) and area of a closed outward triangle surface.
// (Not tri_surface_volume and tri_surface_area: their arithmetic differs in the last bits, and these numbers choose the
// mesh size, hence the generated meshes.)
std::pair<double, double> volume_and_area(const TriSurface& s) {
  double volume = 0.0, area = 0.0;
  for (Eigen::Index f = 0; f < s.tris.rows(); ++f) {
    const Eigen::Vector3d a = s.vertices.row(s.tris(f, 0));
    const Eigen::Vector3d b = s.vertices.row(s.tris(f, 1));
    const Eigen::Vector3d c = s.vertices.row(s.tris(f, 2));
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double nrm[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    volume += (a[0] * nrm[0] + a[1] * nrm[1] + a[2] * nrm[2]) / 6.0;
    area += 0.5 * std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
  }
  return {volume, area};
}

// ---------------------------------------------------------------------------------------------------------------
// Gmsh session: one at a time per process (Gmsh is global state), initialized without the user's config files
// and finalized on scope exit, also when an exception leaves it. Gmsh runs with General.AbortOnError = 0 and its
// log captured: in 4.8 an error raised inside its OpenMP meshing loops is a C++ throw across the parallel region,
// which calls std::terminate, so errors are read back from the log after each step instead.

std::mutex& gmsh_mutex() {
  static std::mutex m;
  return m;
}

class GmshSession {
 public:
  explicit GmshSession(std::ostream* progress) : lock_(gmsh_mutex()), progress_(progress) {
    gmsh::initialize(0, nullptr, /*readConfigFiles=*/false);
    gmsh::option::setNumber("General.Terminal", 0);
    gmsh::option::setNumber("General.AbortOnError", 0);
    gmsh::logger::start();
  }
  ~GmshSession() {
    try {
      gmsh::logger::stop();
      gmsh::finalize();
    } catch (...) {  // a destructor must not throw; Gmsh is going away anyway
    }
  }
  GmshSession(const GmshSession&) = delete;
  GmshSession& operator=(const GmshSession&) = delete;

  // Forwards what Gmsh logged since the last call to the progress stream; throws the first error it logged.
  void check(const std::string& context) {
    std::vector<std::string> lines;
    gmsh::logger::get(lines);
    gmsh::logger::stop();
    gmsh::logger::start();
    const std::string* first_error = nullptr;
    for (const std::string& line : lines) {
      if (progress_ != nullptr && line.rfind("Progress", 0) != 0) *progress_ << "  gmsh: " << line << '\n';
      if (first_error == nullptr && line.rfind("Error", 0) == 0) first_error = &line;
    }
    if (first_error != nullptr) throw_error(context, ": Gmsh: ", *first_error);
  }

 private:
  std::lock_guard<std::mutex> lock_;
  std::ostream* progress_;
};

// Options that make a meshing reproducible and of decent quality.
void set_mesh_options(double h) {
  gmsh::option::setNumber("General.NumThreads", 1);
  gmsh::option::setNumber("Mesh.MaxNumThreads1D", 1);
  gmsh::option::setNumber("Mesh.MaxNumThreads2D", 1);
  gmsh::option::setNumber("Mesh.MaxNumThreads3D", 1);
  gmsh::option::setNumber("Mesh.RandomSeed", 1);
  gmsh::option::setNumber("Mesh.Algorithm", 6);    // 2D: Frontal-Delaunay
  // 3D: Delaunay. (HXT is faster and gives slightly better tets, but in 4.8 its output varies from run to run.)
  gmsh::option::setNumber("Mesh.Algorithm3D", 1);
  gmsh::option::setNumber("Mesh.Optimize", 1);     // tet quality optimization (Debian's Gmsh is built without Netgen)
  gmsh::option::setNumber("Mesh.ElementOrder", 1);
  gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 0);
  // Sizes do not spread from short curves (the plate's 1 cm edges) into faces: h alone governs the count.
  gmsh::option::setNumber("Mesh.MeshSizeExtendFromBoundary", 0);
  gmsh::option::setNumber("Mesh.MeshSizeMin", 0.0);
  gmsh::option::setNumber("Mesh.MeshSizeMax", h);
}

// Gives the flat bottom face (at height z, m) another 2D algorithm than the top. Identically meshed parallel faces
// put nodes exactly above one another, and where no interior node falls between them (the plate, 1 cm thick,
// at h ~ 9 mm) the 3D mesher can join four such coplanar nodes into a zero-volume tet.
void mesh_bottom_differently(double z) {
  constexpr double kTol = 1e-6;  // m
  gmsh::vectorpair faces;
  gmsh::model::getEntitiesInBoundingBox(-1.0, -1.0, z - kTol, 1.0, 1.0, z + kTol, faces, 2);
  for (const auto& face : faces) gmsh::model::mesh::setAlgorithm(2, face.second, 5);  // Delaunay
}

// Gmsh node tag of a surface vertex (0-based), and the coordinates of a list of node tags.
std::size_t tag_of(int vertex) { return static_cast<std::size_t>(vertex) + 1; }

std::vector<double> node_coords(const TriSurface& s, const std::vector<std::size_t>& tags) {
  std::vector<double> xyz;
  xyz.reserve(3 * tags.size());
  for (std::size_t t : tags)
    for (int k = 0; k < 3; ++k) xyz.push_back(s.vertices(static_cast<Eigen::Index>(t - 1), k));
  return xyz;
}

// Puts on discrete surface `surface` the vertices of `s` for which has_node(vertex) holds (the nodes classified on
// it) and the triangles for which has_triangle(triangle) holds, numbering elements from element_tag on.
void add_discrete_triangles(int surface, const TriSurface& s, const std::function<bool(std::size_t)>& has_node,
                            const std::function<bool(std::size_t)>& has_triangle, std::size_t& element_tag) {
  std::vector<std::size_t> nodes, tri_tags, tri_nodes;
  const auto vertex_count = static_cast<std::size_t>(s.vertices.rows());
  for (std::size_t i = 0; i < vertex_count; ++i)
    if (has_node(i)) nodes.push_back(tag_of(static_cast<int>(i)));
  gmsh::model::mesh::addNodes(2, surface, nodes, node_coords(s, nodes));
  for (std::size_t f = 0; f < static_cast<std::size_t>(s.tris.rows()); ++f) {
    if (!has_triangle(f)) continue;
    tri_tags.push_back(element_tag++);
    for (int k = 0; k < 3; ++k) tri_nodes.push_back(tag_of(s.tris(static_cast<Eigen::Index>(f), k)));
  }
  gmsh::model::mesh::addElementsByType(surface, 2, tri_tags, tri_nodes);
}

// Builds the shape's geometry in a fresh Gmsh model (`liver` is used for "liver" only).
void build_geometry(const std::string& shape, const SplitSurface& liver) {
  gmsh::model::add(shape);
  if (shape == "plate") {
    gmsh::model::occ::addBox(-kPlateSide / 2, -kPlateSide / 2, -kPlateThickness / 2, kPlateSide, kPlateSide,
                             kPlateThickness);
    gmsh::model::occ::synchronize();
    mesh_bottom_differently(-kPlateThickness / 2);
    return;
  }
  if (shape == "cylinder") {
    gmsh::model::occ::addCylinder(0, 0, 0, 0, 0, kCylinderHeight, kCylinderRadius);
    gmsh::model::occ::synchronize();
    mesh_bottom_differently(0.0);
    return;
  }
  // Liver: the sampled surface as discrete entities with explicit topology: one point and one closed curve on the
  // loop, the upper and lower disks bounded by it, and the volume they enclose. createGeometry parametrizes the
  // disks so that Gmsh can remesh them at size h. (Gmsh's createTopology would find the same curve, but starts it
  // at a node that varies from call to call within a process, which changed the mesh.)
  std::size_t element_tag = 1;
  auto coords_of = [&liver](const std::vector<std::size_t>& tags) { return node_coords(liver.surface, tags); };

  const int point = gmsh::model::addDiscreteEntity(0);
  const std::vector<std::size_t> point_node = {tag_of(liver.loop.front())};
  gmsh::model::mesh::addNodes(0, point, point_node, coords_of(point_node));
  gmsh::model::mesh::addElementsByType(point, 15, {element_tag++}, point_node);

  const int curve = gmsh::model::addDiscreteEntity(1, -1, {point, point});
  std::vector<std::size_t> curve_nodes, segment_tags, segment_nodes;
  for (std::size_t i = 0; i < liver.loop.size(); ++i) {
    if (i > 0) curve_nodes.push_back(tag_of(liver.loop[i]));
    segment_tags.push_back(element_tag++);
    segment_nodes.push_back(tag_of(liver.loop[i]));
    segment_nodes.push_back(tag_of(liver.loop[(i + 1) % liver.loop.size()]));
  }
  gmsh::model::mesh::addNodes(1, curve, curve_nodes, coords_of(curve_nodes));
  gmsh::model::mesh::addElementsByType(curve, 1, segment_tags, segment_nodes);

  std::vector<int> surfaces;
  for (int sg : {1, -1}) {
    const int surface = gmsh::model::addDiscreteEntity(2, -1, {curve});
    surfaces.push_back(surface);
    // A triangle belongs to the side of its off-loop vertices (at most two of its vertices are on the loop).
    add_discrete_triangles(
        surface, liver.surface, [&liver, sg](std::size_t v) { return liver.side[v] == sg; },
        [&liver, sg](std::size_t f) {
          const auto tri = liver.surface.tris.row(static_cast<Eigen::Index>(f));
          return (liver.side[tri(0)] + liver.side[tri(1)] + liver.side[tri(2)]) * sg > 0;
        },
        element_tag);
  }
  gmsh::model::addDiscreteEntity(3, -1, surfaces);
  gmsh::model::mesh::createGeometry();
}

// Reads the linear tets of the current model into a TetMesh; nodes are those the tets use, in Gmsh tag order.
// ids stay empty (Gmsh's tags mean nothing to a user; files written from the mesh number nodes 1..n).
TetMesh extract_tets() {
  std::vector<std::size_t> elem_tags, elem_nodes;
  gmsh::model::mesh::getElementsByType(4, elem_tags, elem_nodes);
  std::vector<std::size_t> node_tags;
  std::vector<double> coords, params;
  gmsh::model::mesh::getNodes(node_tags, coords, params, -1, -1, /*includeBoundary=*/true,
                              /*returnParametricCoord=*/false);

  std::vector<std::size_t> used(elem_nodes);
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  std::map<std::size_t, std::size_t> position;  // Gmsh node tag -> position in node_tags
  for (std::size_t i = 0; i < node_tags.size(); ++i) position.emplace(node_tags[i], i);

  TetMesh mesh;
  mesh.nodes.resize(static_cast<Eigen::Index>(used.size()), 3);
  std::map<std::size_t, int> index;  // Gmsh node tag -> compact 0-based index
  for (std::size_t i = 0; i < used.size(); ++i) {
    const auto it = position.find(used[i]);
    if (it == position.end()) throw_error("Gmsh: a tetrahedron uses node ", used[i], " that the model does not list");
    for (int k = 0; k < 3; ++k) mesh.nodes(static_cast<Eigen::Index>(i), k) = coords[3 * it->second + k];
    index.emplace(used[i], static_cast<int>(i));
  }
  mesh.tets.resize(static_cast<Eigen::Index>(elem_tags.size()), 4);
  for (std::size_t t = 0; t < elem_tags.size(); ++t)
    for (int k = 0; k < 4; ++k) mesh.tets(static_cast<Eigen::Index>(t), k) = index.at(elem_nodes[4 * t + k]);
  return mesh;
}

// Node-count model: about `fixed` nodes that do not depend on h (a kept surface mesh) plus
// scale * (kNodesPerVolume * volume / h^3 + kNodesPerArea * area / h^2) for characteristic length h (m); `scale` is
// measured over modelled, from attempts.
struct NodeModel {
  double volume = 0.0;  // m^3
  double area = 0.0;    // m^2 of the surface Gmsh meshes at size h (0 when the surface mesh is kept)
  double fixed = 0.0;   // nodes of a kept surface mesh
};

double model_nodes(const NodeModel& model, double h, double scale) {
  return model.fixed + scale * (kNodesPerVolume * model.volume / (h * h * h) + kNodesPerArea * model.area / (h * h));
}

// The h at which model_nodes equals `target` (model_nodes decreases with h; bisection in log h).
double solve_mesh_size(const NodeModel& model, double target, double scale) {
  double lo = std::log(1e-5), hi = std::log(1.0);
  for (int it = 0; it < 100; ++it) {
    const double m = 0.5 * (lo + hi);
    (model_nodes(model, std::exp(m), scale) > target ? lo : hi) = m;
  }
  return std::exp(0.5 * (lo + hi));
}

// Smallest tet quality 6 sqrt(2) |V| / l_rms^3 (1 for a regular tet, 0 for a flat one).
double min_tet_quality(const TetMesh& mesh) {
  double worst = 1.0;
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    double sum_sq = 0.0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) sum_sq += (mesh.nodes.row(mesh.tets(t, i)) - mesh.nodes.row(mesh.tets(t, j))).squaredNorm();
    const double l_rms = std::sqrt(sum_sq / 6.0);
    worst = std::min(worst, 6.0 * std::sqrt(2.0) * std::fabs(tet_volume(mesh, static_cast<int>(t))) / (l_rms * l_rms * l_rms));
  }
  return worst;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Meshes the current Gmsh model (geometry already built) with about `target` nodes: the characteristic length h
// comes from the node model, then each attempt rescales the model by the count it measured (at most
// kMaxCountAttempts meshings for the count); an attempt whose worst tet is below kMinQuality is re-meshed at a 1 %
// smaller h (at most kMaxQualityRetries times). `reset` clears what an attempt meshed. Returns the attempt closest
// to the target; fills report (all but seconds) if given.
TetMesh mesh_to_node_count(GmshSession& gmsh_session, const std::string& context, double target,
                           const NodeModel& model, const std::function<void()>& reset, std::ostream* progress,
                           OrganMeshReport* report) {
  double scale = 1.0;
  double h = solve_mesh_size(model, target, scale);
  // Closest attempts so far with more (`above`) and fewer (`below`) nodes than the target: (h, nodes).
  std::pair<double, double> above{0.0, 0.0}, below{0.0, 0.0};
  TetMesh best;
  double best_error = 0.0, best_h = 0.0, best_quality = 0.0;
  int attempts = 0, count_attempts = 0, quality_retries = 0;
  while (count_attempts < kMaxCountAttempts) {
    ++attempts;
    const auto t0 = std::chrono::steady_clock::now();
    reset();
    set_mesh_options(h);
    gmsh::model::mesh::generate(3);
    gmsh_session.check(context);
    TetMesh mesh = extract_tets();
    if (mesh.tets.rows() == 0) throw_error(context, ": Gmsh produced no tetrahedra at h = ", h, " m");
    const double nodes = static_cast<double>(mesh.nodes.rows());
    const double quality = min_tet_quality(mesh);
    if (progress != nullptr) {
      *progress << context << ": attempt " << attempts << ", h = " << h * 1000.0 << " mm: " << mesh.nodes.rows()
                << " nodes, " << mesh.tets.rows() << " tets, worst quality " << quality << " (" << seconds_since(t0)
                << " s)\n";
    }
    if (quality < kMinQuality) {
      if (++quality_retries > kMaxQualityRetries)
        throw_error(context, ": Gmsh keeps producing flat tetrahedra (worst quality ", quality, " at h = ", h, " m)");
      h *= 0.99;
      continue;
    }
    ++count_attempts;
    // Keep the attempt closest to the target in relative (log) terms; the earlier one wins ties.
    const double error = std::fabs(std::log(nodes / target));
    if (best.tets.rows() == 0 || error < best_error) {
      best = std::move(mesh);
      best_error = error;
      best_h = h;
      best_quality = quality;
    }
    if (std::fabs(nodes / target - 1.0) <= kAcceptRelError) break;

    // Next h: the model rescaled by this attempt. Once attempts bracket the target, interpolate between them in
    // log-log instead (the count is a step function of h at coarse sizes, so the model alone can oscillate).
    if (nodes > target && (above.first == 0.0 || h > above.first)) above = {h, nodes};
    if (nodes < target && (below.first == 0.0 || h < below.first)) below = {h, nodes};
    // Only the part that depends on h is rescaled (a kept surface's nodes are fixed); a count at or below the
    // fixed part says nothing about h and leaves the scale as it is.
    if (nodes > model.fixed) scale *= (nodes - model.fixed) / (model_nodes(model, h, scale) - model.fixed);
    h = solve_mesh_size(model, target, scale);
    if (above.first > 0.0 && below.first > 0.0) {
      const double w = std::log(above.second / target) / std::log(above.second / below.second);
      h = std::exp(std::log(above.first) + w * (std::log(below.first) - std::log(above.first)));
    }
  }
  if (report != nullptr) {
    report->nodes = static_cast<int>(best.nodes.rows());
    report->tets = static_cast<int>(best.tets.rows());
    report->attempts = attempts;
    report->mesh_size = best_h;
    report->min_quality = best_quality;
  }
  return best;
}

// The $SurgsimOrganMesh section that ends a cached .msh (organ_mesher.h): what made the file, for which spec, and the
// checksum of every byte before its checksum line.
constexpr const char* kCacheSection = "$SurgsimOrganMesh";
constexpr const char* kCacheSectionEnd = "$EndSurgsimOrganMesh";

std::string cache_identity(const OrganSpec& spec, int generator, const std::string& gmsh_version) {
  return "generator " + std::to_string(generator) + " gmsh " + gmsh_version + " shape " + spec.shape + " nodes " +
         std::to_string(spec.target_nodes);
}

std::string checksum_hex(const std::string& text, std::size_t bytes) {
  Hasher h;
  h.bytes(text.data(), bytes);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h.digest()));
  return hex;
}

// The whole file; false if it cannot be read.
bool read_file(const std::string& path, std::string& text) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return false;
  text.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  return !f.bad();
}

// Writes the mesh as a Gmsh v2.2 .msh followed by its $SurgsimOrganMesh section.
void write_cached_msh(const std::string& path, const TetMesh& mesh, const OrganSpec& spec) {
  write_msh(path, mesh);
  std::string text;
  if (!read_file(path, text)) throw_error(path, ": cannot read back the mesh just written");
  const std::size_t mesh_bytes = text.size();
  text += std::string(kCacheSection) + "\n" + cache_identity(spec, kOrganMeshVersion, GMSH_API_VERSION) + "\n";
  text += "checksum " + checksum_hex(text, text.size()) + "\n" + kCacheSectionEnd + "\n";
  std::ofstream f(path, std::ios::binary | std::ios::app);
  f.write(text.data() + mesh_bytes, static_cast<std::streamsize>(text.size() - mesh_bytes));
  f.close();
  if (!f) throw_error(path, ": cannot write the mesh's checksum section (disk full?)");
}

}  // namespace

const std::vector<std::string>& organ_shapes() {
  static const std::vector<std::string> shapes = {"liver", "plate", "cylinder"};
  return shapes;
}

void check_organ_spec(const OrganSpec& spec) {
  const auto& shapes = organ_shapes();
  if (std::find(shapes.begin(), shapes.end(), spec.shape) == shapes.end())
    throw_error("unknown organ shape '", spec.shape, "' (expected liver, plate or cylinder)");
  if (spec.target_nodes < kMinOrganNodes || spec.target_nodes > kMaxOrganNodes)
    throw_error("organ node count ", spec.target_nodes, " out of range ", kMinOrganNodes, "..", kMaxOrganNodes);
}

TetMesh generate_organ(const OrganSpec& spec, std::ostream* progress, OrganMeshReport* report) {
  check_organ_spec(spec);
  const auto start = std::chrono::steady_clock::now();
  const std::string context = "organ '" + spec.shape + "' (" + std::to_string(spec.target_nodes) + " nodes)";
  const double target = spec.target_nodes;

  // Volume and area give the first characteristic length. The liver's are those of its sampled surface, first
  // sampled coarsely to estimate h, then at the resolution that h asks for (fixed across re-meshes).
  SplitSurface liver;
  NodeModel model;
  if (spec.shape == "plate") {
    model.volume = kPlateSide * kPlateSide * kPlateThickness;
    model.area = 2 * kPlateSide * kPlateSide + 4 * kPlateSide * kPlateThickness;
  } else if (spec.shape == "cylinder") {
    model.volume = kPi * kCylinderRadius * kCylinderRadius * kCylinderHeight;
    model.area = 2 * kPi * kCylinderRadius * (kCylinderRadius + kCylinderHeight);
  } else {
    liver = liver_surface(kLiverMinCells);
    std::tie(model.volume, model.area) = volume_and_area(liver.surface);
    const int cells = liver_cells(solve_mesh_size(model, target, 1.0));
    if (cells != kLiverMinCells) {
      liver = liver_surface(cells);
      std::tie(model.volume, model.area) = volume_and_area(liver.surface);
    }
  }

  TetMesh best;
  try {
    GmshSession gmsh_session(progress);
    build_geometry(spec.shape, liver);
    gmsh_session.check(context);
    best = mesh_to_node_count(gmsh_session, context, target, model, [] { gmsh::model::mesh::clear(); }, progress,
                              report);
  } catch (const std::string& what) {  // Gmsh 4.8 throws its error message as a std::string
    throw_error(context, ": Gmsh: ", what);
  }
  validate_mesh(best);
  if (report != nullptr) report->seconds = seconds_since(start);
  return best;
}

int closed_surface_nodes(double volume, double area, int target_nodes) {
  if (!(volume > 0.0) || !(area > 0.0) || target_nodes <= 0) return 0;
  const double h = solve_mesh_size(NodeModel{volume, area, 0.0}, target_nodes, 1.0);
  return static_cast<int>(std::lround(kNodesPerArea * area / (h * h)));
}

TetMesh mesh_closed_surface(const TriSurface& surface, int target_nodes, std::ostream* progress,
                            OrganMeshReport* report) {
  const Eigen::MatrixX3d& vertices = surface.vertices;
  const Eigen::MatrixX3i& tris = surface.tris;
  const auto start = std::chrono::steady_clock::now();
  const std::string context = "closed surface (" + std::to_string(vertices.rows()) + " vertices, " +
                              std::to_string(target_nodes) + " nodes wanted)";
  if (target_nodes < kMinOrganNodes || target_nodes > kMaxOrganNodes)
    throw_error(context, ": node count out of range ", kMinOrganNodes, "..", kMaxOrganNodes);
  if (tris.rows() < 4 || vertices.rows() < 4) throw_error(context, ": too few triangles for a closed surface");
  if (!vertices.allFinite()) throw_error(context, ": non-finite vertex coordinates");
  if (tris.minCoeff() < 0 || tris.maxCoeff() >= vertices.rows()) throw_error(context, ": triangle index out of range");
  // The surface's own numbers: volume and area by the divergence theorem, vertices used.
  NodeModel model;
  double area = 0.0;
  std::tie(model.volume, area) = volume_and_area(surface);
  if (!(model.volume > 0.0)) throw_error(context, ": the surface encloses no volume or faces inward");
  std::vector<int> used(surface.tris.data(), surface.tris.data() + surface.tris.size());
  std::sort(used.begin(), used.end());
  model.fixed = static_cast<double>(std::unique(used.begin(), used.end()) - used.begin());
  if (model.fixed >= target_nodes)
    throw_error(context, ": the surface alone has ", static_cast<int>(model.fixed), " vertices, not fewer than the ",
                target_nodes, " nodes wanted (reduce the surface first)");

  TetMesh best;
  try {
    GmshSession gmsh_session(progress);
    gmsh::model::add("closed_surface");
    const int surface_tag = gmsh::model::addDiscreteEntity(2);
    std::size_t element_tag = 1;
    std::vector<char> used_vertex(static_cast<std::size_t>(surface.vertices.rows()), 0);
    for (Eigen::Index i = 0; i < surface.tris.size(); ++i)
      used_vertex[static_cast<std::size_t>(surface.tris.data()[i])] = 1;
    add_discrete_triangles(
        surface_tag, surface, [&used_vertex](std::size_t v) { return used_vertex[v] != 0; },
        [](std::size_t) { return true; }, element_tag);
    // The volume is a built-in-kernel volume bounded by the discrete surface: Gmsh meshes it with its 3D
    // Delaunay and leaves the surface's triangles as they are (a surface without a parametrization is not remeshed).
    const int loop = gmsh::model::geo::addSurfaceLoop({surface_tag});
    const int volume_tag = gmsh::model::geo::addVolume({loop});
    gmsh::model::geo::synchronize();
    gmsh_session.check(context);
    // Each attempt clears the tets only: the surface mesh is kept as given.
    best = mesh_to_node_count(gmsh_session, context, target_nodes, model,
                              [volume_tag] { gmsh::model::mesh::clear({{3, volume_tag}}); }, progress, report);
  } catch (const std::string& what) {  // Gmsh 4.8 throws its error message as a std::string
    throw_error(context, ": Gmsh: ", what);
  }
  validate_mesh(best);
  const SurfaceMesh boundary = boundary_surface(best);
  if (boundary.tris.rows() != tris.rows())
    throw_error(context, ": Gmsh changed the surface (", boundary.tris.rows(), " boundary triangles for ", tris.rows(),
                " given)");
  if (report != nullptr) report->seconds = seconds_since(start);
  return best;
}

std::string organ_mesh_path(const OrganSpec& spec, const std::string& cache_dir, int generator) {
  const std::string name =
      spec.shape + "-" + std::to_string(spec.target_nodes) + "-g" + std::to_string(generator) + ".msh";
  return (std::filesystem::path(cache_dir) / name).string();
}

std::string cached_organ_mesh_problem(const std::string& path, const OrganSpec& spec) {
  std::string text;
  if (!read_file(path, text)) return "cannot be read";
  const std::string opening = "\n" + std::string(kCacheSection) + "\n";
  const std::size_t section = text.rfind(opening);
  if (section == std::string::npos)
    return "no " + std::string(kCacheSection) + " section at its end (cut short, or cached by an older surgsim)";
  // The section's three lines: identity, checksum, end tag; nothing after them.
  std::istringstream lines(text.substr(section + opening.size()));
  std::string identity, checksum_line, end, rest;
  std::getline(lines, identity);
  const std::size_t checksum_at = section + opening.size() + identity.size() + 1;
  std::getline(lines, checksum_line);
  std::getline(lines, end);
  std::getline(lines, rest, '\0');
  if (checksum_line.rfind("checksum ", 0) != 0 || end != kCacheSectionEnd || !rest.empty() || checksum_at > text.size())
    return "its " + std::string(kCacheSection) + " section is damaged or cut short";
  if (checksum_line.substr(9) != checksum_hex(text, checksum_at))
    return "checksum mismatch: the file was altered or damaged after it was written";
  // Intact: now what made it, and for which spec.
  std::istringstream fields(identity);
  std::string generator_word, gmsh_word, gmsh_version, shape_word, shape, nodes_word;
  int generator = 0, nodes = 0;
  fields >> generator_word >> generator >> gmsh_word >> gmsh_version >> shape_word >> shape >> nodes_word >> nodes;
  if (!fields || generator_word != "generator" || gmsh_word != "gmsh" || shape_word != "shape" || nodes_word != "nodes")
    return "its " + std::string(kCacheSection) + " section does not say what made it";
  if (generator != kOrganMeshVersion)
    return "made by organ mesher generator version " + std::to_string(generator) + ", this build's is " +
           std::to_string(kOrganMeshVersion);
  if (gmsh_version != GMSH_API_VERSION)
    return "meshed with Gmsh " + gmsh_version + ", this build uses Gmsh " + GMSH_API_VERSION;
  if (shape != spec.shape || nodes != spec.target_nodes)
    return "made for " + shape + " at " + std::to_string(nodes) + " nodes, not " + spec.shape + " at " +
           std::to_string(spec.target_nodes);
  return "";
}

std::string ensure_organ_mesh(const OrganSpec& spec, const std::string& cache_dir, std::ostream* progress,
                              OrganMeshCacheOutcome* outcome) {
  namespace fs = std::filesystem;
  check_organ_spec(spec);
  const std::string path = organ_mesh_path(spec, cache_dir);
  OrganMeshCacheOutcome local;
  OrganMeshCacheOutcome& out = outcome != nullptr ? *outcome : local;
  out = OrganMeshCacheOutcome();
  std::error_code ec;
  if (fs::is_regular_file(path, ec)) {
    out.rejected = cached_organ_mesh_problem(path, spec);
    if (out.rejected.empty()) return path;
    if (progress != nullptr)
      *progress << "organ " << spec.shape << ": cached " << path << " not used (" << out.rejected
                << "); generating it again\n";
  }

  fs::create_directories(cache_dir, ec);
  if (ec) throw_error(cache_dir, ": cannot create the mesh cache folder (", ec.message(), ")");
  if (::access(cache_dir.c_str(), W_OK) != 0) throw_error(cache_dir, ": the mesh cache folder is not writable");

  const TetMesh mesh = generate_organ(spec, progress);

  // Unique temporary names in the same folder (rename is atomic only within one file system). The .vtk goes
  // first: the .msh appearing is what tells other processes that the entry is complete.
  static std::atomic<unsigned> counter{0};
  const std::string suffix = ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  auto publish = [&suffix](const std::string& final_path, auto&& write) {
    const std::string tmp = final_path + suffix;
    try {
      write(tmp);
    } catch (...) {
      std::error_code ignored;
      fs::remove(tmp, ignored);
      throw;
    }
    if (std::rename(tmp.c_str(), final_path.c_str()) != 0) {
      std::error_code ignored;
      fs::remove(tmp, ignored);
      throw_error(final_path, ": cannot move the generated mesh into place");
    }
  };
  publish(fs::path(path).replace_extension(".vtk").string(), [&mesh](const std::string& p) { write_vtk(p, mesh); });
  publish(path, [&mesh, &spec](const std::string& p) { write_cached_msh(p, mesh, spec); });
  out.generated = true;
  if (progress != nullptr) *progress << "organ " << spec.shape << ": cached " << path << '\n';
  return path;
}

}  // namespace surgsim::mesher
