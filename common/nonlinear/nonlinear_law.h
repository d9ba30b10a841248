// Quasi non-linear law of Cotin 1998, section 3.4 (docs/DESIGN.md, section 'Liver: precomputed linear elasticity', last
// bullet): the linear-elastic result of the precomputed tensors is bent onto measured (or hyperelastically computed)
// curves of a reference cylinder under axial compression. Two polynomials, fitted by least squares from curve files:
//   P maps the linear radial displacement d_r^L = nu r x / h onto the curve d_r(x)  (m -> m),
//   Q maps the linear axial force        f^L   = s E x / h  onto the curve f(x)    (N -> N),
// with r, h, s = pi r^2, E, nu those of the cylinder the curves describe (stated in each file's header).
// At run time each node's displacement u is split along the constraint direction d into (u.d) d and u_r; |u_r| is
// replaced by P(|u_r|), its direction kept. A force f has its collinear amplitude |f.d| replaced by Q(|f.d|), its
// sign and its orthogonal part kept.
//
// Curve files (CSV, '#' comment lines, then a column header and x,value rows):
//   # any comment (model, parameters, the command that produced the file)
//   # cylinder: radius=0.025, height=0.1, young=3000, poisson=0.45      (m, m, Pa, -; exactly once)
//   x,d_r                        (or x,f for a force curve)
//   0,0
//   0.001,1.1327e-04             (x: imposed compression of the top, m, >= 0, strictly increasing, < height;
//   ...                           d_r: outward radial displacement of the lateral surface, m; f: axial force, N)
// Any other line is an error "FILE:LINE: what is wrong (fix)". Blank lines are ignored.
//
// Fit (init phase): the argument t (the linear prediction) is scaled to z = 2 t / t_max - 1 in [-1, 1] and the basis
// is phi_k(z) = T_k(z) - T_k(-1), k = 1..degree (Chebyshev polynomials shifted to vanish at t = 0): P(0) = 0 and
// Q(0) = 0 hold exactly because there is no constant term, and the basis stays well conditioned up to degree 10.
// Solved by column-pivoting Householder QR. Residuals are reported relative to the curve's range (max - min value).
//
// Evaluation (run phase): inside [0, t_max] the polynomial (Clenshaw); beyond t_max the tangent line at t_max
// (linear extrapolation with the end slope, never the polynomial's blow-up); for t < 0 the odd extension -P(-t)
// (amplitudes are never negative; this only keeps the map monotone through 0).
//
// How the nodes use it (run phase, no allocation; `law` is built once in init with load_nonlinear_law):
//   haptic node, after Superposition::solve(contacts, m, sol) returned kOk with sol.count > 0:
//       Eigen::Vector3d d;
//       if (surgsim::nonlinear::constraint_direction(sol.displacement.data(), sol.count, d))
//         law.apply_force(sol.tool_force, d, sol.tool_force);   // Q on the collinear part; aliasing is allowed
//     (d = normalized sum of the imposed displacements u*; a false return from either call leaves tool_force as
//     it was: count it as a fault, the value is still the finite linear force.)
//   visual node, after Superposition::displacements(nodes, lambda, m, u) filled u (3R, row r of the "visual" block
//   at 3r..3r+2): the imposed displacements u*_l are the rows of the contact nodes themselves (every contact node is
//   a boundary node, hence a visual row), so
//       Eigen::Vector3d sum = Eigen::Vector3d::Zero();
//       for (int l = 0; l < m; ++l) sum += u.segment<3>(3 * block.row_of_node[nodes[l]]);
//       Eigen::Vector3d d;
//       // P on every row, in place:
//       if (surgsim::nonlinear::constraint_direction(&sum, 1, d)) law.apply_displacements(u, d);
//     Contact nodes are transformed too: for a push along d their u_r is zero and they stay at u*; when the imposed
//     displacements are not all along d, P moves them off u* by P(|u_r|) - |u_r| (skip their rows if the drawn
//     surface must stay on the tool).
// Both calls return true without touching their input when the law has no curve for them (identity).
#pragma once
#include <Eigen/Core>
#include <array>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "fem/material.h"

