#include "nonlinear/nonlinear_law.h"

#include <Eigen/QR>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <istream>
#include <sstream>

#include "core/error.h"
#include "core/text.h"

using namespace surgsim::core;
using namespace surgsim::fem;

namespace surgsim::nonlinear {
namespace {

// Relative tolerance when comparing a curve's material with the scene's.
constexpr double kMaterialTolerance = 1e-9;
// Samples of the monotonicity check on [0, t_max].
constexpr int kMonotoneSamples = 2001;

std::string trim(const std::string& s) { return std::string(core::text::trim(s)); }

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  for (const std::string_view f : core::text::split(s, sep)) out.emplace_back(f);
  return out;
}

// A number spanning the whole (trimmed) text; NaN and infinities parse (the caller reports them as non-finite).
bool parse_double(const std::string& s, double& value) {
  const text::Number n = core::text::parse_double(s, value);
  return n == text::Number::kOk || n == text::Number::kNotFinite;
}

// T_k(z) for k = 0..n and the derivative sum; z in [-1, 1]. Forward recurrence (stable on [-1, 1]).
struct ChebyshevSums {
  double value = 0;       // sum_k c_k T_k(z)
  double derivative = 0;  // sum_k c_k T_k'(z) = sum_k c_k k U_{k-1}(z)
};

ChebyshevSums chebyshev(const std::array<double, kMaxLawDegree + 1>& c, int n, double z) noexcept {
  ChebyshevSums s;
  double t_prev = 1, t = z;      // T_0, T_1
  double u_prev = 1, u = 2 * z;  // U_0, U_1
  s.value = c[0];
  for (int k = 1; k <= n; ++k) {
    s.value += c[static_cast<std::size_t>(k)] * t;
    s.derivative += c[static_cast<std::size_t>(k)] * k * u_prev;  // T_k' = k U_{k-1}
    const double t_next = 2 * z * t - t_prev;
    const double u_next = 2 * z * u - u_prev;
    t_prev = t;
    t = t_next;
    u_prev = u;
    u = u_next;
  }
  return s;
}

// The unit vector along `direction`, or false when it is not finite or (numerically) zero.
bool unit_direction(const Eigen::Vector3d& direction, Eigen::Vector3d& d) noexcept {
  if (!direction.allFinite()) return false;
  const double n = direction.norm();
  if (!(n > 1e-300)) return false;
  d = direction / n;
  return true;
}

const char* column_name(CurveQuantity q) { return q == CurveQuantity::kForce ? "x,f" : "x,d_r"; }
const char* value_name(CurveQuantity q) { return q == CurveQuantity::kForce ? "f" : "d_r"; }

// "# cylinder: radius=..., height=..., young=..., poisson=..." (text after "cylinder:").
CylinderReference parse_cylinder(const std::string& text, const std::string& where) {
  static const char* const kKeys[] = {"radius", "height", "young", "poisson"};
  double values[4] = {0, 0, 0, 0};
  bool seen[4] = {false, false, false, false};
  for (const std::string& item : split(text, ',')) {
    const std::string kv = trim(item);
    const auto eq = kv.find('=');
    if (eq == std::string::npos)
      throw_error(where, ": cylinder item '", kv,
                  "' is not key=value (expected radius=R, height=H, young=E, poisson=NU)");
    const std::string key = trim(kv.substr(0, eq)), value = trim(kv.substr(eq + 1));
    int k = 0;
    while (k < 4 && key != kKeys[k]) ++k;
    if (k == 4) throw_error(where, ": unknown cylinder key '", key, "' (expected radius, height, young, poisson)");
    if (seen[k]) throw_error(where, ": cylinder key '", key, "' given twice");
    if (!parse_double(value, values[k])) throw_error(where, ": cylinder ", key, " '", value, "' is not a number");
    seen[k] = true;
  }
  for (int k = 0; k < 4; ++k)
    if (!seen[k])
      throw_error(where, ": cylinder line lacks '", kKeys[k], "=' (expected radius=R, height=H, young=E, poisson=NU)");
  CylinderReference c;
  c.radius = values[0];
  c.height = values[1];
  c.young_modulus = values[2];
  c.poisson_ratio = values[3];
  check_cylinder(c, where);
  return c;
}

// Relative difference, with the reference floored at tiny (for poisson = 0).
double rel_diff(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); }

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Reference cylinder and curves

