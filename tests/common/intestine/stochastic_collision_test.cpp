#include "intestine/stochastic_collision.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "support/alloc_counter.h"
#include "core/error.h"
#include "intestine/broad_phase.h"
#include "intestine/intestine_model.h"
#include "mesh/geometry.h"
#include "support/intestine_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

Eigen::Vector3d random_point(std::mt19937& rng, double scale) {
  std::uniform_real_distribution<double> u(-scale, scale);
  return {u(rng), u(rng), u(rng)};
}

TEST(StochasticCollisionTest, SegmentSegmentDistanceMatchesSampling) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d p0 = random_point(rng, 1), p1 = random_point(rng, 1), q0 = random_point(rng, 1);
    // Every fourth pair parallel, to exercise the degenerate branch.
    const Eigen::Vector3d q1 = trial % 4 == 0 ? Eigen::Vector3d(q0 + 0.7 * (p1 - p0)) : random_point(rng, 1);
    double s = 0, t = 0;
    const double d = segment_segment(p0, p1, q0, q1, s, t);
    EXPECT_NEAR(d, ((p0 + s * (p1 - p0)) - (q0 + t * (q1 - q0))).norm(), 1e-12);
    double best = 1e9;
    const int n = 200;
    for (int i = 0; i <= n; ++i) {
      for (int j = 0; j <= n; ++j) {
        best = std::min(best, ((p0 + (p1 - p0) * i / n) - (q0 + (q1 - q0) * j / n)).norm());
      }
    }
    EXPECT_LE(d, best + 1e-12);
    EXPECT_GE(d, best - 0.02);
  }
}

TEST(StochasticCollisionTest, SegmentTriangleDistanceMatchesSamplingAndBoundIsConservative) {
  std::mt19937 rng(12);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d a = random_point(rng, 1), b = random_point(rng, 1), c = random_point(rng, 1);
    const Eigen::Vector3d p0 = random_point(rng, 1.5), p1 = random_point(rng, 1.5);
    double s = 0;
    Eigen::Vector3d bary;
    const double d = segment_triangle(p0, p1, a, b, c, s, bary);
    EXPECT_NEAR(bary.sum(), 1.0, 1e-12);
    EXPECT_NEAR(d, ((p0 + s * (p1 - p0)) - (bary[0] * a + bary[1] * b + bary[2] * c)).norm(), 1e-9);
    double best = 1e9;
    const int n = 60;
    for (int i = 0; i <= n; ++i) {
      const Eigen::Vector3d p = p0 + (p1 - p0) * i / n;
      for (int j = 0; j <= n; ++j) {
        for (int k = 0; j + k <= n; ++k) {
          best = std::min(best, (p - (a + (b - a) * j / n + (c - a) * k / n)).norm());
        }
      }
    }
    EXPECT_LE(d, best + 1e-12);
    EXPECT_GE(d, best - 0.06);
    // The bounded form only gives up when the distance really is at least the bound.
    for (double bound : {0.5 * d, d + 1e-9, 2 * d + 0.1}) {
      double s2 = 0;
      Eigen::Vector3d b2;
      const double db = segment_triangle(p0, p1, a, b, c, s2, b2, bound);
      if (std::isinf(db)) {
        EXPECT_GE(d, bound - 1e-12);
      } else {
        EXPECT_NEAR(db, d, 1e-12);
      }
    }
  }
  // A segment through the triangle: distance 0 at the crossing.
  double s = 0;
  Eigen::Vector3d bary;
  EXPECT_EQ(segment_triangle({0.2, 0.2, -1}, {0.2, 0.2, 1}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, s, bary), 0.0);
  EXPECT_NEAR(s, 0.5, 1e-12);
  EXPECT_NEAR(bary[1], 0.2, 1e-12);
}

// A small topology: rows x cols grid, node (r, c) = r cols + c, positions given by the test.
CollisionTopology grid_topology(int rows, int cols) {
  CollisionTopology t;
  t.rows = rows;
  t.cols = cols;
  for (int i = 0; i < rows * cols; ++i) t.grid.push_back(i);
  return t;
}