namespace surgsim::nonlinear {

/// Quasi non-linear law (paper section 3.4): curve files and polynomial degree. Empty files: linear only.
struct NonlinearSpec {
  std::string displacement_curve;  // absolute path, CSV x,d_r (m) or empty
  std::string force_curve;         // absolute path, CSV x,f (m, N) or empty
  int degree = 6;                  // 4..10
  bool enabled() const { return !displacement_curve.empty() || !force_curve.empty(); }
};

/// Polynomial degrees the fit accepts (inclusive).
inline constexpr int kMinLawDegree = 4;
inline constexpr int kMaxLawDegree = 10;

/// The reference cylinder a curve describes (header line "# cylinder: radius=..., height=..., young=..., poisson=...").
struct CylinderReference {
  double radius = 0.025;          // m, > 0
  double height = 0.10;           // m, > 0
  double young_modulus = 3000.0;  // Pa, > 0
  double poisson_ratio = 0.45;    // [0, 0.5)

  double area() const;                   // m^2, pi r^2: the top (and cross-section) area s
  double linear_radial(double x) const;  // m, d_r^L = nu r x / h for a compression x (m)
  double linear_force(double x) const;   // N, f^L = s E x / h
};

enum class CurveQuantity {
  kRadialDisplacement,  // column header "x,d_r": outward radial displacement of the lateral surface, m
  kForce,               // column header "x,f": axial force on the top, N
};
const char* to_string(CurveQuantity quantity);

/// One curve file, validated.
struct Curve {
  std::string source;  // file path (or the name given to read_curve), for messages
  CurveQuantity quantity = CurveQuantity::kRadialDisplacement;
  CylinderReference cylinder;
  int header_line = 0;     // 1-based line of the column header
  std::vector<int> lines;  // #points: 1-based source line of each point
  Eigen::VectorXd x;       // #points, m: imposed compression, >= 0, strictly increasing, < height
  Eigen::VectorXd value;   // #points, m (d_r) or N (f)

  int size() const { return static_cast<int>(x.size()); }
  /// #points: the linear prediction at each x (d_r^L in m, or f^L in N).
  Eigen::VectorXd linear() const;
};

/// Parses a curve from a stream; `source` names it in messages. Throws surgsim::core::Error "SOURCE:LINE: ..." (or
/// "SOURCE: ..." for what has no line: no cylinder header, no data).
Curve read_curve(std::istream& in, const std::string& source);
/// Opens and parses `path`. Throws surgsim::core::Error (also when the file cannot be opened).
Curve load_curve(const std::string& path);

/// How well a polynomial fits its curve.
struct FitReport {
  int degree = 0;
  int points = 0;
  double range = 0;         // max - min of the fitted values (m or N)
  double rms_residual = 0;  // sqrt(mean (P(t_i) - y_i)^2) / range
  double max_residual = 0;  // max |P(t_i) - y_i| / range
  int worst_line = 0;       // source line of the worst point (0 when unknown)
  double t_max = 0;         // end of the fitted range of the argument (m or N)
  double end_value = 0;     // P(t_max)
  double end_slope = 0;     // P'(t_max): the slope of the linear extrapolation beyond t_max
  double start_slope = 0;   // P'(0): 1 when the curve has the linear law as its small-strain limit
  bool increasing = false;  // P strictly increasing on [0, t_max] (checked on 2001 points) and end_slope > 0
};

/// y = P(t) with P(0) = 0: the shifted-Chebyshev polynomial of the fit inside [0, t_max], its tangent beyond, odd
/// for t < 0. Fixed size: copying and evaluating never allocates.
class PolynomialMap {
 public:
  /// The identity map (degree 1: P(t) = t exactly, for any t).
  PolynomialMap();

  /// Least-squares fit of y_i ~ P(t_i), degree kMinLawDegree..kMaxLawDegree. t must be finite and >= 0 with
  /// max t > 0, y finite, at least degree + 1 distinct t. `lines` (optional, same size) names points in the report.
  /// Throws surgsim::core::Error prefixed by `source` (e.g. the curve file) with the reason.
  static PolynomialMap fit(const Eigen::VectorXd& t, const Eigen::VectorXd& y, int degree, const std::string& source,
                           FitReport* report = nullptr, const std::vector<int>* lines = nullptr);

  double operator()(double t) const noexcept;
  /// dP/dt (continuous at t_max: the end slope beyond).
  double derivative(double t) const noexcept;

  int degree() const { return degree_; }
  double t_max() const { return t_max_; }
  /// Chebyshev coefficients c_1..c_degree of P(t) = sum_k c_k (T_k(2 t / t_max - 1) - T_k(-1)).
  const std::array<double, kMaxLawDegree + 1>& coefficients() const { return c_; }

 private:
  double inside(double t) const noexcept;  // the polynomial, for 0 <= t <= t_max
  double inside_derivative(double t) const noexcept;

