// Intestine rendering geometry (Raghupathi et al. 2004, section 5; docs/DESIGN.md, section 'Intestine rendering'), pure
// CPU code usable by any backend: the generalized cylinder around the intestine's points, the mesentery's triangle
// strip over the grid and the mesentery as a smooth subdivided surface with analytic normals (MesenterySurface, what
// the visual node draws).
//
// Tube pipeline (TubeBuilder::build):
//   1. a cardinal spline through the points (Hermite pieces, tangents (1 - c) (P_{i+1} - P_{i-1}) / 2);
//   2. the curvature indicator c_i of each segment: the turning of the spline's tangent over the segment (angle from
//      t = 0 to 1/2 plus angle from 1/2 to 1, rad), two derivative evaluations;
//   3. segments with c_i > flag_turn get 1..max_extra_samples extra samples (more for a larger turn): one at the
//      parameter of maximal curvature t* (found on 16 samples of |H' x H''| / |H'|^3, refined by a parabola), the
//      others on either side of it at equal steps of turning, so that they crowd where the curve bends most;
//   4. rotation-minimizing frames along the samples by the double reflection method (Wang, Juttler, Zheng, Liu,
//      ACM TOG 2008), the first normal carried over from the previous build so the tube does not spin;
//   5. a ring guard that keeps adjacent cross-sections from intersecting inside the tube (see below);
//   6. two-matrix skinning of a precomputed cylinder primitive: a primitive vertex (cos a, sin a, t) of interval k
//      becomes (1 - w(t)) A_k v + w(t) B_k v, with A_k = [r_a N_a, r_a B_a, l T_a, c_a] and
//      B_k = [r_b N_b, r_b B_b, l T_b, c_b - l T_b] the frames at the interval's ends (l: chord length) and the weight
//      w(t) = 3 t^2 - 2 t^3. Because w'(0) = w'(1) = 0 the axis leaves each ring along that ring's tangent, so
//      the skinned tube is C1 across rings and the axis is a Hermite-like cubic between them.
//   7. levels of detail: LOD i (0..kTubeMaxLod) has sides x rings quads per interval: 16 x 2, 24 x 2, 24 x 4,
//      32 x 4, 32 x 8, 40 x 8, 48 x 8 (32 to 384 quads; each level 1.2 to 2 times the previous one's triangles).
//      The paper's ladder doubles from 4 sides x 1 ring (4 2^i quads): its coarsest levels are a square and an
//      octagon in cross-section with straight pieces between the samples, and a frame-rate controller held below
//      its target (as live next to the haptic node on 2 cores) draws them. Here the coarsest level is still
//      round: 16 sides (on the skinned rest shape adjacent vertex normals at most 26 degrees apart, so the
//      interpolated shading turns smoothly, and the flat faces within 2.5 % of the radius: under a pixel at the
//      shipped camera) and 2 rings per interval, so that the axis follows the skinned curve between samples
//      (tube_geometry_test EveryLevelOfDetailIsRoundWithSmoothNormals). Rings are powers of two up to 8, so every
//      level's rings are a subset of the finest level's (the ring guard below);
//   8. rounded end caps: a hemisphere on the first and the last ring (the ring's own radius and frame), cap_rings =
//      sides / 4 latitude steps from the ring to the pole, sharing the ring's vertices, so the tube is closed
//      (watertight: every edge in exactly two triangles) with outward normals.
// The CPU skinning writes positions, normals and triangle indices (any backend can draw them, tests can check them);
// the same A_k, B_k per interval (TubeMesh::skin) and TubePrimitive let a vertex shader do steps 6 and 8 instead
// (TubeSkinning::kGpu builds the matrices only). A primitive vertex (x, y, t, z) of interval k is skinned to
//   p = (1 - w(t)) (A_k (x, y, t, 1) + z r_a T_a) + w(t) (B_k (x, y, t, 1) + z r_b T_b),
//   n = normalize((1 - w(t)) (x N_a + y B_a + z T_a) + w(t) (x N_b + y B_b + z T_b)),
// with r, N, B, T read back from the matrices' columns: the tube's vertices have z = 0 and (x, y) = (cos a, sin a);
// a cap vertex at latitude phi has (x, y) = cos(phi) (cos a, sin a), t = 0 and z = -sin(phi) (first ring, drawn with
// interval 0) or t = 1 and z = sin(phi) (last ring, interval n - 1).
//
// Ring guard: two cross-sections (centres c1, c2, radii r1, r2, unit normals n1, n2 at angle theta) do not intersect
// inside the tube when d.n2 >= (r1 + e) sin(theta) and d.n1 >= (r2 + e) sin(theta), d = c2 - c1, e = ring_clearance:
// the planes' common line then passes farther than its radius from each ring's centre. The guard checks this for
// every pair of adjacent rings the skinning will produce in an interval, at every LOD (the rings of the coarser LODs
// are a subset of the finest one's), and repairs an interval that fails, least visible first: it turns the end
// rings' tangents step by step from the spline's towards the miter of the adjacent chords (their bisector; the
// chord at the tube's ends); then narrows the two end rings step by step down to min_radius_fraction of the radius
// (a fold tighter than the tube is drawn pinched, as a real bowel folds); and only then removes a sample, an extra
// one first, else the one where the chords turn most, so that a kink sharper than even the narrowed tube can follow
// is cut. The tube's first and last rings always stay. A curve whose radius of curvature stays above about 1.5
// (radius + clearance) passes unchanged: the weight's largest slope, 1.5 at t = 1/2, is where the skinned rings
// turn fastest.
//
// Phases: TubeBuilder and the meshes allocate at construction (make_mesh: for the largest input and a LOD;
// make_mesentery_mesh, make_mesentery_surface); build(), mesentery_strip() and mesentery_surface() allocate nothing.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace surgsim::intestine {

