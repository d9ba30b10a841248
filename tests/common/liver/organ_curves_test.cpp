// Organ curves (issue 16, part 2, liver/organ_curves.h) on a liver-sized box clamped on its bottom face: the law
// fitted on the organ's own Newton indentations reproduces them, and the cache is keyed by the tensors' key (a new
// material is never served the old curves). ctest -R common_organ_curves_test -V prints the fit.
#include "liver/organ_curves.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iostream>

#include "liver/tensor_cache.h"
#include "support/liver_test_util.h"

namespace surgsim {
namespace {

OrganCurveSettings box_settings() {
  OrganCurveSettings s;
  s.sites = {{0.08, 0.06}, {0.05, 0.04}};  // the box spans x 0..0.16, y 0..0.12, z 0..0.08
  s.punch_radius = 0.02;
  s.newton_increment = 0.004;
  return s;
}

TEST(OrganCurves, TheFittedLawReproducesTheNewtonResponsesItWasFittedOn) {
  const auto organ = test::box_organ(8, 6, 4);
  const OrganCurveSettings settings = box_settings();
  const OrganCurves curves = compute_organ_curves(organ->model, settings, nullptr);
  ASSERT_EQ(curves.samples.size(), settings.sites.size() * settings.depths.size());
  FitReport q, p;
  const NonlinearLaw law = fit_organ_law(curves, settings.degree, &q, &p, true);
  EXPECT_FALSE(fit_organ_law(curves, settings.degree).displacement_fit());  // the scenes' law: Q alone
  std::cout << "Q: rms residual " << q.rms_residual << ", max " << q.max_residual << "; P: "
            << (p.degree > 0 ? "max residual " + std::to_string(p.max_residual) : std::string("left out")) << "\n";
  double worst_linear = 0, worst_law = 0;
  for (const auto& s : curves.samples) {
    ASSERT_TRUE(s.converged) << s.depth;
    const double lin = std::abs(s.linear_force - s.newton_force) / s.newton_force;
    const double fit = std::abs(law.q(s.linear_force) - s.newton_force) / s.newton_force;
    worst_linear = std::max(worst_linear, lin);
    worst_law = std::max(worst_law, fit);
    std::cout << "site (" << s.site_x << ", " << s.site_y << ") " << s.depth * 1000 << " mm: Newton " << s.newton_force
              << " N, linear error " << lin << ", organ law error " << fit << "\n";
    if (p.degree > 0) {
      // P is one map for every site: the largest bulge of two sites is matched to within 10 %.
      EXPECT_NEAR(law.p(s.linear_radial), s.newton_radial, 0.1 * s.newton_radial + 1e-6);
    }
  }
  EXPECT_LT(worst_law, 0.03);
  EXPECT_GT(worst_linear, 3 * worst_law);  // the law is what closes the gap
}

TEST(OrganCurves, CacheIsKeyedByTheMaterialAndRewrittenWhenDamaged) {
  const std::string dir = ::testing::TempDir() + "/organ_curves_cache";
  std::filesystem::remove_all(dir);
  OrganCurveSettings settings = box_settings();
  settings.sites = {{0.08, 0.06}};
  settings.depths = {0.05, 0.1, 0.15, 0.2, 0.25};
  const auto organ = test::box_organ(6, 4, 3);
  const auto key_of = [&](const Material& m) {
    TensorCacheKey k;
    k.material = material_hash(m);
    return k.combined();
  };
  OrganCurvesOutcome outcome;
  const OrganCurves first = load_or_compute_organ_curves(organ->model, settings, key_of(organ->material), dir, nullptr, &outcome);
  EXPECT_EQ(outcome, OrganCurvesOutcome::kComputed);
  const OrganCurves again = load_or_compute_organ_curves(organ->model, settings, key_of(organ->material), dir, nullptr, &outcome);
  EXPECT_EQ(outcome, OrganCurvesOutcome::kLoaded);
  ASSERT_EQ(again.samples.size(), first.samples.size());
  for (std::size_t i = 0; i < first.samples.size(); ++i) EXPECT_EQ(again.samples[i].newton_force, first.samples[i].newton_force);

  // A stiffer material: another key, so the curves are computed for it, not read from the first file.
  Material stiffer = organ->material;
  stiffer.young_modulus *= 2;
  const auto organ2 = std::make_unique<test::Organ>(organ->mesh, stiffer, organ->fixed);
  ASSERT_NE(key_of(stiffer), key_of(organ->material));
  const OrganCurves second = load_or_compute_organ_curves(organ2->model, settings, key_of(stiffer), dir, nullptr, &outcome);
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
}

}  // namespace
}  // namespace surgsim