  int degree_ = 1;
  double t_max_ = 1;
  double offset_ = 0;                          // sum_k c_k T_k(-1), so that P(0) = 0
  double end_value_ = 1, end_slope_ = 1;       // P(t_max), P'(t_max)
  std::array<double, kMaxLawDegree + 1> c_{};  // c_[0] unused (0)
};

/// A curve and the polynomial fitted from its linear prediction to its values.
struct CurveFit {
  Curve curve;
  PolynomialMap map;  // P (radial displacement) or Q (force)
  FitReport report;
};

/// Fits P or Q (by curve.quantity) of `degree` from the curve mapped through the cylinder's linear relation.
/// Throws surgsim::core::Error "SOURCE: ..." for a bad degree, too few points (< degree + 1), poisson = 0 for a radial
/// curve (d_r^L would be identically 0) or a constant curve.
CurveFit fit_curve(const Curve& curve, int degree);

/// Homogeneous uniaxial compression of a compressible neo-Hookean cylinder with a traction-free lateral surface,
/// W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 with mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu))
/// (the small-strain match to E, nu). Axial stretch l = 1 - x / h; lateral stretch l_t from zero lateral Cauchy stress,
/// mu (l_t^2 - 1) + lambda ln(l l_t^2) = 0 (Newton); d_r = r (l_t - 1) (outward positive); the force is the axial
/// nominal (first Piola-Kirchhoff) stress times the reference area: f = |P_11| s, P_11 = (mu (l^2 - 1) + lambda ln J)
/// / l, J = l l_t^2. For small x: d_r -> nu r x / h and f -> s E x / h, the linear relations.
struct NeoHookeanPoint {
  double x = 0;                // m, imposed compression
  double lateral_stretch = 1;  // l_t
  double radial = 0;           // m, d_r
  double force = 0;            // N, f
};
/// Throws surgsim::core::Error for 0 > x or x >= height, or a bad cylinder.
NeoHookeanPoint neo_hookean_compression(const CylinderReference& cylinder, double x);

/// Throws surgsim::core::Error "WHERE: ..." unless radius, height, young > 0 (finite) and 0 <= poisson < 0.5.
void check_cylinder(const CylinderReference& cylinder, const std::string& where);

/// d = (sum of the m vectors) / |sum|: the constraint direction of the law (the mean imposed displacement
/// direction). Run phase: noexcept, no allocation. False (d untouched) when m <= 0, a vector is not finite or the
/// sum is (numerically) zero.
bool constraint_direction(const Eigen::Vector3d* imposed, int m, Eigen::Vector3d& direction) noexcept;

/// The organ's force ratio over its surface (fitted by nonlinear/organ_curves.h): a push of depth delta along d on a
/// patch of surface nodes feels the linear force times
///   ratio = [1 + sum_k (a_k + b_k L / h) e^k] * residual(c, delta),   e = delta / h,
/// with h and L the means over the patch nodes of each node's thickness along its inward normal and its distance to
/// the nearest fixed node (m), and residual the regression's own error at the fit sites (Newton / (linear x
/// regression), at each fit depth), interpolated to the patch's rest centroid c by inverse distance to the power
/// kPower (so a fit site's own punch gets its own residual back), 1 at delta = 0, linear in delta between the fit
/// depths and held beyond the last. Beyond e_max the polynomial continues along its tangent; the ratio is kept in
/// [kMinRatio, kMaxRatio]. Only a push has it: when the direction is not within 60 degrees of the patch's inward
/// normal (the mean of its nodes' unit normals; a pull, a lift, a drag along the surface) the ratio is 1, the linear
/// force, as the field was fitted on pushes straight down on top nodes whose normals are within 60 degrees of up.
struct SurfaceForceField {
  static constexpr double kMinRatio = 0.1;
  static constexpr double kMaxRatio = 10.0;
  static constexpr double kPower = 4;
  static constexpr double kPushCosine = 0.5;       // cos 60 degrees
  int degree = 0;                                  // K, 1..kMaxLawDegree (0: an empty field)
  std::array<double, kMaxLawDegree + 1> a{}, b{};  // a_k, b_k for k = 1..K (index 0 unused)
  double e_max = 0;                                // end of the fitted range of e
  std::vector<double> thickness;                   // #V, m (0 off the surface: such nodes are skipped)
  std::vector<double> lever;                       // #V, m
  std::vector<Eigen::Vector3d> position;           // #V, m, rest positions
  std::vector<Eigen::Vector3d> normal;             // #V, unit outward normals at rest (0 off the surface)
  std::vector<double> depths;                      // J fit depths, m, ascending, > 0
  std::vector<Eigen::Vector3d> site_centre;        // S, m: rest centroid of each fit site's punch
  std::vector<double> site_residual;               // S x J (site-major)