constexpr int kTubeMaxLod = 6;

/// Primitive resolution of a level of detail.
struct TubeLod {
  int sides = 4;      // vertices around a ring
  int rings = 1;      // rings per interval (the interval's last ring is the next one's first)
  int cap_rings = 1;  // latitude steps of an end cap from its ring to the pole (sides / 4)
};
TubeLod tube_lod(int lod);  // lod clamped to 0..kTubeMaxLod

struct TubeParams {
  double radius = 0.02;          // m, tube radius
  double tension = 0.0;          // cardinal spline tension c in [0, 1) (0: Catmull-Rom)
  double flag_turn = 0.35;       // rad, c_i above this flags the segment for extra samples
  int max_extra_samples = 3;     // per flagged segment, 0..8
  double ring_clearance = 0.0005;  // m, adjacent rings' planes must meet at least radius + this from both centres
  double min_radius_fraction = 0.5;  // the ring guard narrows rings down to this fraction of the radius, (0, 1]
};

/// Skinning weight of the far frame at parameter t of an interval: 3 t^2 - 2 t^3.
double skin_weight(double t);

/// One ring of the tube (a spline sample after the guard).
struct TubeSample {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();    // m
  Eigen::Vector3d tangent = Eigen::Vector3d::UnitX();  // unit, the ring's normal
  Eigen::Vector3d normal = Eigen::Vector3d::UnitY();   // unit, RMF
  Eigen::Vector3d binormal = Eigen::Vector3d::UnitZ(); // tangent x normal
  int segment = 0;      // spline segment
  double t = 0;         // parameter in the segment
  bool extra = false;   // added by the curvature refinement
  int tilt = 0;         // 0, 2, 4: how far (in quarters) the ring guard turned the tangent towards the miter
  double radius = 0;    // m, the ring's radius (below TubeParams::radius where the guard narrowed it)
  Eigen::Vector3d spline_tangent = Eigen::Vector3d::UnitX();  // unit, before the guard
};

/// Which part of step 6 build() does on the CPU.
enum class TubeSkinning {
  kCpu,  // skinning matrices and the skinned vertices, normals and indices
  kGpu,  // skinning matrices and the counts only (a vertex shader skins TubePrimitive)
};

/// Vertices of one end cap besides its ring (the ring belongs to the tube): (cap_rings - 1) rings and the pole.
int tube_cap_vertices(const TubeLod& lod);
/// Triangles of one end cap: sides (2 cap_rings - 1).
int tube_cap_triangles(const TubeLod& lod);

/// The skinned tube. Sized by TubeBuilder::make_mesh; build() fills the first *_count entries.
struct TubeMesh {
  int lod = 0;
  int sides = 0;
  int intervals = 0;                 // between consecutive samples
  int ring_count = 0;                // intervals * rings per interval + 1
  int body_vertex_count = 0;         // ring_count * sides, ring-major, first
  int vertex_count = 0;              // body, then the first ring's cap, then the last ring's (tube_cap_vertices each)
  int body_index_count = 0;          // the tube's triangles come first, then the two caps'
  int index_count = 0;               // 3 per triangle, caps included
  std::vector<float> positions;      // 3 per vertex, m (TubeSkinning::kCpu only)
  std::vector<float> normals;        // 3 per vertex, unit, outward (kCpu only)
  std::vector<std::uint32_t> indices;  // triangles, counter-clockwise seen from outside (kCpu only)
  std::vector<float> skin;           // 24 per interval: A_k then B_k, 3 x 4 row-major (for GPU skinning)
};