double CylinderReference::area() const { return M_PI * radius * radius; }
double CylinderReference::linear_radial(double x) const { return poisson_ratio * radius * x / height; }
double CylinderReference::linear_force(double x) const { return area() * young_modulus * x / height; }

const char* to_string(CurveQuantity quantity) {
  return quantity == CurveQuantity::kForce ? "force" : "radial displacement";
}

void check_cylinder(const CylinderReference& c, const std::string& where) {
  const auto positive = [&](double v, const char* name, const char* unit) {
    if (!(std::isfinite(v) && v > 0))
      throw_error(where, ": cylinder ", name, " = ", v, " must be a finite number > 0 (", unit, ")");
  };
  positive(c.radius, "radius", "m");
  positive(c.height, "height", "m");
  positive(c.young_modulus, "young", "Pa");
  if (!(std::isfinite(c.poisson_ratio) && c.poisson_ratio >= 0 && c.poisson_ratio < 0.5))
    throw_error(where, ": cylinder poisson = ", c.poisson_ratio, " must be in [0, 0.5)");
}

Eigen::VectorXd Curve::linear() const {
  Eigen::VectorXd out(x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i)
    out[i] = quantity == CurveQuantity::kForce ? cylinder.linear_force(x[i]) : cylinder.linear_radial(x[i]);
  return out;
}

Curve read_curve(std::istream& in, const std::string& source) {
  Curve curve;
  curve.source = source;
  bool have_cylinder = false, have_header = false;
  std::vector<double> xs, vs;
  std::string raw;
  int line = 0;
  while (std::getline(in, raw)) {
    ++line;
    const std::string text = trim(raw);
    const std::string where = source + ":" + std::to_string(line);
    if (text.empty()) continue;

    // Comments; the one meaningful comment is the reference cylinder, which must precede the column header.
    if (text[0] == '#') {
      const std::string body = trim(text.substr(1));
      if (body.rfind("cylinder:", 0) == 0) {
        // (A cylinder line after the column header is always a second one: the header requires the first.)
        if (have_cylinder) throw_error(where, ": second '# cylinder:' line (give the reference cylinder once)");
        curve.cylinder = parse_cylinder(body.substr(9), where);
        have_cylinder = true;
      }
      continue;
    }

    // The column header names the quantity.
    if (!have_header) {
      std::string compact;
      for (char c : text)
        if (c != ' ' && c != '\t') compact += c;
      if (compact == "x,d_r") {
        curve.quantity = CurveQuantity::kRadialDisplacement;
      } else if (compact == "x,f") {
        curve.quantity = CurveQuantity::kForce;
      } else {
        throw_error(where,
                    ": expected the column header 'x,d_r' (radial displacement curve) or 'x,f' (force curve), got '",
                    text, "'");
      }
      if (!have_cylinder)
        throw_error(where,
                    ": column header before any '# cylinder: radius=R, height=H, young=E, poisson=NU' line "
                    "(state the reference cylinder the curve describes)");
      have_header = true;
      curve.header_line = line;
      continue;
    }

    // A data row: x,value.
    const std::vector<std::string> fields = split(text, ',');
    if (fields.size() != 2)
      throw_error(where, ": expected 2 fields 'x,", value_name(curve.quantity), "', got ", fields.size(), " in '", text,
                  "'");
    double x = 0, v = 0;
    if (!parse_double(fields[0], x)) throw_error(where, ": x '", trim(fields[0]), "' is not a number");
    if (!parse_double(fields[1], v))
      throw_error(where, ": ", value_name(curve.quantity), " '", trim(fields[1]), "' is not a number");
    if (!std::isfinite(x)) throw_error(where, ": x = ", x, " is not finite");
    if (!std::isfinite(v)) throw_error(where, ": ", value_name(curve.quantity), " = ", v, " is not finite");
    if (x < 0) throw_error(where, ": x = ", x, " is negative (x is the imposed compression, m, >= 0)");
    if (x >= curve.cylinder.height)
      throw_error(where, ": x = ", x, " is not below the cylinder height ", curve.cylinder.height, " m");
    if (!xs.empty() && !(x > xs.back()))
      throw_error(where, ": x = ", x, " does not increase (previous x = ", xs.back(), " on line ", curve.lines.back(),
                  "; sort the rows and remove duplicates)");
    xs.push_back(x);
    vs.push_back(v);
    curve.lines.push_back(line);
  }
  if (!have_cylinder)
    throw_error(source,
                ": no '# cylinder: radius=R, height=H, young=E, poisson=NU' line (state the reference cylinder "
                "the curve describes)");
  if (!have_header) throw_error(source, ": no column header 'x,d_r' or 'x,f'");
  if (xs.empty()) throw_error(source, ": no data rows after the column header on line ", curve.header_line);
  curve.x = Eigen::Map<const Eigen::VectorXd>(xs.data(), static_cast<Eigen::Index>(xs.size()));
  curve.value = Eigen::Map<const Eigen::VectorXd>(vs.data(), static_cast<Eigen::Index>(vs.size()));
  return curve;
}

