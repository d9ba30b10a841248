// Curves for the organ, not for a cylinder (issue 16, part 2). The paper's quasi non-linear law (nonlinear_law.h)
// bends the linear result onto curves "for the organ we consider"; the shipped curves come from a neo-Hookean
// cylinder, and Q fitted on them is extrapolated beyond 15 % indentation. Here the organ's own mesh is indented with
// the neo-Hookean Newton solver (hyperelastic.h) at a few sites and depths, and the same indentations are solved
// linearly (StaticSolver, the model the tensors hold); then
//   Q maps the linear tool force along the push,          |F_lin . d|  ->  |F_newton . d|   (N -> N),
//   P maps the largest radial (orthogonal to the push) displacement of a boundary node, linear -> Newton  (m -> m),
// both fitted by PolynomialMap::fit (shifted Chebyshev, P(0) = 0) over every site and depth together. The scenes'
// law (load_organ_law) has Q alone: P fitted on the largest bulge and applied to every node's own radial amplitude
// made the visible surface worse than the linear one at every depth in large_deformation_bench (7.1 against 2.4 %
// at 5 % indentation on the shipped liver); fit_organ_law(..., fit_p = true) keeps it (when increasing) for study.
//
// The samples are cached in their own file next to the tensors, <cache_dir>/organ-curves-<key hex>.csv, keyed by the
// tensors' key (mesh, material, fixed set, solver settings) combined with the settings here: a new material (or
// mesh, fixed set, sites, depths, degree) gives another key, so the old file is never read for it. The file repeats
// its key and a checksum of its rows; a file that does not match is recomputed and rewritten (atomically: temp file,
// rename). Init phase only (allocates, minutes of Newton on first use).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "liver/fem.h"
#include "liver/nonlinear_law.h"

namespace surgsim {

struct OrganCurveSettings {
  // Punch sites: x-y (m) of the punch centres on the organ's top surface (free boundary nodes with an upward normal
  // within punch_radius of the centre are pushed straight down, every component imposed).
  std::vector<Eigen::Vector2d> sites = {{0.03, 0.0}, {-0.04, 0.02}, {0.07, -0.02}};
  double punch_radius = 0.02;                                       // m
  std::vector<double> depths = {0.05, 0.10, 0.15, 0.20, 0.25, 0.30};  // fraction of the organ's z extent
  int degree = 4;                                                   // of P and Q, kMinLawDegree..kMaxLawDegree
  double newton_increment = 0.002;                                  // m of depth per Newton load step
  std::uint64_t hash() const;
};

/// One indentation: the organ's response, linear and Newton.
struct OrganCurveSample {
  double site_x = 0, site_y = 0;  // m
  double depth = 0;               // m
  int nodes = 0;                  // punch nodes
  double linear_force = 0;        // N, |F . d| of the linear solve (d = -z, the push)
  double newton_force = 0;        // N, the same of the Newton solve
  double linear_radial = 0;       // m, largest |u_r| of a boundary node, linear
  double newton_radial = 0;       // m, the same, Newton
  bool converged = true;          // Newton reached the full depth
};

struct OrganCurves {
  std::uint64_t key = 0;
  std::vector<OrganCurveSample> samples;
};

/// The punch nodes of a site: free boundary nodes whose area-weighted normal points up (z > 0.5) within `radius` of
/// `centre` in x-y. Ascending.
std::vector<int> organ_punch_nodes(const ElasticModel& model, const Eigen::Vector2d& centre, double radius);

/// Indents the model at every site and depth, linear and Newton (progress on `log`). Throws surgsim::Error for a
/// site without punch nodes. Samples whose Newton solve did not converge are kept with converged = false (the fit
/// skips them).
OrganCurves compute_organ_curves(const ElasticModel& model, const OrganCurveSettings& settings, std::ostream* log);

/// Q (and with `fit_p` P, when its fit is increasing) from the converged samples. `q_report` / `p_report` receive the
/// fits (the
/// P report has degree 0 when P was left out). Throws surgsim::Error when Q cannot be fitted.
NonlinearLaw fit_organ_law(const OrganCurves& curves, int degree, FitReport* q_report = nullptr,
                           FitReport* p_report = nullptr, bool fit_p = false);

/// The cache key of a model's curves: `tensor_key` (TensorCacheKey::combined() of the scene's tensors) with the
/// settings.
std::uint64_t organ_curves_key(std::uint64_t tensor_key, const OrganCurveSettings& settings);
/// <cache_dir>/organ-curves-<key, 16 hex digits>.csv
std::string organ_curves_path(const std::string& cache_dir, std::uint64_t key);
/// Writes the samples with their key and a checksum (temp file, then rename). Throws surgsim::Error.
void save_organ_curves(const std::string& path, const OrganCurves& curves);
/// Reads a cache file; false (out untouched, `why` says what) when it is missing, for another key or damaged.
bool load_organ_curves(const std::string& path, std::uint64_t key, OrganCurves& out, std::string* why = nullptr);

enum class OrganCurvesOutcome : std::uint8_t { kLoaded, kComputed };
/// The cached samples for this key, or computes and caches them. Throws surgsim::Error.
OrganCurves load_or_compute_organ_curves(const ElasticModel& model, const OrganCurveSettings& settings,
                                         std::uint64_t tensor_key, const std::string& cache_dir, std::ostream* log,
                                         OrganCurvesOutcome* outcome = nullptr);

/// A scene's organ law (liver.curves: organ): the model of `mesh`, `material`, `fixed`, its curves loaded or computed
/// for `tensor_key` in `cache_dir`, fitted with settings.degree. Throws surgsim::Error.
NonlinearLaw load_organ_law(const TetMesh& mesh, const Material& material, const FixedSet& fixed,
                            std::uint64_t tensor_key, const std::string& cache_dir, std::ostream* log,
                            const OrganCurveSettings& settings = OrganCurveSettings());

}  // namespace surgsim