/// The precomputed cylinder primitive of a LOD with its two end caps, for GPU skinning.
struct TubePrimitive {
  TubeLod lod;
  int body_vertex_count = 0;           // (rings + 1) x sides, ring-major: one interval of the tube
  int cap_vertex_count = 0;            // per cap: the first ring's cap follows the body, then the last ring's
  int body_index_count = 0;            // the interval's triangles, first in `indices`
  int cap_index_count = 0;             // per cap: the first ring's cap's triangles, then the last ring's
  std::vector<float> vertices;         // 4 per vertex: x, y, t, z (see the header comment)
  std::vector<std::uint32_t> indices;  // triangles, counter-clockwise seen from outside
};

struct TubeStats {
  int samples = 0;            // rings after the guard
  int flagged_segments = 0;   // c_i > flag_turn
  int extra_samples = 0;      // added by the refinement (before the guard)
  int removed_samples = 0;    // removed by the guard
  int tilted_rings = 0;       // rings whose tangent the guard turned towards the miter
  int narrowed_rings = 0;     // rings the guard narrowed
  double min_radius = 0;      // m, the narrowest ring
};

/// Cardinal spline tangents m_i = (1 - c)(P_{i+1} - P_{i-1}) / 2 (one-sided at the ends), n >= 2 points.
void cardinal_tangents(const Eigen::Vector3d* points, int n, double tension, Eigen::Vector3d* tangents);
/// Hermite piece and its derivatives at t in [0, 1].
Eigen::Vector3d hermite(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& m0,
                        const Eigen::Vector3d& m1, double t);
Eigen::Vector3d hermite_d1(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& m0,
                           const Eigen::Vector3d& m1, double t);
Eigen::Vector3d hermite_d2(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& m0,
                           const Eigen::Vector3d& m1, double t);

/// Rotation-minimizing frames by double reflection: given n centres and unit tangents and the first normal r0
/// (orthogonal to tangents[0]), writes normals (and binormals = tangent x normal). No allocation.
void rotation_minimizing_frames(const Eigen::Vector3d* centers, const Eigen::Vector3d* tangents, int n,
                                const Eigen::Vector3d& r0, Eigen::Vector3d* normals, Eigen::Vector3d* binormals);

class TubeBuilder {
 public:
  /// Init phase (allocates): work arrays for up to `max_points` input points. Throws surgsim::core::Error on bad
  /// params.
  TubeBuilder(const TubeParams& params, int max_points);

  const TubeParams& params() const { return params_; }
  int max_points() const { return max_points_; }
  /// Largest number of intervals any input can produce: (max_points - 1)(1 + max_extra_samples).
  int max_intervals() const { return (max_points_ - 1) * (1 + params_.max_extra_samples); }

  /// A mesh with room for any input at LODs up to `lod` (allocates; do it once per LOD you will use).
  TubeMesh make_mesh(int lod = kTubeMaxLod) const;
  /// The cylinder primitive of a LOD (GPU path).
  const TubePrimitive& primitive(int lod) const;

  /// Run phase, no allocation: builds the tube through `count` points (3 count doubles, x y z per point) at `lod`
  /// into `mesh` (made by make_mesh with a LOD >= lod). False, with an empty mesh, for fewer than 2 distinct points,
  /// more than max_points, non-finite input or a mesh too small. With TubeSkinning::kGpu only the matrices and the
  /// counts are written (positions, normals and indices keep whatever they held).
  bool build(const double* points, int count, int lod, TubeMesh& mesh,
             TubeSkinning skinning = TubeSkinning::kCpu) noexcept;

  /// Results of the last build (samples after the guard, c_i per segment, counters).
  int sample_count() const { return sample_count_; }
  const TubeSample& sample(int i) const { return samples_[static_cast<std::size_t>(i)]; }
  double curvature_indicator(int segment) const { return curvature_[static_cast<std::size_t>(segment)]; }
  const TubeStats& stats() const { return stats_; }
  /// Forgets the normal carried from the previous build (the next build starts from a fixed choice).
  void reset_frames() noexcept { has_previous_normal_ = false; }

