// Curves for the organ, not for a cylinder. The paper's quasi non-linear law (nonlinear_law.h)
// bends the linear result onto curves "for the organ we consider"; the shipped curves come from a neo-Hookean
// cylinder. Here the organ's own mesh is indented with the neo-Hookean Newton solver (hyperelastic.h) and the linear
// solve (StaticSolver, the model the tensors hold) at sites spread over its free top surface, with a flat punch
// (every free top-surface node within punch_radius of the centre pushed straight down, every component imposed),
// at a few depths.
//
// One Q for the whole organ does not hold: the Newton / linear force ratio at 30 % depth ranges from 0.8 (the free
// lobe's tip, which bends) to 1.9 (thin clamped rim) over the liver's surface, and the thick dome under the scenes'
// tool has 1.21 while the old three hand-picked sites had 1.21, 1.46 and 1.36, so their common Q erred 8.9 % there.
// The law the scenes use is therefore a field over the surface (SurfaceForceField, nonlinear_law.h):
//   ratio = [1 + sum_k (a_k + b_k L / h) (delta / h)^k] * residual(centroid, delta)
// with h the node's thickness along its inward normal and L its distance to the fixed set (both per surface node,
// from the mesh alone, averaged over the contact patch): a thin or far-from-the-clamp patch stiffens or bends
// differently from a thick clamped one. a_k, b_k by least squares over every site and depth; the residual of that
// regression at each site is interpolated to other patches by inverse distance (power 4) from the site centres.
// validate_organ_law() measures it leave-one-site-out. Q (one polynomial for all sites, as before) is kept as the
// fallback of apply_force calls without contact nodes.
//
// Sites are chosen automatically (unless listed): a lattice of site_spacing over the x-y box of the free top-surface
// nodes, cell centres, keeping those whose punch has at least min_punch_nodes nodes. Each site costs one Newton
// solve carried in increments to the deepest depth (the shallower depths are read off its converged increments,
// interpolated linearly in the load factor) and one linear solve (linear forces are proportional to depth).
//
// The samples are cached in their own file next to the tensors, <cache_dir>/organ-curves-<key hex>.csv, keyed by the
// tensors' key (mesh, material, fixed set, solver settings) combined with the settings here: a new material (or
// mesh, fixed set, sites, depths, degree) gives another key, so the old file is never read for it. The file repeats
// its key and a checksum of its rows; a file that does not match is recomputed and rewritten (atomically: temp file,
// rename). Init phase only (allocates; 23-28 s of Newton for the 21 sites of the 1.4k liver on first use).
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "fem/fem.h"
#include "nonlinear/nonlinear_law.h"