Curve load_curve(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw_error(path, ": cannot open the curve file");
  return read_curve(in, path);
}

// ---------------------------------------------------------------------------------------------------------------
// Polynomial fit and evaluation

// The identity: degree 1, evaluated as t exactly (the coefficients, (T_1(2t - 1) + 1) / 2 = t on [0, 1], are for show).
PolynomialMap::PolynomialMap() {
  c_[1] = 0.5;
  offset_ = -0.5;
}

PolynomialMap PolynomialMap::fit(const Eigen::VectorXd& t, const Eigen::VectorXd& y, int degree,
                                 const std::string& source, FitReport* report, const std::vector<int>* lines) {
  if (degree < kMinLawDegree || degree > kMaxLawDegree)
    throw_error(source, ": polynomial degree ", degree, " is outside ", kMinLawDegree, "..", kMaxLawDegree);
  if (t.size() != y.size()) throw_error(source, ": ", t.size(), " arguments but ", y.size(), " values");
  const int n = static_cast<int>(t.size());
  if (n < degree + 1)
    throw_error(source, ": ", n, " points, a degree-", degree, " fit needs at least ", degree + 1,
                " (add points or lower the degree)");
  if (!t.allFinite() || !y.allFinite()) throw_error(source, ": non-finite point");
  if (t.minCoeff() < 0) throw_error(source, ": negative argument ", t.minCoeff());
  const double t_max = t.maxCoeff();
  if (!(t_max > 0)) throw_error(source, ": every argument is 0: nothing to fit");
  const double range = y.maxCoeff() - y.minCoeff();
  if (!(range > 0)) throw_error(source, ": the values are constant (", y[0], "): nothing to fit");

  // Least squares in the shifted Chebyshev basis phi_k(z) = T_k(z) - T_k(-1), z = 2 t / t_max - 1.
  Eigen::MatrixXd a(n, degree);
  for (int i = 0; i < n; ++i) {
    const double z = 2 * t[i] / t_max - 1;
    double t_prev = 1, tk = z;
    for (int k = 1; k <= degree; ++k) {
      a(i, k - 1) = tk - ((k % 2) ? -1.0 : 1.0);
      const double next = 2 * z * tk - t_prev;
      t_prev = tk;
      tk = next;
    }
  }
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
  if (qr.rank() < degree)
    throw_error(source, ": the points determine only a degree-", qr.rank(), " polynomial through 0 (need ", degree,
                " distinct non-zero arguments)");
  const Eigen::VectorXd c = qr.solve(y);

  PolynomialMap p;
  p.degree_ = degree;
  p.t_max_ = t_max;
  p.c_.fill(0);
  p.offset_ = 0;
  for (int k = 1; k <= degree; ++k) {
    p.c_[static_cast<std::size_t>(k)] = c[k - 1];
    p.offset_ += c[k - 1] * ((k % 2) ? -1.0 : 1.0);
  }
  p.end_value_ = p.inside(t_max);
  p.end_slope_ = p.inside_derivative(t_max);

  if (report) {
    FitReport& r = *report;
    r = FitReport();
    r.degree = degree;
    r.points = n;
    r.range = range;
    double sum2 = 0, worst = -1;
    for (int i = 0; i < n; ++i) {
      const double e = std::abs(p(t[i]) - y[i]);
      sum2 += e * e;
      if (e > worst) {
        worst = e;
        r.worst_line =
            lines && lines->size() == static_cast<std::size_t>(n) ? (*lines)[static_cast<std::size_t>(i)] : 0;
      }
    }
    r.rms_residual = std::sqrt(sum2 / n) / range;
    r.max_residual = worst / range;
    r.t_max = t_max;
    r.end_value = p.end_value_;
    r.end_slope = p.end_slope_;
    r.start_slope = p.inside_derivative(0);
    bool increasing = p.end_slope_ > 0;
    double previous = 0;  // P(0)
    for (int j = 1; j < kMonotoneSamples && increasing; ++j) {
      const double v = p.inside(t_max * j / (kMonotoneSamples - 1));
      increasing = v > previous;
      previous = v;
    }
    r.increasing = increasing;
  }
  return p;
}

