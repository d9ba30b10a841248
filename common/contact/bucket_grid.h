// The liver's bucket grid: collision detection between the tool and the organ surface (paper section 5;
// docs/DESIGN.md, section 'Collision (liver)').
//
// A bucket grid over the organ's bounding box with an open-addressing hash table (cell -> surface nodes, CSR),
// node -> incident triangles (CSR). A query walks the cells along the tool segment [p_prev, p_cur], gathers the
// surface nodes in those cells and their 26 neighbours, and tests the segment against the triangles around them at
// their DEFORMED positions (continuous: a fast tool does not pass through). Deformed positions are evaluated only
// for the candidate nodes, through a callback. Everything is allocated at build time; queries allocate nothing.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "mesh/geometry.h"
#include "mesh/mesh.h"

namespace surgsim::contact {

/// Result of a segment query: the first surface crossing along the segment.
struct SurfaceHit {
  bool hit = false;
  int triangle = -1;                                // row of the surface's tris
  std::array<int, 3> nodes{{-1, -1, -1}};           // mesh node indices of that triangle
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();   // (k1, k2, k3), sum 1
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // m, crossing point on the deformed surface
  double s = 0;                                     // parameter along the segment in [0, 1]
};

/// Closest point on the (rest or deformed) surface near a point.
struct SurfaceProjection {
  bool found = false;
  int triangle = -1;
  std::array<int, 3> nodes{{-1, -1, -1}};
  Eigen::Vector3d bary = Eigen::Vector3d::Zero();
  Eigen::Vector3d point = Eigen::Vector3d::Zero();    // m
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // outward unit normal of the triangle
  double distance = 0;                                // m
};

class BucketGrid {
 public:
  static constexpr int kMaxCandidates = 512;  // surface nodes examined per query
  static constexpr double kFacingCos = -0.5;  // project_rest(facing): cos 120 degrees
  static constexpr int kMaxTriangles = 2048;  // triangles examined per query

  /// Builds the grid over the surface nodes at rest. `cell_size` <= 0 chooses about 2x the mean surface edge.
  /// `margin` (m) enlarges the bounding box so that deformed nodes and the tool near the organ stay inside.
  BucketGrid(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface, double cell_size = 0, double margin = 0.02);

  /// Deformed position callback: fills `out` with node n's current position. Called only for candidates.
  using PositionFn = void (*)(const void* context, int node, Eigen::Vector3d& out);

  /// First crossing of [p0, p1] with the surface, entering from outside (the triangle's outward normal faces p0).
  /// `positions` may be null (rest shape). Allocates nothing.
  SurfaceHit segment_query(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, PositionFn positions = nullptr,
                           const void* context = nullptr) const;

  /// Closest point of the REST surface to p among the triangles around the surface nodes within `radius` cells
  /// (1 = the 27 cells around p). With `facing`, only triangles whose outward normal is within 120 degrees of it
  /// count (cosine above kFacingCos): a contact may slide round an edge onto a side face, but does not jump to the
  /// opposite face when the tool goes deeper than half the organ's thickness. Allocates nothing.
  SurfaceProjection project_rest(const Eigen::Vector3d& p, int radius = 1,
                                 const Eigen::Vector3d* facing = nullptr) const;

  /// Surface nodes in the cell of p and its 26 neighbours (for tests and the nearest-node step).
  int candidates_near(const Eigen::Vector3d& p, int* out, int capacity) const;

  /// Nearest surface node to p at rest among the 27 cells (-1 if none).
  int nearest_node(const Eigen::Vector3d& p) const;

  double cell_size() const { return cell_; }
  /// Brute-force reference for tests: first crossing over all triangles.
  SurfaceHit segment_query_brute(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, PositionFn positions = nullptr,
                                 const void* context = nullptr) const;
  const mesh::SurfaceMesh& surface() const { return *surface_; }
  const Eigen::MatrixX3d& rest() const { return *rest_; }

 private:
  std::uint64_t key(int i, int j, int k) const;
  int find_slot(std::uint64_t key) const;  // slot index of key in the table, or -1
  void cell_of(const Eigen::Vector3d& p, int& i, int& j, int& k) const;
  int gather_cells(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, int* nodes, int capacity) const;
  int triangles_of(const int* nodes, int count, int* tris, int capacity) const;
  void test_triangle(int f, const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, PositionFn positions,
                     const void* context, SurfaceHit& best) const;

  const Eigen::MatrixX3d* rest_;
  const mesh::SurfaceMesh* surface_;
  double cell_ = 0.01;
  Eigen::Vector3d origin_;
  std::array<int, 3> dims_{{1, 1, 1}};
  // Open-addressing table: keys_[slot] (or kEmpty) -> [start_[slot], start_[slot] + count_[slot]) in cell_nodes_.
  std::vector<std::uint64_t> keys_;
  std::vector<int> start_;
  std::vector<int> count_;
  std::vector<int> cell_nodes_;
  // Node -> incident surface triangles (CSR over mesh node indices).
  mesh::NodeTriangles node_tris_;
  // Scratch marks for de-duplication (mutable: queries are logically const, single-threaded per grid).
  mutable std::vector<std::uint32_t> node_mark_;
  mutable std::vector<std::uint32_t> tri_mark_;
  mutable std::uint32_t stamp_ = 0;
};

/// The paper's distribution of a contact displacement over a triangle: alpha_v = k_v / (k1^2 + k2^2 + k3^2), so that
/// moving vertex v by alpha_v d moves the barycentric point by exactly d.
Eigen::Vector3d barycentric_weights(const Eigen::Vector3d& bary);

}  // namespace surgsim::contact