namespace surgsim::nonlinear {

struct OrganCurveSettings {
  // Punch sites: x-y (m) of the punch centres on the organ's top surface. Empty: chosen automatically (above).
  std::vector<Eigen::Vector2d> sites;
  double site_spacing = 0.04;                                         // m, automatic sites
  int min_punch_nodes = 6;                                            // automatic sites
  double punch_radius = 0.02;                                         // m
  std::vector<double> depths = {0.05, 0.10, 0.15, 0.20, 0.25, 0.30};  // fraction of the organ's z extent, ascending
  int degree = 4;                                                     // of Q, kMinLawDegree..kMaxLawDegree
  int ratio_degree = 3;                                               // K of the surface field, 1..kMaxLawDegree
  double newton_increment = 0.002;                                    // m of depth per Newton load step
  std::uint64_t hash() const;
};

/// One indentation: the organ's response, linear and Newton.
struct OrganCurveSample {
  double site_x = 0, site_y = 0;                     // m, the punch centre
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // m, rest centroid of the punch nodes
  double thickness = 0;                              // m, mean thickness of the punch nodes (organ_surface_geometry)
  double lever = 0;                                  // m, mean distance of the punch nodes to the fixed set
  double depth = 0;                                  // m
  int nodes = 0;                                     // punch nodes
  double linear_force = 0;                           // N, |F . d| of the linear solve (d = -z, the push)
  double newton_force = 0;                           // N, the same of the Newton solve
  bool converged = true;                             // Newton reached this depth
};

struct OrganCurves {
  std::uint64_t key = 0;
  std::vector<OrganCurveSample> samples;
};

/// Per-node geometry of the surface field: thickness along the inward (area-weighted) normal to the first boundary
/// crossing (m; the organ's z extent when the ray finds none; 0 off the surface) and distance to the nearest node
/// with a fixed component (m; 0 without a fixed set).
struct OrganSurfaceGeometry {
  std::vector<double> thickness;        // #V
  std::vector<double> lever;            // #V
  std::vector<Eigen::Vector3d> normal;  // #V, unit outward (0 off the surface)
};
OrganSurfaceGeometry organ_surface_geometry(const mesh::TetMesh& mesh, const fem::FixedSet& fixed);

/// The punch nodes of a site: free boundary nodes whose area-weighted normal points up (z > 0.5) within `radius` of
/// `centre` in x-y. Ascending.
std::vector<int> organ_punch_nodes(const fem::ElasticModel& model, const Eigen::Vector2d& centre, double radius);

/// settings.sites, or the automatic lattice (in x then y order).
std::vector<Eigen::Vector2d> organ_curve_sites(const fem::ElasticModel& model, const OrganCurveSettings& settings);

/// Indents the model at every site and depth, linear and Newton (progress on `log`). Throws surgsim::core::Error for a
/// listed site without punch nodes or when no site is found. Depths the Newton solve did not reach are kept with
/// converged = false (the fit skips them).
OrganCurves compute_organ_curves(const fem::ElasticModel& model, const OrganCurveSettings& settings, std::ostream* log);

/// The law: Q (degree settings.degree, the node-less fallback; `q_report` receives its fit) and the surface field
/// (settings.ratio_degree) of `mesh` and `fixed` from the converged samples. Throws surgsim::core::Error when Q cannot
/// be fitted or there are too few samples for the field.
NonlinearLaw fit_organ_law(const OrganCurves& curves, const mesh::TetMesh& mesh, const fem::FixedSet& fixed,
                           const OrganCurveSettings& settings, FitReport* q_report = nullptr);

/// Leave-one-site-out cross-validation of the field: for each site, the field fitted on the other sites predicts the
/// site's Newton force at each converged depth (at its punch's mean thickness, lever and centroid).
struct OrganLawValidation {
  struct Site {
    double site_x = 0, site_y = 0;
    int nodes = 0;
    double worst = 0;    // largest |F_pred - F_newton| / F_newton over its depths, held out
    double fitted = 0;   // the same with every site in the fit
    double q_worst = 0;  // the same with the one-Q law (fitted on every site)
  };
  std::vector<Site> sites;
  double worst = 0, mean = 0;  // held out, over every site and depth
  double fitted_worst = 0;     // in sample
};
OrganLawValidation validate_organ_law(const OrganCurves& curves, const OrganCurveSettings& settings);

/// The cache key of a model's curves: `tensor_key` (TensorCacheKey::combined() of the scene's tensors) with the
/// settings.
std::uint64_t organ_curves_key(std::uint64_t tensor_key, const OrganCurveSettings& settings);
/// <cache_dir>/organ-curves-<key, 16 hex digits>.csv
std::string organ_curves_path(const std::string& cache_dir, std::uint64_t key);
/// Writes the samples with their key and a checksum (temp file, then rename). Throws surgsim::core::Error.
void save_organ_curves(const std::string& path, const OrganCurves& curves);
/// Reads a cache file; false (out untouched, `why` says what) when it is missing, for another key or damaged.
bool load_organ_curves(const std::string& path, std::uint64_t key, OrganCurves& out, std::string* why = nullptr);

enum class OrganCurvesOutcome : std::uint8_t { kLoaded, kComputed };
/// The cached samples for this key, or computes and caches them. Throws surgsim::core::Error.
OrganCurves load_or_compute_organ_curves(const fem::ElasticModel& model, const OrganCurveSettings& settings,
                                         std::uint64_t tensor_key, const std::string& cache_dir, std::ostream* log,
                                         OrganCurvesOutcome* outcome = nullptr);

/// A scene's organ law (liver.curves: organ): the model of `mesh`, `material`, `fixed`, its curves loaded or computed
/// for `tensor_key` in `cache_dir`, fitted (fit_organ_law). Throws surgsim::core::Error.
NonlinearLaw load_organ_law(const mesh::TetMesh& mesh, const fem::Material& material, const fem::FixedSet& fixed,
                            std::uint64_t tensor_key, const std::string& cache_dir, std::ostream* log,
                            const OrganCurveSettings& settings = OrganCurveSettings());

}  // namespace surgsim::nonlinear