  bool empty() const { return degree == 0; }
  int node_count() const { return static_cast<int>(thickness.size()); }
  /// The regression part for a mean thickness h and lever (m) at depth delta (m).
  double regression(double delta, double h, double lever_m) const noexcept;
  /// The interpolated residual at rest point c, depth delta (m).
  double residual_at(const Eigen::Vector3d& c, double delta) const noexcept;
  /// The ratio of a patch: nodes[0..m) (nodes outside 0..node_count() or off the surface are skipped), pushed along
  /// the unit `direction` by delta >= 0 (m). 1 when no node is usable or the direction is not a push. Run phase, no
  /// allocation.
  double ratio(const int* nodes, int m, const Eigen::Vector3d& direction, double delta) const noexcept;
};

/// P and Q of a scene. Immutable after construction; the const run-phase members may be called from any thread.
class NonlinearLaw {
 public:
  /// The identity law: linear elasticity unchanged.
  NonlinearLaw() = default;
  /// Either may be absent (that part stays linear). Throws surgsim::core::Error when a fit is not increasing, or a fit
  /// of the wrong quantity is given.
  NonlinearLaw(std::optional<CurveFit> displacement, std::optional<CurveFit> force);
  /// With the organ's surface field: apply_force with the contact nodes uses it instead of Q (Q stays the fallback
  /// of the node-less apply_force). Throws surgsim::core::Error for a field whose sizes do not match.
  NonlinearLaw(std::optional<CurveFit> displacement, std::optional<CurveFit> force, SurfaceForceField field);

  bool identity() const { return !displacement_ && !force_ && field_.empty(); }
  const SurfaceForceField& surface_field() const { return field_; }
  const std::optional<CurveFit>& displacement_fit() const { return displacement_; }
  const std::optional<CurveFit>& force_fit() const { return force_; }

  /// P and Q on amplitudes (m -> m, N -> N); the identity where the law has no curve. Run phase.
  double p(double radial) const noexcept { return displacement_ ? displacement_->map(radial) : radial; }
  double q(double force) const noexcept { return force_ ? force_->map(force) : force; }

  /// Run phase, no allocation: out = (u.d) d + P(|u_r|) u_r / |u_r| with u_r = u - (u.d) d. `direction` is any
  /// finite non-zero vector (normalized here). Non-finite u or a bad direction: out = u, false. out may alias u.
  bool apply_displacement(const Eigen::Vector3d& u, const Eigen::Vector3d& direction,
                          Eigen::Vector3d& out) const noexcept;
  /// Run phase, no allocation: apply_displacement to each node of u (3n entries, node i at 3i..3i+2), in place.
  /// False when u.size() is not a multiple of 3, the direction is bad (u untouched) or some node is not finite
  /// (that node untouched, the others transformed).
  bool apply_displacements(Eigen::Ref<Eigen::VectorXd> u, const Eigen::Vector3d& direction) const noexcept;
  /// Run phase, no allocation: out = f_r + sign(f.d) Q(|f.d|) d with f_r = f - (f.d) d. Non-finite f or a bad
  /// direction: out = f, false. out may alias f.
  bool apply_force(const Eigen::Vector3d& f, const Eigen::Vector3d& direction, Eigen::Vector3d& out) const noexcept;
  /// Run phase, no allocation: as above, with the contact nodes `nodes[l]` and their imposed displacements
  /// `imposed[l]` (l < m). With a surface field: out = f_r + ratio (f.d) d, ratio = field.ratio(nodes, m, d, delta),
  /// delta = |mean of imposed[l].d|; without one (or m <= 0): the node-less apply_force (Q).
  bool apply_force(const Eigen::Vector3d& f, const Eigen::Vector3d& direction, const int* nodes,
                   const Eigen::Vector3d* imposed, int m, Eigen::Vector3d& out) const noexcept;

 private:
  std::optional<CurveFit> displacement_;
  std::optional<CurveFit> force_;
  SurfaceForceField field_;
};

/// The scene's law: each named curve loaded, checked for its column (x,d_r for displacement_curve, x,f for
/// force_curve), fitted with spec.degree and required to be increasing. An empty spec gives the identity law.
/// Throws surgsim::core::Error naming the curve file.
NonlinearLaw load_nonlinear_law(const NonlinearSpec& spec);
/// As above, and refuses curves made for another Young's modulus or Poisson ratio than the scene's `material`
/// (relative difference > 1e-9): their linear input would not be the linear model the scene computes.
NonlinearLaw load_nonlinear_law(const NonlinearSpec& spec, const fem::Material& material);

}  // namespace surgsim::nonlinear