double PolynomialMap::inside(double t) const noexcept {
  return chebyshev(c_, degree_, 2 * t / t_max_ - 1).value - offset_;
}

double PolynomialMap::inside_derivative(double t) const noexcept {
  return chebyshev(c_, degree_, 2 * t / t_max_ - 1).derivative * 2 / t_max_;
}

double PolynomialMap::operator()(double t) const noexcept {
  if (degree_ == 1) return t;  // the identity, exactly
  if (t < 0) return -(*this)(-t);
  if (t > t_max_) return end_value_ + end_slope_ * (t - t_max_);
  return inside(t);
}

double PolynomialMap::derivative(double t) const noexcept {
  if (degree_ == 1) return 1;
  const double a = std::abs(t);
  return a > t_max_ ? end_slope_ : inside_derivative(a);
}

CurveFit fit_curve(const Curve& curve, int degree) {
  if (degree < kMinLawDegree || degree > kMaxLawDegree)
    throw_error(curve.source, ": polynomial degree ", degree, " is outside ", kMinLawDegree, "..", kMaxLawDegree);
  if (curve.size() < degree + 1)
    throw_error(curve.source, ": ", curve.size(), " points, a degree-", degree, " fit needs at least ", degree + 1,
                " (add points or lower nonlinear.degree)");
  if (curve.quantity == CurveQuantity::kRadialDisplacement && !(curve.cylinder.poisson_ratio > 0))
    throw_error(curve.source,
                ": poisson = 0 makes the linear radial displacement nu r x / h identically 0, so P is "
                "undefined (a radial curve needs poisson > 0)");
  CurveFit f;
  f.curve = curve;
  f.map = PolynomialMap::fit(curve.linear(), curve.value, degree, curve.source, &f.report, &curve.lines);
  return f;
}

// ---------------------------------------------------------------------------------------------------------------
// Neo-Hookean reference curves

