#include "liver/organ_curves.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>

#include "core/error.h"
#include "liver/hyperelastic.h"
#include "liver/static_solver.h"

namespace surgsim {

namespace {

// FNV-1a over raw bytes.
struct Fnv {
  std::uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ c[i]) * 1099511628211ull;
  }
  template <class T>
  void value(const T& v) { bytes(&v, sizeof v); }
};

const Eigen::Vector3d kPush(0, 0, -1);  // the punch pushes straight down

// Largest |u_r| (orthogonal to the push) over the boundary nodes.
double largest_radial(const Eigen::MatrixX3d& u, const std::vector<int>& boundary) {
  double best = 0;
  for (int n : boundary) {
    const Eigen::Vector3d v = u.row(n).transpose();
    best = std::max(best, (v - v.dot(kPush) * kPush).norm());
  }
  return best;
}

std::string row_text(const OrganCurveSample& s) {
  char buf[320];
  std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%d,%.17g,%.17g,%.17g,%.17g,%d", s.site_x, s.site_y, s.depth,
                s.nodes, s.linear_force, s.newton_force, s.linear_radial, s.newton_radial, s.converged ? 1 : 0);
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

constexpr const char* kHeader = "# surgsim organ curves v1";
constexpr const char* kColumns =
    "site_x_m,site_y_m,depth_m,nodes,linear_force_n,newton_force_n,linear_radial_m,newton_radial_m,converged";

}  // namespace

std::uint64_t OrganCurveSettings::hash() const {
  Fnv f;
  f.value(sites.size());
  for (const auto& s : sites) {
    f.value(s.x());
    f.value(s.y());
  }
  f.value(punch_radius);
  f.value(depths.size());
  for (double d : depths) f.value(d);
  f.value(degree);
  f.value(newton_increment);
  return f.h;
}

std::vector<int> organ_punch_nodes(const ElasticModel& model, const Eigen::Vector2d& centre, double radius) {
  const TetMesh& mesh = *model.mesh;
  const SurfaceMesh surface = boundary_surface(mesh);
  Eigen::MatrixX3d normals = Eigen::MatrixX3d::Zero(mesh.nodes.rows(), 3);
  for (Eigen::Index f = 0; f < surface.tris.rows(); ++f) {
    const Eigen::RowVector3d a = mesh.nodes.row(surface.tris(f, 0)), b = mesh.nodes.row(surface.tris(f, 1)),
                             c = mesh.nodes.row(surface.tris(f, 2));
    const Eigen::RowVector3d n = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) normals.row(surface.tris(f, k)) += n;
  }
  std::vector<int> out;
  for (int n : surface.nodes) {
    const double len = normals.row(n).norm();
    if (!model.fixed.node_fully_free(n) || !(len > 0)) continue;
    if (normals(n, 2) / len > 0.5 && (mesh.nodes.row(n).head<2>().transpose() - centre).norm() <= radius) out.push_back(n);
  }
  return out;
}

OrganCurves compute_organ_curves(const ElasticModel& model, const OrganCurveSettings& settings, std::ostream* log) {
  const TetMesh& mesh = *model.mesh;
  const double height = mesh.nodes.col(2).maxCoeff() - mesh.nodes.col(2).minCoeff();
  const std::vector<int> boundary = boundary_surface(mesh).nodes;
  StaticSolver linear(model);
  OrganCurves out;
  for (const Eigen::Vector2d& site : settings.sites) {
    const std::vector<int> punch = organ_punch_nodes(model, site, settings.punch_radius);
    if (punch.empty())
      throw_error("organ curves: no free top-surface node within ", settings.punch_radius, " m of (", site.x(), ", ",
                  site.y(), "): move the site onto the organ's top");
    for (double fraction : settings.depths) {
      OrganCurveSample s;
      s.site_x = site.x();
      s.site_y = site.y();
      s.depth = fraction * height;
      s.nodes = static_cast<int>(punch.size());
      std::vector<ImposedDisplacement> imposed;
      for (int k : punch) imposed.push_back({k, s.depth * kPush, 7});
      const StaticSolution lin = linear.solve(imposed);
      s.linear_force = std::abs(lin.total_reaction.dot(kPush));
      s.linear_radial = largest_radial(lin.displacement, boundary);
      HyperelasticOptions opts;
      opts.load_steps = std::max(2, static_cast<int>(std::ceil(s.depth / settings.newton_increment)));
      if (log) *log << "organ curves: site (" << site.x() << ", " << site.y() << "), " << s.depth * 1000 << " mm: Newton, "
                    << opts.load_steps << " increments" << std::endl;
      const HyperelasticSolution ref = HyperelasticSolver(model, opts).solve(imposed);
      s.converged = ref.converged();
      s.newton_force = std::abs(ref.total_reaction.dot(kPush));
      s.newton_radial = largest_radial(ref.displacement, boundary);
      out.samples.push_back(s);
    }
  }
  return out;
}

NonlinearLaw fit_organ_law(const OrganCurves& curves, int degree, FitReport* q_report, FitReport* p_report,
                           bool fit_p) {
  std::vector<const OrganCurveSample*> ok;
  for (const auto& s : curves.samples)
    if (s.converged) ok.push_back(&s);
  const auto n = static_cast<Eigen::Index>(ok.size());
  Eigen::VectorXd lf(n), nf(n), lr(n), nr(n), depth(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const OrganCurveSample& s = *ok[static_cast<std::size_t>(i)];
    lf[i] = s.linear_force;
    nf[i] = s.newton_force;
    lr[i] = s.linear_radial;
    nr[i] = s.newton_radial;
    depth[i] = s.depth;
  }
  // The fits as CurveFits (the law's type): x is the indentation depth, the value the Newton response.
  const auto make = [&](CurveQuantity q, const Eigen::VectorXd& t, const Eigen::VectorXd& y, FitReport* report) {
    CurveFit fit;
    fit.curve.source = q == CurveQuantity::kForce ? "organ curves (force)" : "organ curves (radial displacement)";
    fit.curve.quantity = q;
    fit.curve.x = depth;
    fit.curve.value = y;
    fit.map = PolynomialMap::fit(t, y, degree, fit.curve.source, &fit.report);
    if (report) *report = fit.report;
    return fit;
  };
  std::optional<CurveFit> q = make(CurveQuantity::kForce, lf, nf, q_report);
  if (!q->report.increasing) throw_error("organ curves: the fitted Q is not increasing (degree ", degree, "): lower the degree");
  std::optional<CurveFit> p;
  if (fit_p) {
    try {
      CurveFit pf = make(CurveQuantity::kRadialDisplacement, lr, nr, p_report);
      if (pf.report.increasing) p = std::move(pf);
    } catch (const Error&) {  // too few distinct bulges: Q alone
    }
  }
  if (!p && p_report) *p_report = FitReport{};
  return NonlinearLaw(std::move(p), std::move(q));
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
  const std::string tmp = path + ".tmp";
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
  if (header != kHeader || columns != kColumns) return fail("not an organ curves v1 file");
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
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%d,%lf,%lf,%lf,%lf,%d", &s.site_x, &s.site_y, &s.depth, &s.nodes,
                    &s.linear_force, &s.newton_force, &s.linear_radial, &s.newton_radial, &conv) != 9)
      return fail("damaged row");
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
  return fit_organ_law(curves, settings.degree);
}

}  // namespace surgsim