 private:
  bool sample_spline(int count) noexcept;
  void first_frame(const Eigen::Vector3d& r0) noexcept;
  void frame_step(int k) noexcept;
  double interval_fit(int k) const noexcept;  // >= 1: the interval's rings pass the guard
  int repair(int k, double fit) noexcept;
  void erase(int k) noexcept;
  void guard(const Eigen::Vector3d& r0) noexcept;
  void skin(int lod, TubeSkinning skinning, TubeMesh& mesh) const noexcept;

  TubeParams params_;
  int max_points_ = 0;
  std::vector<Eigen::Vector3d> points_, tangents_;
  std::vector<double> curvature_;
  std::vector<TubeSample> samples_;
  int sample_count_ = 0;
  TubeStats stats_;
  Eigen::Vector3d previous_normal_ = Eigen::Vector3d::UnitY();
  bool has_previous_normal_ = false;
  std::vector<TubePrimitive> primitives_;
};

/// The mesentery as one triangle strip over a rows x cols grid of points (row 0: the intestine), strips joined by
/// degenerate triangles.
struct MesenteryMesh {
  int rows = 0, cols = 0;
  int vertex_count = 0;               // rows * cols, vertex (r, c) at r cols + c
  int index_count = 0;                // (rows - 1) 2 cols + (rows - 2) 2
  std::vector<float> positions;       // 3 per vertex, m
  std::vector<float> normals;         // 3 per vertex, unit (grid normal; the membrane is two-sided)
  std::vector<std::uint32_t> strip;   // GL_TRIANGLE_STRIP indices
};

/// Allocates the mesh and writes the (fixed) strip indices.
MesenteryMesh make_mesentery_mesh(int rows, int cols);
/// Run phase, no allocation: positions and normals from `points` (3 rows cols doubles, node (r, c) at r cols + c,
/// the layout of IntestineState::positions()). False if the mesh is too small for its grid or a point is not finite.
bool mesentery_strip(const double* points, MesenteryMesh& mesh) noexcept;

/// The mesentery as a smooth surface (what the visual node draws): the rows x cols grid of the mass-spring model
/// refined by a bicubic Catmull-Rom patch (the tensor product of the cardinal spline of cardinal_tangents with tension
/// 0 along the columns and across the rows: one-sided tangents at the borders, so row 0's curve is the tube's axis
/// spline), `col_steps` vertices per grid interval along the intestine and `row_steps` across the membrane. Every
/// vertex carries the patch's analytic unit normal, normalize(dS/du x dS/dv) (u along the columns, v across the
/// rows: the side of MesenteryMesh::normals), and its surface coordinates (u in grid columns, v in [0, 1] from the
/// intestine to the vessel row) for the shader's vessels. Where the patch degenerates (rows converging to a point at
/// a tapered end: dS/dv = 0) the normal is the nearest valid one of the same vertex row, then of the same column.
struct MesenterySurface {
  int rows = 0, cols = 0;              // the mass-spring grid
  int row_steps = 1, col_steps = 1;    // vertices per grid interval across the rows and along the columns
  int vertex_rows = 0, vertex_cols = 0;  // (rows - 1) row_steps + 1, (cols - 1) col_steps + 1
  int vertex_count = 0;                // vertex_rows * vertex_cols, vertex (i, j) at i vertex_cols + j
  int degenerate_normals = 0;          // vertices of the last build whose normal was borrowed from a neighbour
  std::vector<float> positions;        // 3 per vertex, m
  std::vector<float> normals;          // 3 per vertex, unit
  std::vector<float> coords;           // 2 per vertex: u (grid columns, 0..cols - 1), v (0 intestine .. 1 vessel)
  std::vector<std::uint32_t> indices;  // triangles, 3 per triangle, counter-clockwise seen from the normals' side
  // Work arrays: the grid rows refined along u (point and d/du per grid row and vertex column).
  std::vector<Eigen::Vector3d> along, along_du;
};

/// Allocates the surface for a rows x cols grid and writes the (fixed) triangles and coordinates. Throws
/// surgsim::core::Error for rows or cols < 2 or steps outside 1..16.
MesenterySurface make_mesentery_surface(int rows, int cols, int row_steps, int col_steps);
/// Run phase, no allocation: the refined positions and normals from `points` (3 rows cols doubles, the layout of
/// IntestineState::positions()). False (the surface unchanged) if a point is not finite or the surface was not made
/// by make_mesentery_surface.
bool mesentery_surface(const double* points, MesenterySurface& surface) noexcept;

}  // namespace surgsim::intestine