NeoHookeanPoint neo_hookean_compression(const CylinderReference& c, double x) {
  check_cylinder(c, "neo-Hookean cylinder");
  if (!(std::isfinite(x) && x >= 0 && x < c.height))
    throw_error("neo-Hookean cylinder: compression x = ", x, " m must be in [0, height = ", c.height, ")");
  const double e = c.young_modulus, nu = c.poisson_ratio;
  const double mu = e / (2 * (1 + nu));
  const double lambda = e * nu / ((1 + nu) * (1 - 2 * nu));
  const double l = 1 - x / c.height;

  // Zero lateral Cauchy stress: g(t) = mu (t^2 - 1) + lambda ln(l t^2) = 0. g increases with t > 0 and g(1) =
  // lambda ln l <= 0, so the root is >= 1: bracket it, then Newton with bisection when a step leaves the bracket.
  const auto g = [&](double t) { return mu * (t * t - 1) + lambda * std::log(l * t * t); };
  double lo = 1, hi = 2;
  while (g(hi) < 0) hi *= 2;
  double t = 1;
  if (g(1) < 0) {
    for (int it = 0; it < 200; ++it) {
      const double gt = g(t);
      if (gt == 0) break;
      (gt < 0 ? lo : hi) = t;
      double next = t - gt / (2 * mu * t + 2 * lambda / t);
      if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
      const bool done = std::abs(next - t) <= 1e-15 * t;
      t = next;
      if (done) break;
    }
  }

  NeoHookeanPoint p;
  p.x = x;
  p.lateral_stretch = t;
  p.radial = c.radius * (t - 1);
  const double j = l * t * t;
  const double p11 = (mu * (l * l - 1) + lambda * std::log(j)) / l;  // first Piola-Kirchhoff, axial (< 0)
  p.force = std::abs(p11) * c.area();
  return p;
}

// ---------------------------------------------------------------------------------------------------------------
// The law

bool constraint_direction(const Eigen::Vector3d* imposed, int m, Eigen::Vector3d& direction) noexcept {
  if (!imposed || m <= 0) return false;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double total = 0;
  for (int l = 0; l < m; ++l) {
    if (!imposed[l].allFinite()) return false;
    sum += imposed[l];
    total += imposed[l].norm();
  }
  const double n = sum.norm();
  if (!(n > 1e-12 * total) || !(n > 0)) return false;
  direction = sum / n;
  return true;
}

NonlinearLaw::NonlinearLaw(std::optional<CurveFit> displacement, std::optional<CurveFit> force)
    : displacement_(std::move(displacement)), force_(std::move(force)) {
  const auto check = [](const std::optional<CurveFit>& f, CurveQuantity want, const char* name) {
    if (!f) return;
    if (f->curve.quantity != want)
      throw_error(f->curve.source, ":", f->curve.header_line, ": column header '", column_name(f->curve.quantity),
                  "' is a ", to_string(f->curve.quantity), " curve, but it is used as the ", name, " (needs '",
                  column_name(want), "')");
    if (!f->report.increasing)
      throw_error(f->curve.source, ": the degree-", f->report.degree, " fit of ",
                  want == CurveQuantity::kForce ? "Q" : "P", " is not increasing on [0, ", f->report.t_max,
                  "] (end slope ", f->report.end_slope, "): lower nonlinear.degree or check the curve");
  };
  check(displacement_, CurveQuantity::kRadialDisplacement, "displacement curve");
  check(force_, CurveQuantity::kForce, "force curve");
}

bool NonlinearLaw::apply_displacement(const Eigen::Vector3d& u, const Eigen::Vector3d& direction,
                                      Eigen::Vector3d& out) const noexcept {
  Eigen::Vector3d d;
  if (!u.allFinite() || !unit_direction(direction, d)) {
    out = u;
    return false;
  }
  if (!displacement_) {
    out = u;
    return true;
  }
  const double along = u.dot(d);
  const Eigen::Vector3d radial = u - along * d;
  const double amplitude = radial.norm();
  Eigen::Vector3d result = along * d;
  if (amplitude > 0) result += radial * (displacement_->map(amplitude) / amplitude);
  if (!result.allFinite()) {
    out = u;
    return false;
  }
  out = result;
  return true;
}

bool NonlinearLaw::apply_displacements(Eigen::Ref<Eigen::VectorXd> u, const Eigen::Vector3d& direction) const noexcept {
  Eigen::Vector3d d;
  if (u.size() % 3 != 0 || !unit_direction(direction, d)) return false;
  if (!displacement_) return u.allFinite();
  bool ok = true;
  for (Eigen::Index i = 0; i + 2 < u.size(); i += 3) {
    Eigen::Vector3d v = u.segment<3>(i);
    ok = apply_displacement(v, d, v) && ok;
    u.segment<3>(i) = v;
  }
  return ok;
}