// Two straight runs of the chain crossing 3 cm apart: nodes 0..19 along x at z = 0, nodes 20..39 along -y at
// x = 0.22, z = 0.03. The closest pair is unique: segment 5 (x 0.20..0.24) under segment 30 (y 0.02..-0.02).
// Row 1 (a membrane 1 m below) completes the grid.
Eigen::Matrix3Xd crossing_runs(int cols) {
  Eigen::Matrix3Xd x(3, 2 * cols);
  for (int c = 0; c < cols; ++c) {
    const Eigen::Vector3d p = c < 20 ? Eigen::Vector3d(0.04 * c, 0, 0) : Eigen::Vector3d(0.22, 1.22 - 0.04 * c, 0.03);
    x.col(c) = p;
    x.col(cols + c) = p + Eigen::Vector3d(0, 0, -1);
  }
  return x;
}

TEST(StochasticCollisionTest, TrackedPairConvergesToTheLocalMinimumAndReportsIt) {
  const int cols = 40;
  StochasticParams params;
  params.random_pairs = params.random_mesentery_pairs = 0;
  params.max_moves = 50;
  StochasticDetector det(grid_topology(2, cols), params);
  const Eigen::Matrix3Xd x = crossing_runs(cols);
  ASSERT_TRUE(det.add_pair(1, 37, false));  // far from the minimum
  ContactList out(64);
  const DetectStats st = det.detect(x, out);
  ASSERT_EQ(det.segment_pair_count(), 1);
  EXPECT_EQ(det.segment_pair(0).a, 5);
  EXPECT_EQ(det.segment_pair(0).b, 30);
  EXPECT_NEAR(det.segment_pair(0).distance, 0.03, 1e-12);
  EXPECT_EQ(st.contacts, out.size());
  ASSERT_GE(out.size(), 1);  // 3 cm < 4 cm: in contact
  EXPECT_NEAR(out[0].distance, 0.03, 1e-12);
  EXPECT_NEAR(out[0].weights[1], 0.5, 1e-12);
  EXPECT_NEAR(out[0].weights[3], 0.5, 1e-12);
  EXPECT_NEAR(out[0].normal.z(), -1.0, 1e-12);  // from B (segment 30, above) towards A (segment 5, below)
}

TEST(StochasticCollisionTest, ConvergingPairsMergeAndFarPairsDrop) {
  const int cols = 40;
  StochasticParams params;
  params.random_pairs = params.random_mesentery_pairs = 0;
  params.max_moves = 50;
  StochasticDetector det(grid_topology(2, cols), params);
  const Eigen::Matrix3Xd x = crossing_runs(cols);
  ASSERT_TRUE(det.add_pair(1, 37, false));
  ASSERT_TRUE(det.add_pair(12, 22, false));  // both roll down to (5, 30)
  ContactList out(64);
  DetectStats st = det.detect(x, out);
  EXPECT_EQ(det.segment_pair_count(), 1);
  EXPECT_EQ(st.merged, 1);
  // Lift the second run 20 cm: the pair's distance exceeds drop_factor x 4 cm and it is dropped.
  Eigen::Matrix3Xd far = x;
  for (int c = 20; c < cols; ++c) far(2, c) += 0.2;
  out.clear();
  st = det.detect(far, out);
  EXPECT_EQ(det.segment_pair_count(), 0);
  EXPECT_EQ(st.dropped, 1);
  EXPECT_EQ(out.size(), 0);
}

