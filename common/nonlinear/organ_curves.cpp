#include "nonlinear/organ_curves.h"

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <ostream>
#include <sstream>

#include <unistd.h>

#include "core/error.h"
#include "fem/hyperelastic.h"
#include "fem/static_solver.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;

namespace surgsim::nonlinear {

namespace {

// FNV-1a over raw bytes.
struct Fnv {
  std::uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ c[i]) * 1099511628211ull;
  }
  template <class T>
  void value(const T& v) {
    bytes(&v, sizeof v);
  }
};

const Eigen::Vector3d kPush(0, 0, -1);  // the punch pushes straight down

std::string row_text(const OrganCurveSample& s) {
  char buf[512];
  std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%d,%.17g,%.17g,%d", s.site_x,
                s.site_y, s.centre.x(), s.centre.y(), s.centre.z(), s.thickness, s.lever, s.depth, s.nodes,
                s.linear_force, s.newton_force, s.converged ? 1 : 0);
  return buf;
}

std::uint64_t rows_checksum(const std::vector<OrganCurveSample>& samples) {
  Fnv f;
  for (const auto& s : samples) {
    const std::string r = row_text(s);
    f.bytes(r.data(), r.size());
  }
  return f.h;
}

constexpr const char* kHeader = "# surgsim organ curves v2";
constexpr const char* kColumns =
    "site_x_m,site_y_m,centre_x_m,centre_y_m,centre_z_m,thickness_m,lever_m,depth_m,nodes,linear_force_n,"
    "newton_force_n,converged";

// Area-weighted normals of the boundary nodes (#V x 3, not normalized; 0 off the surface).
Eigen::MatrixX3d surface_normals(const TetMesh& mesh, const SurfaceMesh& surface) {
  Eigen::MatrixX3d normals = Eigen::MatrixX3d::Zero(mesh.nodes.rows(), 3);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::RowVector3d a = mesh.nodes.row(surface.tris(f, 0)), b = mesh.nodes.row(surface.tris(f, 1)),
                             c = mesh.nodes.row(surface.tris(f, 2));
    const Eigen::RowVector3d n = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) normals.row(surface.tris(f, k)) += n;
  }
  return normals;
}

// Free boundary nodes whose normal points up (z > 0.5).
std::vector<int> top_nodes(const ElasticModel& model, const SurfaceMesh& surface, const Eigen::MatrixX3d& normals) {
  std::vector<int> out;
  for (int n : surface.nodes) {
    const double len = normals.row(n).norm();
    if (model.fixed.node_fully_free(n) && len > 0 && normals(n, 2) / len > 0.5) out.push_back(n);
  }
  return out;
}

// Distance along the unit ray x + t d (t > 1e-6 m) to the first boundary triangle it meets (Moller-Trumbore); +inf
// when none.
double ray_to_boundary(const TetMesh& mesh, const SurfaceMesh& surface, const Eigen::Vector3d& x,
                       const Eigen::Vector3d& d) {
  double best = std::numeric_limits<double>::infinity();
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::Vector3d a = mesh.nodes.row(surface.tris(f, 0)).transpose();
    const Eigen::Vector3d e1 = mesh.nodes.row(surface.tris(f, 1)).transpose() - a;
    const Eigen::Vector3d e2 = mesh.nodes.row(surface.tris(f, 2)).transpose() - a;
    const Eigen::Vector3d p = d.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-14) continue;
    const Eigen::Vector3d tv = x - a;
    const double u = tv.dot(p) / det;
    if (u < -1e-9 || u > 1 + 1e-9) continue;
    const Eigen::Vector3d q = tv.cross(e1);
    const double v = d.dot(q) / det;
    if (v < -1e-9 || u + v > 1 + 1e-9) continue;
    const double t = e2.dot(q) / det;
    if (t > 1e-6 && t < best) best = t;
  }
  return best;
}

// The samples of one site, in depth order (converged ones only).
struct SiteSamples {
  const OrganCurveSample* site = nullptr;  // the first sample (site data)
  std::vector<const OrganCurveSample*> converged;
};

std::vector<SiteSamples> group_sites(const OrganCurves& curves) {
  std::vector<SiteSamples> out;
  for (const auto& s : curves.samples) {
    if (out.empty() || out.back().site->site_x != s.site_x || out.back().site->site_y != s.site_y)
      out.push_back(SiteSamples{&s, {}});
    if (s.converged && s.linear_force > 0 && s.newton_force > 0 && s.thickness > 0) out.back().converged.push_back(&s);
  }
  return out;
}