bool NonlinearLaw::apply_force(const Eigen::Vector3d& f, const Eigen::Vector3d& direction,
                               Eigen::Vector3d& out) const noexcept {
  Eigen::Vector3d d;
  if (!f.allFinite() || !unit_direction(direction, d)) {
    out = f;
    return false;
  }
  if (!force_) {
    out = f;
    return true;
  }
  const double along = f.dot(d);
  const Eigen::Vector3d result = (f - along * d) + std::copysign(force_->map(std::abs(along)), along) * d;
  if (!result.allFinite()) {
    out = f;
    return false;
  }
  out = result;
  return true;
}

double SurfaceForceField::regression(double delta, double h, double lever_m) const noexcept {
  if (degree <= 0 || !(h > 0)) return 1;
  const double lam = lever_m / h;
  const auto poly = [&](double e, double& slope) {
    double v = 0, d = 0, p = 1;  // p = e^(k-1)
    for (int k = 1; k <= degree; ++k) {
      const double c = a[static_cast<std::size_t>(k)] + b[static_cast<std::size_t>(k)] * lam;
      d += k * c * p;
      p *= e;
      v += c * p;
    }
    slope = d;
    return v;
  };
  const double e = std::abs(delta) / h;
  double slope = 0;
  if (e <= e_max) return 1 + poly(e, slope);
  const double end = poly(e_max, slope);
  return 1 + end + slope * (e - e_max);
}

double SurfaceForceField::residual_at(const Eigen::Vector3d& c, double delta) const noexcept {
  const auto j_count = static_cast<std::size_t>(depths.size());
  const std::size_t sites = site_centre.size();
  if (j_count == 0 || sites == 0 || site_residual.size() != sites * j_count) return 1;
  // Which fit depths bracket delta: linear between (0, 1) and them, held beyond the last.
  std::size_t j = 0;
  while (j < j_count && depths[j] < delta) ++j;
  const auto at = [&](std::size_t s, std::size_t k) { return site_residual[s * j_count + k]; };
  double sum_w = 0, v0 = 0, v1 = 0;
  for (std::size_t s = 0; s < sites; ++s) {
    const double r2 = (site_centre[s] - c).squaredNorm();
    if (r2 < 1e-16) {  // on a site: its own values
      sum_w = 1;
      v0 = j == 0 ? 1.0 : at(s, std::min(j, j_count) - 1);
      v1 = at(s, std::min(j, j_count - 1));
      break;
    }
    const double w = 1 / (r2 * r2);  // kPower = 4
    sum_w += w;
    v0 += w * (j == 0 ? 1.0 : at(s, std::min(j, j_count) - 1));
    v1 += w * at(s, std::min(j, j_count - 1));
  }
  v0 /= sum_w;
  v1 /= sum_w;
  if (j >= j_count) return v1;
  const double x0 = j == 0 ? 0.0 : depths[j - 1], x1 = depths[j];
  return v0 + (v1 - v0) * (delta - x0) / (x1 - x0);
}

double SurfaceForceField::ratio(const int* nodes, int m, const Eigen::Vector3d& direction,
                                double delta) const noexcept {
  if (degree <= 0 || nodes == nullptr || m <= 0) return 1;
  const int n = node_count();
  if (static_cast<int>(lever.size()) != n || static_cast<int>(position.size()) != n ||
      static_cast<int>(normal.size()) != n)
    return 1;
  double h = 0, lever_m = 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero(), outward = Eigen::Vector3d::Zero();
  int used = 0;
  for (int l = 0; l < m; ++l) {
    const int node = nodes[l];
    if (node < 0 || node >= n || !(thickness[static_cast<std::size_t>(node)] > 0)) continue;
    h += thickness[static_cast<std::size_t>(node)];
    lever_m += lever[static_cast<std::size_t>(node)];
    c += position[static_cast<std::size_t>(node)];
    outward += normal[static_cast<std::size_t>(node)];
    ++used;
  }
  if (used == 0 || !(-direction.dot(outward) >= kPushCosine * direction.norm() * outward.norm()))
    return 1;  // not a push into the organ
  const double value = regression(delta, h / used, lever_m / used) * residual_at(c / used, delta);
  if (!std::isfinite(value)) return 1;
  return std::clamp(value, kMinRatio, kMaxRatio);
}

