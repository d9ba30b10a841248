// One instrument pushes a loop's mesentery until it folds onto the intestine of the next loop, while a
// second one holds that mesentery's own intestine in place. The contact is between a segment and the membrane, never
// between two segments: the brute-force reference, the broad phase live in the step and the stochastic detector with
// its intestine-mesentery pairs (three seeds) find it; the paper's detector of segment pairs alone finds nothing.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <memory>
#include <vector>

#include "intestine/broad_phase.h"
#include "intestine/intestine_model.h"
#include "intestine/stochastic_collision.h"

using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

int count_kind(const ContactList& list, ContactKind kind) {
  int n = 0;
  for (const auto& c : list) n += c.kind == kind;
  return n;
}

TEST(MembraneFoldTest, AProbeFoldsTheMesenteryOntoTheNextLoopAndOnlyTheTriangleCasesSeeIt) {
  // A small body: 60 x 4 masses, three folds (six legs 54 degrees apart around the vessel), no gravity (only the
  // probes move it), a stiff tool and a viscous medium so that the membrane follows the tool without overshoot.
  IntestineParams params;
  params.gravity.setZero();
  params.columns = 60;
  params.rows = 4;
  params.folds = 3;
  params.length = 2.5;
  params.drag = 20;
  params.probe_stiffness = 3000;
  params.detector = CollisionDetector::kBroadPhase;  // the live detector: every contact of the reference
  const IntestineModel model(params);
  const CollisionTopology& topo = model.topology();
  IntestineState state(model, 1);
  const double hm = topo.mesentery_half_thickness;

  // At rest, the closest pair of a segment and a mesentery triangle whose closest point lies inside the triangle,
  // along its normal, in the middle of the legs (away from the crests): a leg's sheet facing the next leg's
  // intestine, 54 degrees away around the vessel.
  int seg = -1, tri = -1;
  double rest_distance = std::numeric_limits<double>::infinity();
  Eigen::Vector3d on_sheet = Eigen::Vector3d::Zero(), u = Eigen::Vector3d::Zero();
  for (int s = 0; s < topo.segments(); ++s) {
    const Eigen::Vector3d p0 = state.x.col(topo.node(0, s)), p1 = state.x.col(topo.node(0, s + 1));
    for (int cell = 0; cell < topo.cells(); ++cell) {
      if (!topo.cell_tested(s, cell)) continue;
      for (int t = 2 * cell; t < 2 * cell + 2; ++t) {
        int n[3];
        topo.triangle(t, n);
        const Eigen::Vector3d A = state.x.col(n[0]), B = state.x.col(n[1]), C = state.x.col(n[2]);
        double param = 0;
        Eigen::Vector3d bary;
        const double d = segment_triangle(p0, p1, A, B, C, param, bary);
        if (!(d < rest_distance) || (bary.array() < 0.1).any()) continue;
        const Eigen::Vector3d a = p0 + param * (p1 - p0), b = bary[0] * A + bary[1] * B + bary[2] * C;
        Eigen::Vector3d normal = (B - A).cross(C - A).normalized();
        if (normal.dot(a - b) < 0) normal = -normal;
        const double mid = 0.4 * model.fold_amplitude();  // along the vessel (x), from the folds' centre
        if (normal.dot((a - b).normalized()) < 0.9 || std::abs(a.x()) > mid || std::abs(b.x()) > mid) continue;
        rest_distance = d;
        seg = s;
        tri = t;
        on_sheet = b;
        u = normal;
      }
    }
  }
  ASSERT_GE(seg, 0);
  const int sheet_column = (tri / 2) % (topo.cols - 1);
  // Different legs (the crest between them lies in the middle), far beyond the cells excluded around a segment.
  ASSERT_GT(std::abs(sheet_column - seg), 2 * topo.cell_exclusion);
  ASSERT_GT(rest_distance, 0.1);  // m: far apart at rest

  // Probe 0 pushes the sheet from behind towards the other loop's intestine at 5 cm/s. Probe 1 stands still against
  // the sheet's own intestine, on the side the push goes to: without it the pushed sheet drags its intestine along
  // and the two intestines meet first (a segment pair).
  Probe probes[2];
  probes[0].active = probes[1].active = true;
  probes[0].radius = 0.03;
  probes[1].radius = 0.05;
  const Eigen::Vector3d start = on_sheet - (probes[0].radius + hm + 0.003) * u;
  const Eigen::Vector3d own = 0.5 * (model.rest().col(topo.node(0, sheet_column)) +
                                     model.rest().col(topo.node(0, sheet_column + 1)));
  probes[1].center = own + (topo.intestine_radius + probes[1].radius + 0.002) * u;

  StochasticParams segments_only = params.detection;  // the paper's detector: segment pairs alone
  segments_only.random_mesentery_pairs = 0;
  StochasticDetector paper(topo, segments_only);
  const std::uint64_t seeds[3] = {1, 2, 3};
  std::vector<std::unique_ptr<StochasticDetector>> stochastic;
  for (std::uint64_t seed : seeds) {
    StochasticParams sp = params.detection;
    sp.seed = seed;
    stochastic.push_back(std::make_unique<StochasticDetector>(topo, sp));
  }
  int found_at[3] = {-1, -1, -1};
  ContactList truth(100000), found(4096), paper_found(4096);
  StepReport report;
  int first = -1;
  for (int s = 0; s < 3000; ++s) {
    probes[0].center = start + 0.05 * (s * 1e-3) * u;
    // The phases of step(), so that every detector looks at the positions the live one sees.
    step_dynamics(model, state, probes, 2, 1e-3, report);
    ASSERT_EQ(report.status, StepStatus::kOk) << "step " << s;
    truth.clear();
    detect_brute_force(topo, state.x, truth);
    step_detection(model, state, report);
    paper_found.clear();
    paper.detect(state.x, paper_found);
    for (int k = 0; k < 3; ++k) {
      found.clear();
      stochastic[static_cast<std::size_t>(k)]->detect(state.x, found);
      if (found_at[k] < 0 && count_kind(found, ContactKind::kSegmentTriangle) > 0) found_at[k] = s;
    }

    // No two segments ever touch: the reference's segment-segment part and the paper's detector find nothing.
    ASSERT_EQ(count_kind(truth, ContactKind::kSegmentSegment), 0) << "step " << s;
    EXPECT_EQ(paper_found.size(), 0) << "step " << s;
    if (first < 0 && count_kind(truth, ContactKind::kSegmentTriangle) > 0) {
      first = s;
      // The fold: the other loop's intestine against this sheet, its cells of rows 0 and 1 only.
      for (const auto& c : truth) {
        EXPECT_EQ(c.kind, ContactKind::kSegmentTriangle);
        EXPECT_LE(std::abs(c.element_a - seg), 1) << "segment " << c.element_a;
        EXPECT_LE(std::abs((c.element_b / 2) % (topo.cols - 1) - sheet_column), 3) << "triangle " << c.element_b;
      }
      // The live broad phase reports every contact of the reference.
      EXPECT_EQ(state.contacts().size(), truth.size()) << "step " << s;
      EXPECT_EQ(count_kind(state.contacts(), ContactKind::kSegmentTriangle), truth.size());
    }
    step_response(model, state, report);
    if (first >= 0 && ((found_at[0] >= 0 && found_at[1] >= 0 && found_at[2] >= 0) || s >= first + 100)) break;
  }
  ASSERT_GE(first, 0) << "the probe never folded the mesentery onto the intestine";
  for (int k = 0; k < 3; ++k) {
    // The stochastic detector's intestine-mesentery pairs find the fold within 0.1 s of its first contact, never
    // before the reference (there is nothing to find before).
    EXPECT_GE(found_at[k], first) << "seed " << seeds[k];
    EXPECT_LE(found_at[k], first + 100) << "seed " << seeds[k];
  }
  std::printf("segment %d and triangle %d (column %d) %.0f mm apart at rest; first contact at step %d; stochastic "
              "detector at steps %d %d %d\n",
              seg, tri, sheet_column, 1e3 * rest_distance, first, found_at[0], found_at[1], found_at[2]);
}

}  // namespace
}  // namespace surgsim::intestine