// The model part of the field (degree, a, b, e_max, depths, site centres and residuals) from the sites in `use`.
SurfaceForceField fit_field_model(const std::vector<SiteSamples>& sites, const std::vector<bool>& use,
                                  const std::vector<double>& depths, int degree) {
  if (degree < 1 || degree > kMaxLawDegree)
    throw_error("organ curves: ratio_degree ", degree, " is outside 1..", kMaxLawDegree);
  std::vector<const OrganCurveSample*> rows;
  double lam_min = std::numeric_limits<double>::infinity(), lam_max = -lam_min;
  for (std::size_t i = 0; i < sites.size(); ++i) {
    if (!use[i]) continue;
    for (const OrganCurveSample* s : sites[i].converged) {
      rows.push_back(s);
      lam_min = std::min(lam_min, s->lever / s->thickness);
      lam_max = std::max(lam_max, s->lever / s->thickness);
    }
  }
  // The lever terms only when the sites differ in L / h (one site alone cannot tell them from the a_k).
  const bool with_lever = lam_max - lam_min > 1e-6 * std::max(1.0, std::abs(lam_max));
  const int cols = with_lever ? 2 * degree : degree;
  const auto n = static_cast<Eigen::Index>(rows.size());
  if (n < cols)
    throw_error("organ curves: ", n, " converged indentations, the surface field of degree ", degree, " needs ", cols,
                " (add sites or depths, or lower ratio_degree)");
  Eigen::MatrixXd a(n, cols);
  Eigen::VectorXd y(n);
  SurfaceForceField field;
  field.degree = degree;
  for (Eigen::Index i = 0; i < n; ++i) {
    const OrganCurveSample& s = *rows[static_cast<std::size_t>(i)];
    const double e = s.depth / s.thickness, lam = s.lever / s.thickness;
    field.e_max = std::max(field.e_max, e);
    double p = 1;
    for (int k = 1; k <= degree; ++k) {
      p *= e;
      a(i, k - 1) = p;
      if (with_lever) a(i, degree + k - 1) = lam * p;
    }
    y[i] = s.newton_force / s.linear_force - 1;
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
  if (qr.rank() < cols)
    throw_error("organ curves: the indentations determine only ", qr.rank(), " of the ", cols,
                " coefficients of the surface field (add sites or depths, or lower ratio_degree)");
  const Eigen::VectorXd c = qr.solve(y);
  for (int k = 1; k <= degree; ++k) {
    field.a[static_cast<std::size_t>(k)] = c[k - 1];
    field.b[static_cast<std::size_t>(k)] = with_lever ? c[degree + k - 1] : 0.0;
  }
  // Each site's residual at every fit depth (a depth it did not reach keeps the previous one, 1 before any).
  field.depths = depths;
  for (std::size_t i = 0; i < sites.size(); ++i) {
    if (!use[i]) continue;
    const OrganCurveSample& site = *sites[i].site;
    field.site_centre.push_back(site.centre);
    double last = 1;
    for (double depth : depths) {
      for (const OrganCurveSample* s : sites[i].converged)
        if (std::abs(s->depth - depth) <= 1e-12 * depth)
          last = s->newton_force / (s->linear_force * field.regression(depth, s->thickness, s->lever));
      field.site_residual.push_back(last);
    }
  }
  return field;
}

// The depths (m) of the samples: those of the first site, in order.
std::vector<double> sample_depths(const OrganCurves& curves) {
  std::vector<double> out;
  for (const auto& s : curves.samples) {
    if (!out.empty() && (s.site_x != curves.samples.front().site_x || s.site_y != curves.samples.front().site_y)) break;
    out.push_back(s.depth);
  }
  return out;
}

double predicted_ratio(const SurfaceForceField& field, const OrganCurveSample& s) {
  return std::clamp(field.regression(s.depth, s.thickness, s.lever) * field.residual_at(s.centre, s.depth),
                    SurfaceForceField::kMinRatio, SurfaceForceField::kMaxRatio);
}

}  // namespace