TEST(StochasticCollisionTest, IntestineMesenteryPairConvergesInTwoSteps) {
  // A flat membrane (rows 1..4 at z = 0, shifted half a cell along x); the chain (row 0) runs 30 cm above it except
  // for a dip that brings its segments 20-21 down to 1.5 cm above row 2-3 of the membrane.
  const int rows = 5, cols = 30;
  CollisionTopology topo = grid_topology(rows, cols);
  Eigen::Matrix3Xd x(3, rows * cols);
  for (int r = 1; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) x.col(r * cols + c) = Eigen::Vector3d(0.04 * c + 0.02, 0.05 * r, 0);
  }
  for (int c = 0; c < cols; ++c) {
    const double w = std::clamp(1.0 - (std::abs(c - 20.5) - 0.5) / 6.0, 0.0, 1.0);
    x.col(c) = Eigen::Vector3d(0.04 * c, 0.125 * w, 0.3 - 0.285 * w + 0.002 * (c - 20) * (c - 20));
  }
  StochasticParams params;
  params.random_pairs = params.random_mesentery_pairs = 0;
  params.max_moves = 60;
  StochasticDetector det(topo, params);
  const int cw = cols - 1;
  ASSERT_TRUE(det.add_pair(26, 3 * cw + 12, true));  // a far segment and a far cell
  ContactList out(64);
  det.detect(x, out);
  ASSERT_EQ(det.cell_pair_count(), 1);
  // Reference: the closest (segment, cell) over all tested pairs.
  double best = 1e9;
  for (int s = 0; s < cw; ++s) {
    for (int cell = 0; cell < topo.cells(); ++cell) {
      if (!topo.cell_tested(s, cell)) continue;
      for (int t = 0; t < 2; ++t) {
        int n[3];
        topo.triangle(2 * cell + t, n);
        double ss = 0;
        Eigen::Vector3d bb;
        best = std::min(best, segment_triangle(x.col(s), x.col(s + 1), x.col(n[0]), x.col(n[1]), x.col(n[2]), ss, bb));
      }
    }
  }
  EXPECT_NEAR(det.cell_pair(0).distance, best, 1e-12);
  ASSERT_GE(out.size(), 1);
  EXPECT_EQ(out[0].kind, ContactKind::kSegmentTriangle);
  EXPECT_EQ(out[0].count_b, 3);
  EXPECT_GT(out[0].normal.z(), 0.99);  // from the membrane up to the chain
}

TEST(StochasticCollisionTest, NeighboursAndMesenteryPairsAreNeverTested) {
  IntestineParams p;
  p.detection.random_pairs = p.detection.random_mesentery_pairs = 50;
  const IntestineModel model(p);
  IntestineState state(model, 3);
  StepReport report;
  const CollisionTopology& topo = model.topology();
  for (int s = 0; s < 600; ++s) {
    step(model, state, test::scripted_probe(0.4 + s * 1e-3), 1e-3, report);
    for (const auto& c : state.contacts()) {
      ASSERT_LT(c.element_a, topo.segments());
      // Side A is always an intestine segment: no mesentery-mesentery contact exists.
      EXPECT_EQ(c.nodes[0], topo.node(0, c.element_a));
      if (c.kind == ContactKind::kSegmentSegment) {
        EXPECT_GT(std::abs(c.element_a - c.element_b), topo.segment_exclusion);
      } else {
        EXPECT_TRUE(topo.cell_tested(c.element_a, c.element_b / 2));
      }
    }
    for (int i = 0; i < state.detector().segment_pair_count(); ++i) {
      const ActivePair& ap = state.detector().segment_pair(i);
      EXPECT_TRUE(topo.segments_tested(ap.a, ap.b));
    }
  }
}

TEST(StochasticCollisionTest, BruteForceCullMissesNothing) {
  IntestineParams p;
  const IntestineModel model(p);
  IntestineState state(model, 5);
  StepReport report;
  for (int s = 0; s < 500; ++s) step(model, state, test::scripted_probe(0.4 + s * 1e-3), 1e-3, report);
  ContactList culled(100000);
  detect_brute_force(model.topology(), state.x, culled);
  // Without the bounding-box cull.
  const CollisionTopology& topo = model.topology();
  long exact = 0;
  for (int a = 0; a < topo.segments(); ++a) {
    for (int b = a + 1; b < topo.segments(); ++b) {
      double s = 0, t = 0;
      if (topo.segments_tested(a, b) &&
          segment_segment(state.x.col(a), state.x.col(a + 1), state.x.col(b), state.x.col(b + 1), s, t) <
              2 * topo.intestine_radius) {
        ++exact;
      }
    }
    for (int tri = 0; tri < 2 * topo.cells(); ++tri) {
      if (!topo.cell_tested(a, tri / 2)) continue;
      int n[3];
      topo.triangle(tri, n);
      double s = 0;
      Eigen::Vector3d bb;
      if (segment_triangle(state.x.col(a), state.x.col(a + 1), state.x.col(n[0]), state.x.col(n[1]),
                           state.x.col(n[2]), s, bb) < topo.intestine_radius + topo.mesentery_half_thickness) {
        ++exact;
      }
    }
  }
  EXPECT_GT(exact, 10);
  EXPECT_EQ(culled.size(), exact);
}

