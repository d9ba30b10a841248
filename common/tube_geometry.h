// Intestine rendering geometry (Raghupathi et al. 2004, section 5; DESIGN.md 4.4), pure CPU code usable by any
// backend: the generalized cylinder around the intestine's points and the mesentery's triangle strip.
//
// Tube pipeline (TubeBuilder::build):
//   1. a cardinal spline through the points (Hermite pieces, tangents (1 - c) (P_{i+1} - P_{i-1}) / 2);
//   2. the curvature indicator c_i of each segment: the turning of the spline's tangent over the segment (angle from
//      t = 0 to 1/2 plus angle from 1/2 to 1, rad), two derivative evaluations;
//   3. segments with c_i > flag_turn get 1..max_extra_samples extra samples clustered around the parameter of
//      maximal curvature t* (found on 16 samples of |H' x H''| / |H'|^3, refined by a parabola);
//   4. a ring guard that keeps adjacent cross-sections from intersecting inside the tube (see below);
//   5. rotation-minimizing frames along the samples by the double reflection method (Wang, Juttler, Zheng, Liu,
//      ACM TOG 2008), the first normal carried over from the previous build so the tube does not spin;
//   6. two-matrix skinning of a precomputed cylinder primitive: a primitive vertex (cos a, sin a, t) of interval k
//      becomes (1 - w(t)) A_k v + w(t) B_k v, with A_k = [r N_a, r B_a, l T_a, c_a] and
//      B_k = [r N_b, r B_b, l T_b, c_b - l T_b] the frames at the interval's ends (l: chord length) and the weight
//      w(t) = 3 t^2 - 2 t^3. Because w'(0) = w'(1) = 0 the axis leaves each ring along that ring's tangent, so
//      the skinned tube is C1 across rings and the axis is a Hermite-like cubic between them.
//   7. levels of detail: LOD i (0..kTubeMaxLod) has sides x rings = 4 2^i quads per interval (8 2^i triangles),
//      sides = 4 2^ceil(i/2), rings = 2^floor(i/2).
// The CPU skinning writes positions, normals and triangle indices (any backend can draw them, tests can check them);
// the same A_k, B_k per interval (TubeMesh::skin) and TubePrimitive let a vertex shader do step 6 instead.
//
// Ring guard: two cross-sections (centres c1, c2, unit normals n1, n2 at angle theta, radius r) do not intersect
// inside the tube when d.n1 >= r sin(theta) and d.n2 >= r sin(theta), d = c2 - c1 (the planes' common line is then at
// least r from both centres). If every ring's tangent stays within phi(l) of each adjacent chord, with
// sin(phi) = l / (2 kappa r) and phi <= 45 deg, the condition holds with margin kappa for the rings and, with
// kappa >= the weight's largest slope (1.5), for the skinned rings between them. The guard projects each ring's
// tangent into the cones of its two chords; a sample where the cones are disjoint (a kink sharper than the tube can
// follow) is removed, which lengthens its neighbours' chords. Folds the collision response allows (legs at least
// 2 r apart) keep every point; only kinks sharper than the tube radius are cut.
//
// Phases: TubeBuilder and the meshes allocate at construction (make_mesh: for the largest input and a LOD);
// build() and mesentery_strip() allocate nothing.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace surgsim::intestine {

constexpr int kTubeMaxLod = 6;

/// Primitive resolution of a level of detail.
struct TubeLod {
  int sides = 4;  // vertices around a ring
  int rings = 1;  // rings per interval (the interval's last ring is the next one's first)
};
TubeLod tube_lod(int lod);  // lod clamped to 0..kTubeMaxLod

struct TubeParams {
  double radius = 0.02;          // m, tube radius
  double tension = 0.0;          // cardinal spline tension c in [0, 1) (0: Catmull-Rom)
  double flag_turn = 0.35;       // rad, c_i above this flags the segment for extra samples
  int max_extra_samples = 3;     // per flagged segment, 0..8
  double fold_safety = 1.6;      // kappa of the ring guard, >= 1.5 (the weight function's largest slope)
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
  bool tilted = false;  // the ring guard turned the tangent towards a chord
};

/// The skinned tube. Sized by TubeBuilder::make_mesh; build() fills the first *_count entries.
struct TubeMesh {
  int lod = 0;
  int sides = 0;
  int intervals = 0;                 // between consecutive samples
  int ring_count = 0;                // intervals * rings per interval + 1
  int vertex_count = 0;              // ring_count * sides, ring-major
  int index_count = 0;               // 3 per triangle
  std::vector<float> positions;      // 3 per vertex, m
  std::vector<float> normals;        // 3 per vertex, unit
  std::vector<std::uint32_t> indices;  // triangles, counter-clockwise seen from outside
  std::vector<float> skin;           // 24 per interval: A_k then B_k, 3 x 4 row-major (for GPU skinning)
};

/// The precomputed cylinder primitive of a LOD, for GPU skinning: (rings + 1) x sides vertices.
struct TubePrimitive {
  TubeLod lod;
  std::vector<float> vertices;         // 4 per vertex: cos a, sin a, t, w(t)
  std::vector<std::uint32_t> indices;  // triangles
};

struct TubeStats {
  int samples = 0;            // rings after the guard
  int flagged_segments = 0;   // c_i > flag_turn
  int extra_samples = 0;      // added by the refinement (before the guard)
  int removed_samples = 0;    // removed by the guard
  int tilted_rings = 0;       // rings whose tangent the guard turned towards a chord
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
  /// Init phase (allocates): work arrays for up to `max_points` input points. Throws surgsim::Error on bad params.
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
  /// more than max_points, non-finite input or a mesh too small.
  bool build(const double* points, int count, int lod, TubeMesh& mesh) noexcept;

  /// Results of the last build (samples after the guard, c_i per segment, counters).
  int sample_count() const { return sample_count_; }
  const TubeSample& sample(int i) const { return samples_[static_cast<std::size_t>(i)]; }
  double curvature_indicator(int segment) const { return curvature_[static_cast<std::size_t>(segment)]; }
  const TubeStats& stats() const { return stats_; }
  /// Forgets the normal carried from the previous build (the next build starts from a fixed choice).
  void reset_frames() noexcept { has_previous_normal_ = false; }

 private:
  bool sample_spline(int count) noexcept;
  void guard() noexcept;
  void skin(int lod, TubeMesh& mesh) const noexcept;

  TubeParams params_;
  int max_points_ = 0;
  std::vector<Eigen::Vector3d> points_, tangents_;
  std::vector<double> curvature_;
  std::vector<TubeSample> samples_;
  std::vector<Eigen::Vector3d> centers_, ring_tangents_, normals_, binormals_;
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
/// the layout of IntestineState::positions()). False if the mesh was made for another grid or a point is not finite.
bool mesentery_strip(const double* points, MesenteryMesh& mesh) noexcept;

}  // namespace surgsim::intestine
