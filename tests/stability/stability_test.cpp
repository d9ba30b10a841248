// The stability suite as assertions: the expected outcome of every case (stability_cases.h) and no
// non-finite value in any output. The report program (build/bench/stability_report) prints the same cases.
#include "stability_cases.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

namespace surgsim::stability {
namespace {

// The row of `name` / `parameter` (fails the test when it is missing).
const CaseResult* find(const std::vector<CaseResult>& rows, const std::string& name, const std::string& parameter) {
  for (const CaseResult& r : rows)
    if (r.name == name && r.parameter == parameter) return &r;
  ADD_FAILURE() << "no case " << name << " / " << parameter;
  return nullptr;
}

void expect(const std::vector<CaseResult>& rows, const std::string& name, const std::string& parameter,
            Outcome outcome) {
  const CaseResult* r = find(rows, name, parameter);
  if (r == nullptr) return;
  EXPECT_EQ(to_string(r->outcome), std::string(to_string(outcome))) << name << " / " << parameter << ": " << r->message;
}

// Every row: finite outputs, never "failed", a non-empty message.
void expect_all_sound(const std::vector<CaseResult>& rows) {
  ASSERT_FALSE(rows.empty());
  for (const CaseResult& r : rows) {
    EXPECT_TRUE(r.all_finite) << r.name << " / " << r.parameter << ": " << r.message;
    EXPECT_NE(r.outcome, Outcome::kFailed) << r.name << " / " << r.parameter << ": " << r.message;
    EXPECT_FALSE(r.message.empty()) << r.name << " / " << r.parameter;
    EXPECT_TRUE(std::isfinite(r.max_force_n) && std::isfinite(r.max_displacement_m)) << r.name << " / " << r.parameter;
  }
}

TEST(StabilityTest, PoissonRatioUpToTheIncompressibleLimit) {
  const std::vector<CaseResult> rows = liver_poisson_cases();
  expect_all_sound(rows);
  for (const char* nu : {"nu=0", "nu=0.3", "nu=0.45", "nu=0.49", "nu=0.499", "nu=0.4999"}) {
    expect(rows, "poisson", nu, Outcome::kConverged);
    const CaseResult* r = find(rows, "poisson", nu);
    ASSERT_NE(r, nullptr);
    EXPECT_LT(r->residual, 1e-8) << nu;
    EXPECT_GT(r->condition, 1) << nu;
    EXPECT_GT(r->max_force_n, 0) << nu;
  }
  // Locking: the stiffness' condition grows as nu -> 0.5.
  EXPECT_GT(find(rows, "poisson", "nu=0.4999")->condition, 100 * find(rows, "poisson", "nu=0.3")->condition);
  for (const char* nu : {"nu=0.5", "nu=0.6"}) {
    expect(rows, "poisson", nu, Outcome::kRefused);
    EXPECT_NE(find(rows, "poisson", nu)->message.find("Poisson ratio must be in [0, 0.5)"), std::string::npos);
  }
}

TEST(StabilityTest, YoungsModulusFromOnePascalToOneGigapascal) {
  const std::vector<CaseResult> rows = liver_young_cases();
  expect_all_sound(rows);
  // Each converged case also checked force / E and the displacements against E = 3000 Pa (else it is "failed").
  for (const char* e : {"E=1 Pa", "E=1000 Pa", "E=1e+06 Pa", "E=1e+09 Pa"}) expect(rows, "young", e, Outcome::kConverged);
  EXPECT_NEAR(find(rows, "young", "E=1e+09 Pa")->max_force_n / find(rows, "young", "E=1 Pa")->max_force_n, 1e9, 1e-3);
  for (const char* e : {"E=0 Pa", "E=-1 Pa", "E=inf Pa", "E=nan Pa"}) {
    expect(rows, "young", e, Outcome::kRefused);
    EXPECT_NE(find(rows, "young", e)->message.find("Young's modulus"), std::string::npos) << e;
  }
}

TEST(StabilityTest, SliversAreSolvedOrRefusedNeverNonFinite) {
  const std::vector<CaseResult> rows = liver_sliver_cases();
  expect_all_sound(rows);
  for (const char* p : {"volume ratio 0.1", "volume ratio 0.001", "volume ratio 1e-06"})
    expect(rows, "sliver", p, Outcome::kConverged);
  // Below validate_mesh's zero-volume threshold (1e-12 of the mean volume) the mesh is refused, naming the tet.
  expect(rows, "sliver", "volume ratio 1e-15", Outcome::kRefused);
  EXPECT_NE(find(rows, "sliver", "volume ratio 1e-15")->message.find("zero volume"), std::string::npos);
}

TEST(StabilityTest, ContactsOnAdjacentDuplicateAndFixedNodes) {
  const std::vector<CaseResult> rows = liver_contact_cases();
  expect_all_sound(rows);
  expect(rows, "contacts_adjacent", "2 nodes on one edge, both pressed", Outcome::kConverged);
  expect(rows, "contacts_adjacent", "2 nodes on one edge, pulled apart 8 mm", Outcome::kConverged);
  expect(rows, "contacts_adjacent", "2 x 2 patch of nodes", Outcome::kConverged);
  expect(rows, "contacts_duplicate", "same node twice, equal", Outcome::kMerged);
  expect(rows, "contacts_duplicate", "same node twice, 1 mm apart", Outcome::kMerged);
  expect(rows, "contacts_fixed", "superposition, a fixed node among 2", Outcome::kRefused);
  expect(rows, "contacts_fixed", "reference solve, a fixed node", Outcome::kRefused);
  expect(rows, "contacts_fixed", "tool on a side triangle with fixed corners", Outcome::kIgnored);
  expect(rows, "contacts_fixed", "tool on the fixed bottom face", Outcome::kIgnored);
  expect(rows, "contacts_interior", "superposition, an interior node", Outcome::kRefused);
  expect(rows, "contacts_nonfinite", "superposition, NaN displacement", Outcome::kRefused);
}

TEST(StabilityTest, DisplacementsLargerThanAnElementInvertTetsAndAreDetected) {
  const std::vector<CaseResult> rows = liver_large_displacement_cases();
  expect_all_sound(rows);
  expect(rows, "large_displacement", "0.25 edges down", Outcome::kConverged);
  expect(rows, "large_displacement", "3 edges down", Outcome::kDetected);
  // Shear at the same amplitude flattens tets (reported: deformed / rest volume) without turning them over.
  expect(rows, "large_displacement", "3 edges sideways", Outcome::kConverged);
}

TEST(StabilityTest, FastToolDoesNotTunnelAndItsForceIsClamped) {
  const std::vector<CaseResult> rows = liver_tool_speed_cases();
  expect_all_sound(rows);  // a tunnelling tool or a device force above the limit makes a case "failed"
  for (const char* v : {"v=0.1 m/s", "v=1 m/s", "v=10 m/s"}) expect(rows, "tool_speed", v, Outcome::kConverged);
  expect(rows, "tool_speed", "v=10 m/s, E x 10", Outcome::kClamped);
  // Pushed through the whole organ, the contact keeps to the top face and the device holds its limit; it used to
  // re-anchor on the fixed bottom face past half the thickness and drop to 0 N, as if the organ had vanished.
  expect(rows, "tool_speed", "v=10 m/s, through", Outcome::kClamped);
  // The same final pose gives the same force whatever the speed (the shaft points behind a fast tip used to soften it).
  const double slow = find(rows, "tool_speed", "v=0.1 m/s")->max_force_n;
  EXPECT_NEAR(find(rows, "tool_speed", "v=10 m/s")->max_force_n, slow, 1e-6 * slow);
  EXPECT_NEAR(find(rows, "tool_speed", "v=1 m/s")->max_force_n, slow, 1e-6 * slow);
}

TEST(StabilityTest, IntestineSpringsFromTenToAMillionNewtonsPerMetre) {
  const std::vector<CaseResult> rows = intestine_spring_cases();
  expect_all_sound(rows);  // "diverged" is not "failed": the step guard held and every output stayed finite
  for (const char* k : {"k=10 N/m", "k=100 N/m", "k=1000 N/m", "k=10000 N/m", "k=100000 N/m", "k=1e+06 N/m"}) {
    expect(rows, "springs_implicit", k, Outcome::kConverged);  // never gains energy
    expect(rows, "springs_implicit_collide", k, Outcome::kConverged);  // ends below its initial energy
  }
  for (const char* k : {"k=10 N/m", "k=100 N/m", "k=1000 N/m"}) expect(rows, "springs_explicit", k, Outcome::kConverged);
  for (const char* k : {"k=10000 N/m", "k=100000 N/m", "k=1e+06 N/m"}) expect(rows, "springs_explicit", k, Outcome::kDiverged);
}

TEST(StabilityTest, ProbeYankedOutOfADeepContact) {
  const std::vector<CaseResult> rows = intestine_yank_cases();
  expect_all_sound(rows);  // energy growth after the yank, the clamp and the release are checked in each case
  for (const char* k : {"k_probe=300 N/m, 10 m/s", "k_probe=10000 N/m, 10 m/s", "k_probe=1e+06 N/m, 10 m/s"})
    expect(rows, "probe_yank", k, Outcome::kClamped);
  expect(rows, "probe_plunge", "k_probe=300 N/m, 10 m/s", Outcome::kClamped);
}

// Same input, bit-identical numbers (NaN where a case has none).
bool same(double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; }

TEST(StabilityTest, Deterministic) {
  for (auto group : {liver_contact_cases, liver_tool_speed_cases}) {
    const std::vector<CaseResult> a = group(), b = group();
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(csv_row(a[i]), csv_row(b[i]));
      EXPECT_TRUE(same(a[i].residual, b[i].residual) && same(a[i].condition, b[i].condition) &&
                  same(a[i].max_force_n, b[i].max_force_n) && same(a[i].max_displacement_m, b[i].max_displacement_m))
          << a[i].name << " / " << a[i].parameter;
    }
  }
}

}  // namespace
}  // namespace surgsim::stability