std::uint64_t OrganCurveSettings::hash() const {
  Fnv f;
  f.value(sites.size());
  for (const auto& s : sites) {
    f.value(s.x());
    f.value(s.y());
  }
  f.value(site_spacing);
  f.value(min_punch_nodes);
  f.value(punch_radius);
  f.value(depths.size());
  for (double d : depths) f.value(d);
  f.value(degree);
  f.value(ratio_degree);
  f.value(newton_increment);
  return f.h;
}

OrganSurfaceGeometry organ_surface_geometry(const TetMesh& mesh, const FixedSet& fixed) {
  const SurfaceMesh surface = boundary_surface(mesh);
  const Eigen::MatrixX3d normals = surface_normals(mesh, surface);
  const auto nv = static_cast<std::size_t>(mesh.nodes.rows());
  const double height = mesh.nodes.col(2).maxCoeff() - mesh.nodes.col(2).minCoeff();
  OrganSurfaceGeometry g;
  g.thickness.assign(nv, 0.0);
  g.lever.assign(nv, 0.0);
  g.normal.assign(nv, Eigen::Vector3d::Zero());
  std::vector<int> fixed_nodes;
  for (Eigen::Index n = 0; n < mesh.nodes.rows(); ++n)
    if (fixed.node_touched(static_cast<int>(n))) fixed_nodes.push_back(static_cast<int>(n));
  for (int n : surface.nodes) {
    const double len = normals.row(n).norm();
    if (!(len > 0)) continue;
    const Eigen::Vector3d x = mesh.nodes.row(n).transpose();
    g.normal[static_cast<std::size_t>(n)] = normals.row(n).transpose() / len;
    const double t = ray_to_boundary(mesh, surface, x, -g.normal[static_cast<std::size_t>(n)]);
    g.thickness[static_cast<std::size_t>(n)] = std::isfinite(t) ? t : height;
    double best = fixed_nodes.empty() ? 0.0 : std::numeric_limits<double>::infinity();
    for (int k : fixed_nodes) best = std::min(best, (mesh.nodes.row(k) - mesh.nodes.row(n)).norm());
    g.lever[static_cast<std::size_t>(n)] = best;
  }
  return g;
}

std::vector<int> organ_punch_nodes(const ElasticModel& model, const Eigen::Vector2d& centre, double radius) {
  const TetMesh& mesh = *model.mesh;
  const SurfaceMesh surface = boundary_surface(mesh);
  std::vector<int> out;
  for (int n : top_nodes(model, surface, surface_normals(mesh, surface)))
    if ((mesh.nodes.row(n).head<2>().transpose() - centre).norm() <= radius) out.push_back(n);
  return out;
}

std::vector<Eigen::Vector2d> organ_curve_sites(const ElasticModel& model, const OrganCurveSettings& settings) {
  if (!settings.sites.empty()) return settings.sites;
  if (!(settings.site_spacing > 0)) throw_error("organ curves: site_spacing ", settings.site_spacing, " m must be > 0");
  const TetMesh& mesh = *model.mesh;
  const SurfaceMesh surface = boundary_surface(mesh);
  const std::vector<int> top = top_nodes(model, surface, surface_normals(mesh, surface));
  std::vector<Eigen::Vector2d> out;
  if (top.empty()) return out;
  Eigen::Vector2d lo = mesh.nodes.row(top[0]).head<2>().transpose(), hi = lo;
  for (int n : top) {
    lo = lo.cwiseMin(mesh.nodes.row(n).head<2>().transpose());
    hi = hi.cwiseMax(mesh.nodes.row(n).head<2>().transpose());
  }
  const double h = settings.site_spacing;
  for (double x = lo.x() + h / 2; x <= hi.x(); x += h) {
    for (double y = lo.y() + h / 2; y <= hi.y(); y += h) {
      const Eigen::Vector2d c(x, y);
      int count = 0;
      for (int n : top)
        if ((mesh.nodes.row(n).head<2>().transpose() - c).norm() <= settings.punch_radius) ++count;
      if (count >= settings.min_punch_nodes) out.push_back(c);
    }
  }
  return out;
}

