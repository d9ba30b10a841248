// Organ curves (nonlinear/organ_curves.h) on a clamped wedge: a liver-sized box whose thickness grows
// from 4 cm (x = 0) to 8 cm (x = 0.16 m), so that the Newton / linear force ratio of a punch differs over the surface
// as it does on the liver. The law reproduces the indentations it was fitted on, holds at a site it was not fitted
// on (where one Q for the organ does not), and the cache is keyed by the tensors' key (a new material is never served
// the old curves). ctest -R common_organ_curves_test -V prints the fits.
#include "nonlinear/organ_curves.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iostream>

#include "fem/hyperelastic.h"
#include "fem/static_solver.h"
#include "compliance/tensor_cache.h"
#include "support/liver_test_util.h"

using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;

namespace surgsim {
namespace {

// box_organ's box with z scaled by 0.5 + 0.5 x / 0.16: 4 cm thick at x = 0, 8 cm at x = 0.16; z <= 0 clamped.
std::unique_ptr<test::Organ> wedge_organ() {
  auto box = test::box_organ(8, 6, 4);
  TetMesh mesh = box->mesh;
  for (Eigen::Index n = 0; n < mesh.nodes.rows(); ++n) mesh.nodes(n, 2) *= 0.5 + 0.5 * mesh.nodes(n, 0) / 0.16;
  return std::make_unique<test::Organ>(std::move(mesh), box->material, box->fixed);
}

OrganCurveSettings wedge_settings() {
  OrganCurveSettings s;  // automatic sites: a 4 cm lattice, cell centres x 0.02 .. 0.14, y 0.02 .. 0.10
  s.punch_radius = 0.025;
  s.min_punch_nodes = 3;
  s.depths = {0.05, 0.10, 0.15, 0.20};
  s.newton_increment = 0.004;
  return s;
}

const Eigen::Vector3d kDown(0, 0, -1);

// The law's force for a straight push of `depth` on `nodes` (the linear solve's force through the law, as the
// haptic node applies it) and the Newton force, |F . d| both.
struct Push {
  double linear = 0, law = 0, one_q = 0, newton = 0;
};
Push push(const test::Organ& organ, const NonlinearLaw& law, const std::vector<int>& nodes, double depth) {
  std::vector<ImposedDisplacement> imposed;
  std::vector<Eigen::Vector3d> u;
  for (int k : nodes) {
    imposed.push_back({k, depth * kDown, 7});
    u.push_back(depth * kDown);
  }
  StaticSolver linear(organ.model);
  const Eigen::Vector3d f_lin = -linear.solve(imposed).total_reaction;
  Push p;
  p.linear = std::abs(f_lin.dot(kDown));
  Eigen::Vector3d f;
  EXPECT_TRUE(law.apply_force(f_lin, kDown, nodes.data(), u.data(), static_cast<int>(nodes.size()), f));
  p.law = std::abs(f.dot(kDown));
  EXPECT_TRUE(law.apply_force(f_lin, kDown, f));  // without the nodes: Q, one curve for the whole organ
  p.one_q = std::abs(f.dot(kDown));
  HyperelasticOptions opts;
  opts.load_steps = std::max(2, static_cast<int>(std::ceil(depth / 0.004)));
  const HyperelasticSolution ref = HyperelasticSolver(organ.model, opts).solve(imposed);
  EXPECT_TRUE(ref.converged()) << ref.message;
  p.newton = std::abs(ref.total_reaction.dot(kDown));
  return p;
}

TEST(OrganCurves, SitesAreChosenOverTheFreeTop) {
  const auto organ = wedge_organ();
  const std::vector<Eigen::Vector2d> sites = organ_curve_sites(organ->model, wedge_settings());
  ASSERT_EQ(sites.size(), 12u);  // 4 x 3 cell centres, each with its 5 nodes
  EXPECT_NEAR(sites.front().x(), 0.02, 1e-12);
  EXPECT_NEAR(sites.back().x(), 0.14, 1e-12);
  EXPECT_NEAR(sites.back().y(), 0.10, 1e-12);
  const OrganSurfaceGeometry g = organ_surface_geometry(organ->mesh, organ->fixed);
  // The thickness along the inward normal of a top node follows the wedge: the top z = 0.04 + 0.25 x leans, so the
  // ray along its normal meets the bottom after z sqrt(1 + 0.25^2).
  const std::vector<int> at_x2 = organ_punch_nodes(organ->model, {0.02, 0.06}, 0.001);
  const std::vector<int> at_x14 = organ_punch_nodes(organ->model, {0.14, 0.06}, 0.001);
  ASSERT_EQ(at_x2.size(), 1u);
  ASSERT_EQ(at_x14.size(), 1u);
  EXPECT_NEAR(g.thickness[static_cast<std::size_t>(at_x2[0])], 0.045 * std::sqrt(1 + 0.0625), 1e-9);
  EXPECT_NEAR(g.thickness[static_cast<std::size_t>(at_x14[0])], 0.075 * std::sqrt(1 + 0.0625), 1e-9);
  EXPECT_NEAR(g.lever[static_cast<std::size_t>(at_x2[0])], 0.045, 1e-9);  // straight down to the clamped bottom
}

TEST(OrganCurves, TheLawReproducesTheFitAndHoldsAtASiteItWasNotFittedOn) {
  const auto organ = wedge_organ();
  const OrganCurveSettings settings = wedge_settings();
  const OrganCurves curves = compute_organ_curves(organ->model, settings, nullptr);
  ASSERT_EQ(curves.samples.size(), 12 * settings.depths.size());
  FitReport q;
  const NonlinearLaw law = fit_organ_law(curves, organ->mesh, organ->fixed, settings, &q);
  ASSERT_FALSE(law.surface_field().empty());
  EXPECT_FALSE(law.displacement_fit());  // Q and the field, no P

  // Fitted on: each site's punch, at each depth, through the law as the nodes apply it.
  double worst_fit = 0, worst_q = 0;
  for (const auto& s : curves.samples) {
    ASSERT_TRUE(s.converged) << s.depth;
    const std::vector<int> nodes = organ_punch_nodes(organ->model, {s.site_x, s.site_y}, settings.punch_radius);
    std::vector<Eigen::Vector3d> u(nodes.size(), s.depth * kDown);
    Eigen::Vector3d f;
    law.apply_force(s.linear_force * -kDown, kDown, nodes.data(), u.data(), static_cast<int>(nodes.size()), f);
    worst_fit = std::max(worst_fit, std::abs(f.dot(-kDown) - s.newton_force) / s.newton_force);
    worst_q = std::max(worst_q, std::abs(law.q(s.linear_force) - s.newton_force) / s.newton_force);
  }
  std::cout << "fitted on: surface field worst " << worst_fit << ", one Q worst " << worst_q << " (Q max residual "
            << q.max_residual << " of the range)\n";
  EXPECT_LT(worst_fit, 1e-9);  // the residual interpolation gives each site its own values back

  // Held out, site by site (the field fitted on the other 11).
  const OrganLawValidation v = validate_organ_law(curves, settings);
  ASSERT_EQ(v.sites.size(), 12u);
  double worst_q_held = 0;
  for (const auto& s : v.sites) {
    std::cout << "site (" << s.site_x << ", " << s.site_y << "): held out " << s.worst << ", one Q " << s.q_worst
              << "\n";
    worst_q_held = std::max(worst_q_held, s.q_worst);
  }
  std::cout << "leave one site out: worst " << v.worst << ", mean " << v.mean << "; in sample " << v.fitted_worst
            << "\n";
  EXPECT_LT(v.fitted_worst, 1e-9);
  EXPECT_LT(v.worst, 0.03);
  EXPECT_GT(worst_q_held, 2 * v.worst);  // one Q for the wedge errs more than the field held out

  // A site between the lattice's (not a fit site), pushed 20 % of the height, solved afresh: the law as the haptic
  // node applies it against Newton.
  for (const Eigen::Vector2d& c : {Eigen::Vector2d(0.04, 0.04), Eigen::Vector2d(0.12, 0.08)}) {
    const std::vector<int> nodes = organ_punch_nodes(organ->model, c, settings.punch_radius);
    ASSERT_GE(nodes.size(), 3u);
    const Push p = push(*organ, law, nodes, 0.2 * 0.08);
    const double err = std::abs(p.law - p.newton) / p.newton, err_q = std::abs(p.one_q - p.newton) / p.newton;
    std::cout << "held-out punch (" << c.x() << ", " << c.y() << "): Newton " << p.newton << " N, linear "
              << std::abs(p.linear - p.newton) / p.newton << ", one Q " << err_q << ", surface field " << err << "\n";
    EXPECT_LT(err, 0.05);  // the target (3.1 and 0.26 % here; one Q 3.8 and 8.9 %, linear 29 and 18 %)
    EXPECT_LT(err, std::abs(p.linear - p.newton) / p.newton);
  }
}

TEST(OrganCurves, CacheIsKeyedByTheMaterialAndRewrittenWhenDamaged) {
  const std::string dir = ::testing::TempDir() + "/organ_curves_cache";
  std::filesystem::remove_all(dir);
  OrganCurveSettings settings;
  settings.sites = {{0.08, 0.06}};
  settings.punch_radius = 0.02;
  settings.newton_increment = 0.004;
  settings.depths = {0.05, 0.1, 0.15, 0.2, 0.25};
  const auto organ = test::box_organ(6, 4, 3);
  const auto key_of = [&](const Material& m) {
    TensorCacheKey k;
    k.material = material_hash(m);
    return k.combined();
  };
  OrganCurvesOutcome outcome;
  const OrganCurves first =
      load_or_compute_organ_curves(organ->model, settings, key_of(organ->material), dir, nullptr, &outcome);
  EXPECT_EQ(outcome, OrganCurvesOutcome::kComputed);
  const OrganCurves again =
      load_or_compute_organ_curves(organ->model, settings, key_of(organ->material), dir, nullptr, &outcome);
  EXPECT_EQ(outcome, OrganCurvesOutcome::kLoaded);
  ASSERT_EQ(again.samples.size(), first.samples.size());
  for (std::size_t i = 0; i < first.samples.size(); ++i) {
    EXPECT_EQ(again.samples[i].newton_force, first.samples[i].newton_force);
    EXPECT_EQ(again.samples[i].centre, first.samples[i].centre);
    EXPECT_EQ(again.samples[i].thickness, first.samples[i].thickness);
    EXPECT_EQ(again.samples[i].lever, first.samples[i].lever);
  }

  // A stiffer material: another key, so the curves are computed for it, not read from the first file.
  Material stiffer = organ->material;
  stiffer.young_modulus *= 2;
  const auto organ2 = std::make_unique<test::Organ>(organ->mesh, stiffer, organ->fixed);
  ASSERT_NE(key_of(stiffer), key_of(organ->material));
  const OrganCurves second =
      load_or_compute_organ_curves(organ2->model, settings, key_of(stiffer), dir, nullptr, &outcome);
  EXPECT_EQ(outcome, OrganCurvesOutcome::kComputed);
  EXPECT_NEAR(second.samples[0].newton_force, 2 * first.samples[0].newton_force, 1e-6 * first.samples[0].newton_force);
  std::string why;
  OrganCurves dummy;
  EXPECT_FALSE(load_organ_curves(organ_curves_path(dir, first.key), second.key, dummy, &why));
  EXPECT_NE(why.find("another key"), std::string::npos) << why;

  // A damaged file is recomputed and rewritten.
  const std::string path = organ_curves_path(dir, first.key);
  {
    std::fstream f(path, std::ios::in | std::ios::out);
    f.seekp(-12, std::ios::end);
    f << "9";
  }
  EXPECT_FALSE(load_organ_curves(path, first.key, dummy, &why));
  load_or_compute_organ_curves(organ->model, settings, key_of(organ->material), dir, nullptr, &outcome);
  EXPECT_EQ(outcome, OrganCurvesOutcome::kComputed);
  EXPECT_TRUE(load_organ_curves(path, first.key, dummy, &why)) << why;

  // A file of the first format (one Q, three columns fewer) is not read as this one.
  {
    std::ofstream f(path);
    f << "# surgsim organ curves v1\n# key=" << std::hex << first.key << " rows=0 checksum=cbf29ce484222325\n"
      << "site_x_m,site_y_m,depth_m,nodes,linear_force_n,newton_force_n,linear_radial_m,newton_radial_m,converged\n";
  }
  EXPECT_FALSE(load_organ_curves(path, first.key, dummy, &why));
  EXPECT_NE(why.find("not an organ curves v2 file"), std::string::npos) << why;

  // Both nodes compute and save the curves at once on a cache miss: another process's temporary file in the way (here
  // path.tmp held as a folder) must not stop this one. A shared path.tmp made the second node's save throw.
  std::filesystem::create_directories(path + ".tmp");
  EXPECT_NO_THROW(save_organ_curves(path, first));
  EXPECT_TRUE(load_organ_curves(path, first.key, dummy, &why)) << why;
  std::filesystem::remove_all(path + ".tmp");
}

}  // namespace
}  // namespace surgsim