NonlinearLaw::NonlinearLaw(std::optional<CurveFit> displacement, std::optional<CurveFit> force, SurfaceForceField field)
    : NonlinearLaw(std::move(displacement), std::move(force)) {
  const std::size_t n = field.thickness.size();
  if (field.degree < 0 || field.degree > kMaxLawDegree || field.lever.size() != n || field.position.size() != n ||
      field.normal.size() != n || field.site_residual.size() != field.site_centre.size() * field.depths.size())
    throw_error("organ surface field: degree ", field.degree, ", ", n, " thicknesses, ", field.lever.size(),
                " levers, ", field.position.size(), " positions, ", field.site_residual.size(), " residuals for ",
                field.site_centre.size(), " sites x ", field.depths.size(),
                " depths: the sizes do not match (recompute the organ curves)");
  field_ = std::move(field);
}

bool NonlinearLaw::apply_force(const Eigen::Vector3d& f, const Eigen::Vector3d& direction, const int* nodes,
                               const Eigen::Vector3d* imposed, int m, Eigen::Vector3d& out) const noexcept {
  if (field_.empty() || nodes == nullptr || imposed == nullptr || m <= 0) return apply_force(f, direction, out);
  Eigen::Vector3d d;
  if (!f.allFinite() || !unit_direction(direction, d)) {
    out = f;
    return false;
  }
  double delta = 0;
  for (int l = 0; l < m; ++l) delta += imposed[l].dot(d);
  delta = std::abs(delta / m);
  if (!std::isfinite(delta)) {
    out = f;
    return false;
  }
  const double along = f.dot(d);
  const Eigen::Vector3d result = f + (field_.ratio(nodes, m, d, delta) - 1) * along * d;
  if (!result.allFinite()) {
    out = f;
    return false;
  }
  out = result;
  return true;
}

NonlinearLaw load_nonlinear_law(const NonlinearSpec& spec) {
  if (!spec.enabled()) return NonlinearLaw();
  if (spec.degree < kMinLawDegree || spec.degree > kMaxLawDegree)
    throw_error("nonlinear.degree ", spec.degree, " is outside ", kMinLawDegree, "..", kMaxLawDegree);
  std::optional<CurveFit> displacement, force;
  if (!spec.displacement_curve.empty()) displacement = fit_curve(load_curve(spec.displacement_curve), spec.degree);
  if (!spec.force_curve.empty()) force = fit_curve(load_curve(spec.force_curve), spec.degree);
  return NonlinearLaw(std::move(displacement), std::move(force));
}

NonlinearLaw load_nonlinear_law(const NonlinearSpec& spec, const Material& material) {
  NonlinearLaw law = load_nonlinear_law(spec);
  for (const std::optional<CurveFit>* f : {&law.displacement_fit(), &law.force_fit()}) {
    if (!*f) continue;
    const CylinderReference& c = (*f)->curve.cylinder;
    if (rel_diff(c.young_modulus, material.young_modulus) > kMaterialTolerance ||
        rel_diff(c.poisson_ratio, material.poisson_ratio) > kMaterialTolerance)
      throw_error((*f)->curve.source, ": the curve describes young=", c.young_modulus, ", poisson=", c.poisson_ratio,
                  " but the scene's material is young_modulus=", material.young_modulus,
                  ", poisson_ratio=", material.poisson_ratio,
                  ": the linear input of the law would not be the scene's (regenerate the "
                  "curves with surgsim-curves --young ",
                  material.young_modulus, " --poisson ", material.poisson_ratio, ")");
  }
  return law;
}

}  // namespace surgsim::nonlinear