OrganCurves compute_organ_curves(const ElasticModel& model, const OrganCurveSettings& settings, std::ostream* log) {
  const TetMesh& mesh = *model.mesh;
  const double height = mesh.nodes.col(2).maxCoeff() - mesh.nodes.col(2).minCoeff();
  if (settings.depths.empty()) throw_error("organ curves: no depths");
  for (std::size_t j = 0; j < settings.depths.size(); ++j)
    if (!(settings.depths[j] > 0) || (j > 0 && !(settings.depths[j] > settings.depths[j - 1])))
      throw_error("organ curves: depths must be > 0 and ascending (depth ", j + 1, " is ", settings.depths[j], ")");
  const std::vector<Eigen::Vector2d> sites = organ_curve_sites(model, settings);
  if (sites.empty())
    throw_error("organ curves: no site on the organ's top with ", settings.min_punch_nodes, " free nodes within ",
                settings.punch_radius, " m (lower min_punch_nodes or site_spacing)");
  const OrganSurfaceGeometry geometry = organ_surface_geometry(mesh, model.fixed);
  StaticSolver linear(model);
  OrganCurves out;
  const double deepest = settings.depths.back() * height;
  const auto start = std::chrono::steady_clock::now();
  for (std::size_t si = 0; si < sites.size(); ++si) {
    const Eigen::Vector2d& site = sites[si];
    const std::vector<int> punch = organ_punch_nodes(model, site, settings.punch_radius);
    if (punch.empty())
      throw_error("organ curves: no free top-surface node within ", settings.punch_radius, " m of (", site.x(), ", ",
                  site.y(), "): move the site onto the organ's top");
    OrganCurveSample base;
    base.site_x = site.x();
    base.site_y = site.y();
    base.nodes = static_cast<int>(punch.size());
    for (int k : punch) {
      base.centre += mesh.nodes.row(k).transpose();
      base.thickness += geometry.thickness[static_cast<std::size_t>(k)];
      base.lever += geometry.lever[static_cast<std::size_t>(k)];
    }
    base.centre /= static_cast<double>(punch.size());
    base.thickness /= static_cast<double>(punch.size());
    base.lever /= static_cast<double>(punch.size());
    std::vector<ImposedDisplacement> imposed;
    for (int k : punch) imposed.push_back({k, deepest * kPush, 7});
    // Linear: proportional to the depth.
    const double linear_per_m = std::abs(linear.solve(imposed).total_reaction.dot(kPush)) / deepest;
    // Newton: one solve in increments to the deepest depth; the converged increments give the force on the way.
    HyperelasticOptions opts;
    opts.load_steps = std::max(2, static_cast<int>(std::ceil(deepest / settings.newton_increment)));
    if (log)
      *log << "organ curves: site " << si + 1 << "/" << sites.size() << " (" << site.x() << ", " << site.y() << "), "
           << punch.size() << " nodes: Newton to " << deepest * 1000 << " mm in " << opts.load_steps << " increments"
           << std::endl;
    const HyperelasticSolution ref = HyperelasticSolver(model, opts).solve(imposed);
    std::vector<std::pair<double, double>> path{{0.0, 0.0}};  // (depth m, force N) of the converged increments
    for (const HyperelasticStep& step : ref.steps)
      if (step.converged && step.load_factor * deepest > path.back().first)
        path.emplace_back(step.load_factor * deepest, std::abs(step.total_reaction.dot(kPush)));
    for (double fraction : settings.depths) {
      OrganCurveSample s = base;
      s.depth = fraction * height;
      s.linear_force = linear_per_m * s.depth;
      s.converged = s.depth <= path.back().first * (1 + 1e-12);
      for (std::size_t k = 1; k < path.size() && s.converged; ++k) {
        if (path[k].first + 1e-15 < s.depth) continue;
        const double w = (s.depth - path[k - 1].first) / (path[k].first - path[k - 1].first);
        s.newton_force = path[k - 1].second + w * (path[k].second - path[k - 1].second);
        break;
      }
      out.samples.push_back(s);
    }
  }
  if (log)
    *log << "organ curves: " << sites.size() << " sites in "
         << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s" << std::endl;
  return out;
}

