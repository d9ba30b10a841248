// surgsim-curves: the reference curves of the quasi non-linear law (Cotin 1998, section 3.4), computed from a named
// hyperelastic model instead of measurements: homogeneous uniaxial compression of a compressible neo-Hookean
// cylinder with a traction-free lateral surface (see neo_hookean_compression in nonlinear_law.h). Writes
// DIR/NAME_dr.csv (x,d_r) and DIR/NAME_force.csv (x,f), then reads them back and prints the fit residuals of P and Q
// for every degree 4..10.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.h"
#include "nonlinear/nonlinear_law.h"

using namespace surgsim::core;
using namespace surgsim::nonlinear;

namespace {

using namespace surgsim;

// 12 significant digits: parameters read back exactly, data to 1e-12 relative (the test's regeneration check).
std::string number(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.12g", v);
  return buf;
}

struct Options {
  CylinderReference cylinder;
  double max_strain = 0.30;  // x_max / h
  int points = 31;
  std::string name = "liver";
  std::string out_dir = ".";
};

std::string command_line(const Options& o) {
  return "surgsim-curves --radius " + number(o.cylinder.radius) + " --height " + number(o.cylinder.height) +
         " --young " + number(o.cylinder.young_modulus) + " --poisson " + number(o.cylinder.poisson_ratio) +
         " --max-strain " + number(o.max_strain) + " --points " + std::to_string(o.points) + " --name " + o.name +
         " --out-dir DIR";
}

void write_curve(const std::string& path, const Options& o, bool force, const std::vector<NeoHookeanPoint>& pts) {
  const CylinderReference& c = o.cylinder;
  const double e = c.young_modulus, nu = c.poisson_ratio;
  const double mu = e / (2 * (1 + nu)), lambda = e * nu / ((1 + nu) * (1 - 2 * nu));
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw_error(path, ": cannot write");
  std::fprintf(f, "# surgsim quasi non-linear law curve (Cotin 1998, section 3.4): %s of a cylinder under axial compression\n",
               force ? "axial force" : "radial displacement");
  std::fprintf(f, "# model: compressible neo-Hookean, W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,\n");
  std::fprintf(f, "#   mu = E / (2 (1 + nu)) = %s Pa, lambda = E nu / ((1 + nu)(1 - 2 nu)) = %s Pa (small-strain match)\n",
               number(mu).c_str(), number(lambda).c_str());
  std::fprintf(f, "# load: homogeneous uniaxial compression, traction-free lateral surface; axial stretch l = 1 - x / h;\n");
  std::fprintf(f, "#   lateral stretch l_t from mu (l_t^2 - 1) + lambda ln(l l_t^2) = 0 (zero lateral Cauchy stress, Newton)\n");
  if (force) {
    std::fprintf(f, "# f = |P_11| s: axial first Piola-Kirchhoff (nominal) stress P_11 = (mu (l^2 - 1) + lambda ln J) / l,\n");
    std::fprintf(f, "#   J = l l_t^2, times the reference area s = pi r^2 (N); small x: f -> s E x / h\n");
  } else {
    std::fprintf(f, "# d_r = r (l_t - 1): radial displacement of the lateral surface, outward positive (m); small x: d_r -> nu r x / h\n");
  }
  std::fprintf(f, "# x: imposed compression of the top, m, from 0 to %s h in %d points\n", number(o.max_strain).c_str(),
               o.points);
  std::fprintf(f, "# produced by: %s\n", command_line(o).c_str());
  std::fprintf(f, "# cylinder: radius=%s, height=%s, young=%s, poisson=%s\n", number(c.radius).c_str(),
               number(c.height).c_str(), number(c.young_modulus).c_str(), number(c.poisson_ratio).c_str());
  std::fprintf(f, "%s\n", force ? "x,f" : "x,d_r");
  for (const NeoHookeanPoint& p : pts)
    std::fprintf(f, "%s,%s\n", number(p.x).c_str(), number(force ? p.force : p.radial).c_str());
  if (std::fclose(f) != 0) throw_error(path, ": writing failed");
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "surgsim-curves: reference curves of the quasi non-linear law (Cotin 1998, section 3.4) from the homogeneous "
      "uniaxial compression of a compressible neo-Hookean cylinder, W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 "
      "(mu, lambda from E and nu), traction-free lateral surface. Writes DIR/NAME_dr.csv (x,d_r: outward radial "
      "displacement, m) and DIR/NAME_force.csv (x,f: |first Piola axial stress| x pi r^2, N) for compressions x (m) "
      "from 0 to max-strain x height, and prints the fit residuals of P and Q for degrees 4..10."};
  app.add_option("--radius", o.cylinder.radius, "Cylinder radius r, m")->capture_default_str();
  app.add_option("--height", o.cylinder.height, "Cylinder height h, m")->capture_default_str();
  app.add_option("--young", o.cylinder.young_modulus, "Young's modulus E, Pa")->capture_default_str();
  app.add_option("--poisson", o.cylinder.poisson_ratio, "Poisson ratio nu in (0, 0.5)")->capture_default_str();
  app.add_option("--max-strain", o.max_strain, "Largest compression as a fraction of the height, in (0, 0.9]")
      ->capture_default_str();
  app.add_option("--points", o.points, "Points per curve, 11..10000 (evenly spaced in x, from 0)")->capture_default_str();
  app.add_option("--name", o.name, "File name prefix: DIR/NAME_dr.csv and DIR/NAME_force.csv")->capture_default_str();
  app.add_option("--out-dir", o.out_dir, "Output folder (created)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  try {
    check_cylinder(o.cylinder, "surgsim-curves");
    if (!(o.cylinder.poisson_ratio > 0)) throw_error("--poisson must be > 0 (P maps nu r x / h, which is 0 otherwise)");
    if (!(o.max_strain > 0 && o.max_strain <= 0.9)) throw_error("--max-strain ", o.max_strain, " is outside (0, 0.9]");
    if (o.points < kMaxLawDegree + 1 || o.points > 10000)
      throw_error("--points ", o.points, " is outside ", kMaxLawDegree + 1, "..10000");
    if (o.name.empty() || o.name.find('/') != std::string::npos) throw_error("--name must be a plain file prefix");

    // The model at evenly spaced compressions.
    std::vector<NeoHookeanPoint> pts;
    const double x_max = o.max_strain * o.cylinder.height;
    for (int i = 0; i < o.points; ++i) pts.push_back(neo_hookean_compression(o.cylinder, x_max * i / (o.points - 1)));

    std::filesystem::create_directories(o.out_dir);
    const std::string dr_path = (std::filesystem::path(o.out_dir) / (o.name + "_dr.csv")).string();
    const std::string f_path = (std::filesystem::path(o.out_dir) / (o.name + "_force.csv")).string();
    write_curve(dr_path, o, false, pts);
    write_curve(f_path, o, true, pts);
    std::printf("wrote %s and %s (%d points, x up to %s m)\n", dr_path.c_str(), f_path.c_str(), o.points,
                number(x_max).c_str());
    const NeoHookeanPoint& end = pts.back();
    std::printf("at x = %s m: d_r = %.6g m (linear %.6g), f = %.6g N (linear %.6g)\n", number(end.x).c_str(),
                end.radial, o.cylinder.linear_radial(end.x), end.force, o.cylinder.linear_force(end.x));

    // Read the files back (the loader's validation) and report the fits.
    const Curve dr = load_curve(dr_path), f = load_curve(f_path);
    std::printf("fit residuals relative to the curve's range (P: x,d_r; Q: x,f)\n");
    std::printf("degree  P rms      P max      P'(0)     Q rms      Q max      Q'(0)     increasing\n");
    for (int degree = kMinLawDegree; degree <= kMaxLawDegree; ++degree) {
      const CurveFit p = fit_curve(dr, degree), q = fit_curve(f, degree);
      std::printf("%6d  %.3e  %.3e  %.6f  %.3e  %.3e  %.6f  %s\n", degree, p.report.rms_residual,
                  p.report.max_residual, p.report.start_slope, q.report.rms_residual, q.report.max_residual,
                  q.report.start_slope, p.report.increasing && q.report.increasing ? "yes" : "NO");
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "surgsim-curves: %s\n", e.what());
    return 1;
  }
}