// The paper's fig. 14 as numbers: over a scripted run (gravity folds the intestine onto itself, the probe pushes
// and lifts the folds), how many of the brute-force contacts the stochastic detector reports, on the same positions.
TEST(StochasticCollisionTest, RecallAgainstBruteForceOverAScriptedRun) {
  IntestineParams p;  // n = 10 random pairs of each kind per step
  const IntestineModel model(p);
  IntestineState state(model, 1);
  StepReport report;
  ContactList truth(100000);
  RecallStats total;
  double residual = 0;
  for (int s = 0; s < 1800; ++s) {
    step_dynamics(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
    step_detection(model, state, report);
    if (s % 10 == 0) {
      truth.clear();
      detect_brute_force(model.topology(), state.x, truth);
      total += compare_with_reference(model.topology(), state.contacts(), truth);
    }
    step_response(model, state, report);
    if (s % 10 == 0) {
      truth.clear();
      detect_brute_force(model.topology(), state.x, truth);
      for (const auto& c : truth) residual = std::max(residual, c.radius_sum - c.distance);
    }
  }
  std::printf("recall over the scripted run (n = %d): pairs %.3f (%ld / %ld), penetration-weighted %.3f, contact zones "
              "%.3f (%ld / %ld); deepest missed %.4f m; largest penetration left after the response %.4f m\n",
              p.detection.random_pairs, total.pair_recall(), total.found, total.truth, total.depth_recall(),
              total.region_recall(), total.regions_found, total.regions, total.max_missed, residual);
  EXPECT_GT(total.truth, 1000);
  EXPECT_GT(total.pair_recall(), 0.85);
  EXPECT_GT(total.depth_recall(), 0.5);  // the found contacts are resolved at once and stay shallow
  EXPECT_GT(total.region_recall(), 0.85);
  EXPECT_LT(residual, 0.5 * p.intestine_radius);  // never near crossing the tube
}

// The loop's own detection and response on crafted crossings in the real model, no dynamics: one leg of a fold
// pushed three quarters of the way onto the other leg (the tubes overlap by centimetres along several segments), and
// a segment of another fold pushed to 5 mm from the nearest mesentery it does not belong to. Both are undone within
// 40 steps (the random pairs have to find every part of the crafted zones first).
TEST(StochasticCollisionTest, StochasticDetectionAndResponseUntangleCraftedCrossings) {
  const IntestineModel model(IntestineParams{});
  const CollisionTopology& topo = model.topology();
  IntestineState state(model, 4);
  // The fold whose crest is node 10: nodes 10 - k and 10 + k face each other.
  for (int c = 4; c <= 8; ++c) state.x.col(c) += 0.75 * (state.x.col(20 - c) - state.x.col(c));
  // Segment 45 and its closest tested mesentery triangle at rest.
  double best = 1e9, sp = 0;
  Eigen::Vector3d pb = Eigen::Vector3d::Zero();
  for (int tri = 0; tri < 2 * topo.cells(); ++tri) {
    if (!topo.cell_tested(45, tri / 2)) continue;
    int n[3];
    topo.triangle(tri, n);
    double s = 0;
    Eigen::Vector3d bary;
    const double d = segment_triangle(state.x.col(45), state.x.col(46), state.x.col(n[0]), state.x.col(n[1]),
                                      state.x.col(n[2]), s, bary);
    if (d < best) {
      best = d;
      sp = s;
      pb = bary[0] * state.x.col(n[0]) + bary[1] * state.x.col(n[1]) + bary[2] * state.x.col(n[2]);
    }
  }
  const Eigen::Vector3d pa = state.x.col(45) + sp * (state.x.col(46) - state.x.col(45));
  const Eigen::Vector3d shift = (pb - pa) * (1 - 0.005 / best);
  state.x.col(45) += shift;
  state.x.col(46) += shift;

  ContactList truth(100000);
  detect_brute_force(topo, state.x, truth);
  double before = 0;
  bool membrane = false;
  for (const auto& c : truth) {
    before = std::max(before, c.radius_sum - c.distance);
    membrane = membrane || (c.kind == ContactKind::kSegmentTriangle && c.element_a == 45);
  }
  ASSERT_GT(before, 0.02);
  ASSERT_TRUE(membrane);
  StepReport report;
  for (int s = 0; s < 40; ++s) {  // 40 ms at the haptic rate
    step_detection(model, state, report);
    step_response(model, state, report);
  }
  truth.clear();
  detect_brute_force(topo, state.x, truth);
  double left = 0;
  for (const auto& c : truth) left = std::max(left, c.radius_sum - c.distance);
  EXPECT_LT(left, 1e-3) << truth.size() << " contacts left, deepest " << left << " m";
}

// A mesentery fold pushed onto the middle of an intestine segment far from it along the chain (what a probe pressing
// the membrane against a loop does): the four nodes of cell (row 1, column 70) are moved so that the cell stands
// across segment 30, (a) pierced at its middle (segment crossing the triangle) and (b) with one edge 5 mm from the
// segment's middle (edge-triangle: the closest points are the middle of the segment and of that edge). No intestine
// node moves, so no segment-segment pair comes close: the segment tests alone (the paper's) never see it; the
// point/edge-triangle cases do, in the reference, in the exact broad phase and in the stochastic detector's
// intestine-mesentery pairs.
TEST(StochasticCollisionTest, MembraneFoldOnASegmentIsCaughtOnlyByTheTriangleCases) {
  const IntestineModel model(IntestineParams{});
  const CollisionTopology& topo = model.topology();
  const int seg = 30, col = 70, cw = topo.cols - 1, cell = 1 * cw + col;
  for (int variant = 0; variant < 2; ++variant) {
    SCOPED_TRACE(variant == 0 ? "pierced" : "edge");
    IntestineState state(model, 5);
    const Eigen::Vector3d p0 = state.x.col(topo.node(0, seg)), p1 = state.x.col(topo.node(0, seg + 1));
    const Eigen::Vector3d m = 0.5 * (p0 + p1), d = (p1 - p0).normalized();
    const Eigen::Vector3d u = d.cross(Eigen::Vector3d::UnitZ()).normalized(), w = d.cross(u);
    const double h = 0.02;
    // The cell's square in the plane (u, w) across the segment: (a) centred a little off the diagonal, so that the
    // segment pierces triangle 0's interior; (b) moved by h + 5 mm along u, its edge 5 mm from the middle.
    const Eigen::Vector3d centre = variant == 0 ? Eigen::Vector3d(m + 0.3 * h * u - 0.1 * h * w)
                                                : Eigen::Vector3d(m + (h + 0.005) * u);
    state.x.col(topo.node(1, col)) = centre - h * u - h * w;
    state.x.col(topo.node(1, col + 1)) = centre + h * u - h * w;
    state.x.col(topo.node(2, col + 1)) = centre + h * u + h * w;
    state.x.col(topo.node(2, col)) = centre - h * u + h * w;

    ContactList truth(100000), broad_found(100000);
    detect_brute_force(topo, state.x, truth);
    const CollisionContact* fold = nullptr;  // the cell's closer triangle
    for (const auto& c : truth) {
      if (c.kind == ContactKind::kSegmentTriangle && c.element_a == seg && c.element_b / 2 == cell &&
          (fold == nullptr || c.distance < fold->distance)) {
        fold = &c;
      }
      EXPECT_FALSE(c.kind == ContactKind::kSegmentSegment && (c.element_a == seg || c.element_b == seg))
          << "segment pair " << c.element_a << "-" << c.element_b << " at " << c.distance;
    }
    ASSERT_NE(fold, nullptr);
    EXPECT_LT(fold->distance, variant == 0 ? 1e-12 : 0.0051);
    EXPECT_GT(fold->weights[1], 0.3);  // at the segment's middle, not at an end
    EXPECT_LT(fold->weights[1], 0.7);
    BroadPhaseDetector broad(topo);
    broad.detect(state.x, broad_found);
    EXPECT_EQ(broad_found.size(), truth.size());

    // The paper's segment tests alone: never, however long they search.
    auto caught = [&](const StochasticParams& params, int steps) {
      StochasticDetector det(topo, params);
      ContactList out(4096);
      for (int s = 0; s < steps; ++s) {
        out.clear();
        det.detect(state.x, out);
        for (const auto& c : out) {
          if (c.element_a == seg && c.kind == ContactKind::kSegmentTriangle && c.element_b / 2 == cell) return s;
        }
      }
      return -1;
    };
    StochasticParams segments_only = model.params().detection;
    segments_only.random_mesentery_pairs = 0;
    EXPECT_EQ(caught(segments_only, 300), -1);
    // With the intestine-mesentery pairs (n = 10 a step): found within 300 steps (0.3 s), for every seed tried.
    for (std::uint64_t seed : {1, 2, 3}) {
      StochasticParams params = model.params().detection;
      params.seed = seed;
      const int at = caught(params, 300);
      EXPECT_GE(at, 0) << "seed " << seed;
    }
  }
}

TEST(StochasticCollisionTest, SameSeedSameResultOtherSeedOtherPairs) {
  const IntestineModel model(IntestineParams{});
  auto run = [&](std::uint64_t seed, IntestineState& st) {
    StepReport r;
    for (int s = 0; s < 500; ++s) step(model, st, test::scripted_probe(0.3 + s * 1e-3), 1e-3, r);
  };
  IntestineState a(model, 42), b(model, 42), c(model, 43);
  run(42, a);
  run(42, b);
  run(43, c);
  EXPECT_EQ(std::memcmp(a.x.data(), b.x.data(), sizeof(double) * static_cast<std::size_t>(a.x.size())), 0);
  EXPECT_EQ(std::memcmp(a.v.data(), b.v.data(), sizeof(double) * static_cast<std::size_t>(a.v.size())), 0);
  ASSERT_EQ(a.detector().segment_pair_count(), b.detector().segment_pair_count());
  for (int i = 0; i < a.detector().segment_pair_count(); ++i) {
    EXPECT_EQ(a.detector().segment_pair(i).a, b.detector().segment_pair(i).a);
    EXPECT_EQ(a.detector().segment_pair(i).b, b.detector().segment_pair(i).b);
  }
  EXPECT_NE(a.x, c.x);  // another seed draws other pairs
}

TEST(StochasticCollisionTest, DetectAllocatesNothing) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 9);
  StepReport report;
  for (int s = 0; s < 300; ++s) step(model, state, Probe{}, 1e-3, report);
  ContactList out(2048);
  StochasticDetector& det = state.detector();
  det.set_random_pairs(100, 100);
  surgsim::test::AllocationCounter counter;
  for (int s = 0; s < 20; ++s) {
    out.clear();
    det.detect(state.x, out);
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_GT(out.size(), 0);
}

TEST(StochasticCollisionTest, RejectsBadSetups) {
  StochasticParams params;
  EXPECT_THROW(StochasticDetector(grid_topology(1, 10), params), Error);
  params.drop_factor = 0.5;
  EXPECT_THROW(StochasticDetector(grid_topology(2, 10), params), Error);
  params = StochasticParams{};
  params.capacity = 0;
  EXPECT_THROW(StochasticDetector(grid_topology(2, 10), params), Error);
}

}  // namespace
}  // namespace surgsim::intestine