NonlinearLaw fit_organ_law(const OrganCurves& curves, const TetMesh& mesh, const FixedSet& fixed,
                           const OrganCurveSettings& settings, FitReport* q_report) {
  std::vector<const OrganCurveSample*> ok;
  for (const auto& s : curves.samples)
    if (s.converged) ok.push_back(&s);
  const auto n = static_cast<Eigen::Index>(ok.size());
  Eigen::VectorXd lf(n), nf(n), depth(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const OrganCurveSample& s = *ok[static_cast<std::size_t>(i)];
    lf[i] = s.linear_force;
    nf[i] = s.newton_force;
    depth[i] = s.depth;
  }
  // Q as a CurveFit (the law's type): x is the indentation depth, the value the Newton force.
  CurveFit q;
  q.curve.source = "organ curves (force)";
  q.curve.quantity = CurveQuantity::kForce;
  q.curve.x = depth;
  q.curve.value = nf;
  q.map = PolynomialMap::fit(lf, nf, settings.degree, q.curve.source, &q.report);
  if (q_report) *q_report = q.report;
  if (!q.report.increasing)
    throw_error("organ curves: the fitted Q is not increasing (degree ", settings.degree, "): lower the degree");

  const std::vector<SiteSamples> sites = group_sites(curves);
  SurfaceForceField field =
      fit_field_model(sites, std::vector<bool>(sites.size(), true), sample_depths(curves), settings.ratio_degree);
  OrganSurfaceGeometry g = organ_surface_geometry(mesh, fixed);
  field.thickness = std::move(g.thickness);
  field.lever = std::move(g.lever);
  field.normal = std::move(g.normal);
  field.position.resize(static_cast<std::size_t>(mesh.nodes.rows()));
  for (Eigen::Index k = 0; k < mesh.nodes.rows(); ++k)
    field.position[static_cast<std::size_t>(k)] = mesh.nodes.row(k).transpose();
  return NonlinearLaw(std::nullopt, std::move(q), std::move(field));
}

OrganLawValidation validate_organ_law(const OrganCurves& curves, const OrganCurveSettings& settings) {
  const std::vector<SiteSamples> sites = group_sites(curves);
  const std::vector<double> depths = sample_depths(curves);
  OrganLawValidation v;
  const SurfaceForceField all =
      fit_field_model(sites, std::vector<bool>(sites.size(), true), depths, settings.ratio_degree);
  std::vector<const OrganCurveSample*> ok;
  for (const auto& s : curves.samples)
    if (s.converged) ok.push_back(&s);
  Eigen::VectorXd lf(static_cast<Eigen::Index>(ok.size())), nf(lf.size());
  for (Eigen::Index i = 0; i < lf.size(); ++i) {
    lf[i] = ok[static_cast<std::size_t>(i)]->linear_force;
    nf[i] = ok[static_cast<std::size_t>(i)]->newton_force;
  }
  const PolynomialMap q = PolynomialMap::fit(lf, nf, settings.degree, "organ curves (force)");
  double sum = 0;
  int count = 0;
  for (std::size_t i = 0; i < sites.size(); ++i) {
    OrganLawValidation::Site r;
    r.site_x = sites[i].site->site_x;
    r.site_y = sites[i].site->site_y;
    r.nodes = sites[i].site->nodes;
    std::vector<bool> use(sites.size(), true);
    use[i] = false;
    const SurfaceForceField held = fit_field_model(sites, use, depths, settings.ratio_degree);
    for (const OrganCurveSample* s : sites[i].converged) {
      const double err = std::abs(s->linear_force * predicted_ratio(held, *s) - s->newton_force) / s->newton_force;
      const double fit = std::abs(s->linear_force * predicted_ratio(all, *s) - s->newton_force) / s->newton_force;
      r.worst = std::max(r.worst, err);
      r.fitted = std::max(r.fitted, fit);
      r.q_worst = std::max(r.q_worst, std::abs(q(s->linear_force) - s->newton_force) / s->newton_force);
      sum += err;
      ++count;
    }
    v.worst = std::max(v.worst, r.worst);
    v.fitted_worst = std::max(v.fitted_worst, r.fitted);
    v.sites.push_back(r);
  }
  v.mean = count > 0 ? sum / count : 0;
  return v;
}

std::uint64_t organ_curves_key(std::uint64_t tensor_key, const OrganCurveSettings& settings) {
  Fnv f;
  f.value(tensor_key);
  f.value(settings.hash());
  return f.h;
}

std::string organ_curves_path(const std::string& cache_dir, std::uint64_t key) {
  char name[64];
  std::snprintf(name, sizeof name, "organ-curves-%016" PRIx64 ".csv", key);
  return (std::filesystem::path(cache_dir) / name).string();
}

void save_organ_curves(const std::string& path, const OrganCurves& curves) {
  std::error_code ec;
  const std::filesystem::path p(path);
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path(), ec);
  // Per process: both nodes compute and save the same file at once on a cache miss (as save_tensor_cache).
  const std::string tmp = path + ".tmp." + std::to_string(static_cast<long>(::getpid()));
  {
    std::ofstream out(tmp);
    if (!out) throw_error(tmp, ": cannot write the organ curves (check the cache folder's permissions)");
    char line[96];
    out << kHeader << "\n";
    std::snprintf(line, sizeof line, "# key=%016" PRIx64 " rows=%zu checksum=%016" PRIx64, curves.key,
                  curves.samples.size(), rows_checksum(curves.samples));
    out << line << "\n" << kColumns << "\n";
    for (const auto& s : curves.samples) out << row_text(s) << "\n";
    if (!out) throw_error(tmp, ": write failed");
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw_error(path, ": cannot rename ", tmp, " (", ec.message(), ")");
}

bool load_organ_curves(const std::string& path, std::uint64_t key, OrganCurves& out, std::string* why) {
  const auto fail = [&](const std::string& w) {
    if (why) *why = path + ": " + w;
    return false;
  };
  std::ifstream in(path);
  if (!in) return fail("missing");
  std::string header, meta, columns;
  std::getline(in, header);
  std::getline(in, meta);
  std::getline(in, columns);
  if (header != kHeader || columns != kColumns) return fail("not an organ curves v2 file");
  std::uint64_t k = 0, sum = 0;
  std::size_t rows = 0;
  if (std::sscanf(meta.c_str(), "# key=%" SCNx64 " rows=%zu checksum=%" SCNx64, &k, &rows, &sum) != 3)
    return fail("no key line");
  if (k != key) return fail("made for another key (material, mesh, fixed set or settings changed)");
  OrganCurves c;
  c.key = k;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    OrganCurveSample s;
    int conv = 0;
    double cx = 0, cy = 0, cz = 0;
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%d,%lf,%lf,%d", &s.site_x, &s.site_y, &cx, &cy, &cz,
                    &s.thickness, &s.lever, &s.depth, &s.nodes, &s.linear_force, &s.newton_force, &conv) != 12)
      return fail("damaged row");
    s.centre = Eigen::Vector3d(cx, cy, cz);
    s.converged = conv != 0;
    c.samples.push_back(s);
  }
  if (c.samples.size() != rows || rows_checksum(c.samples) != sum) return fail("rows or checksum do not match");
  out = std::move(c);
  return true;
}

OrganCurves load_or_compute_organ_curves(const ElasticModel& model, const OrganCurveSettings& settings,
                                         std::uint64_t tensor_key, const std::string& cache_dir, std::ostream* log,
                                         OrganCurvesOutcome* outcome) {
  const std::uint64_t key = organ_curves_key(tensor_key, settings);
  const std::string path = organ_curves_path(cache_dir, key);
  OrganCurves curves;
  std::string why;
  if (load_organ_curves(path, key, curves, &why)) {
    if (outcome) *outcome = OrganCurvesOutcome::kLoaded;
    return curves;
  }
  if (log) *log << "organ curves: " << why << "; computing them (Newton indentations of the organ)" << std::endl;
  curves = compute_organ_curves(model, settings, log);
  curves.key = key;
  save_organ_curves(path, curves);
  if (outcome) *outcome = OrganCurvesOutcome::kComputed;
  return curves;
}

NonlinearLaw load_organ_law(const TetMesh& mesh, const Material& material, const FixedSet& fixed,
                            std::uint64_t tensor_key, const std::string& cache_dir, std::ostream* log,
                            const OrganCurveSettings& settings) {
  // The cached curves need no elastic model: build it (a stiffness assembly) only when they must be computed.
  const std::uint64_t key = organ_curves_key(tensor_key, settings);
  OrganCurves curves;
  if (!load_organ_curves(organ_curves_path(cache_dir, key), key, curves, nullptr)) {
    const ElasticModel model = build_elastic_model(mesh, material, fixed);
    curves = load_or_compute_organ_curves(model, settings, tensor_key, cache_dir, log);
  }
  return fit_organ_law(curves, mesh, fixed, settings);
}

}  // namespace surgsim::nonlinear
