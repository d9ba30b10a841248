// The exact broad phase (intestine/broad_phase.h) against the brute-force reference: the same contacts, value for
// value, over the scripted run and on crafted membrane crossings; no allocation once built. Under motion the sleeping
// pairs are checked against an all-pairs distance check written here (nodes that teleport, jumps of one margin).
#include "intestine/broad_phase.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "support/alloc_counter.h"
#include "intestine/intestine_model.h"
#include "support/intestine_test_util.h"

using namespace surgsim::intestine;

namespace surgsim::intestine {
namespace {

using Key = std::tuple<int, int, int, double, double, double>;

std::vector<Key> keys(const ContactList& l) {
  std::vector<Key> k;
  for (const auto& c : l) {
    k.emplace_back(static_cast<int>(c.kind), c.element_a, c.element_b, c.distance, c.weights[1], c.normal.x());
  }
  std::sort(k.begin(), k.end());
  return k;
}

TEST(BroadPhaseTest, SameContactsAsBruteForceOverTheScriptedRun) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 1);
  BroadPhaseDetector broad(model.topology());
  StepReport report;
  ContactList truth(100000), found(100000);
  long contacts = 0, membrane = 0;
  for (int s = 0; s < 1200; ++s) {
    step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
    if (s % 5 != 0) continue;
    for (double margin : {0.0, 0.01}) {
      truth.clear();
      found.clear();
      detect_brute_force(model.topology(), state.x, truth, margin);
      const BroadPhaseStats st = broad.detect(state.x, found, margin);
      ASSERT_EQ(keys(found), keys(truth)) << "step " << s << " margin " << margin;
      EXPECT_EQ(st.contacts, found.size());
      EXPECT_GE(st.overlaps, st.contacts);
      if (margin == 0) {
        contacts += truth.size();
        for (const auto& c : truth) membrane += c.kind == ContactKind::kSegmentTriangle;
      }
    }
  }
  EXPECT_GT(contacts, 5000);  // the run has contacts of both kinds to compare
  EXPECT_GT(membrane, 500);
}

// Called every step at one margin, pairs far apart sleep until their nodes could have closed the gap: still every
// contact of the reference, value for value, at every step (and most pairs do sleep).
TEST(BroadPhaseTest, SameContactsAsBruteForceWhilePairsSleep) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 1);
  BroadPhaseDetector broad(model.topology());
  StepReport report;
  ContactList truth(100000), found(100000);
  long asleep = 0, overlaps = 0;
  for (int s = 0; s < 1700; ++s) {
    step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
    truth.clear();
    found.clear();
    detect_brute_force(model.topology(), state.x, truth);
    const BroadPhaseStats st = broad.detect(state.x, found);
    ASSERT_EQ(keys(found), keys(truth)) << "step " << s;
    asleep += st.asleep;
    overlaps += st.overlaps;
  }
  EXPECT_GT(asleep, overlaps);  // the feature is at work: more pairs asleep than boxes overlapping
  // After reset() nothing sleeps.
  broad.reset();
  found.clear();
  EXPECT_EQ(broad.detect(state.x, found).asleep, 0);
}

// A block pair whose boxes overlap but whose element pairs all sleep sleeps as a whole (for the smallest of
// their slacks), so on a body that has not moved none of its element pairs is looked at again.
TEST(BroadPhaseTest, BlockPairsWhoseElementPairsAllSleepAreNotLookedAt) {
  const IntestineModel model(IntestineParams{});
  const IntestineState state(model, 1);  // the rest shape: free of contacts
  BroadPhaseDetector broad(model.topology());
  ContactList out(4096);
  const BroadPhaseStats first = broad.detect(state.x, out);
  ASSERT_EQ(out.size(), 0);
  EXPECT_EQ(first.asleep, 0);
  EXPECT_GT(first.overlaps, 0);  // element pairs of overlapping block pairs tested, then put to sleep
  const BroadPhaseStats second = broad.detect(state.x, out);
  EXPECT_EQ(second.asleep, 0);    // not even looked at: their block pairs sleep
  EXPECT_EQ(second.overlaps, 0);
  EXPECT_EQ(out.size(), 0);
}

// ---- An all-pairs reference independent of the detector: every pair's exact distance, by its own formulas ----

using V3 = Eigen::Vector3d;

double point_segment_distance(const V3& p, const V3& a, const V3& b) {
  const V3 ab = b - a;
  const double l2 = ab.squaredNorm();
  const double t = l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

// |P(s) - Q(t)| is convex over the unit square: its minimum lies on the square's boundary (an end of one segment
// against the other) or where the lines' common perpendicular meets both segments inside. Also gives the closest
// points.
double segment_distance(const V3& p0, const V3& p1, const V3& q0, const V3& q1, V3* on_p = nullptr,
                        V3* on_q = nullptr) {
  const V3 u = p1 - p0, v = q1 - q0, w = p0 - q0;
  auto along = [](const V3& p, const V3& a, const V3& ab) {
    const double l2 = ab.squaredNorm();
    return l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
  };
  // Candidates (s, t): each end against the other segment, then the common perpendicular (the first again when it
  // misses either segment).
  std::pair<double, double> st[5] = {{0, along(p0, q0, v)},
                                     {1, along(p1, q0, v)},
                                     {along(q0, p0, u), 0},
                                     {along(q1, p0, u), 1},
                                     {0, along(p0, q0, v)}};
  const double a = u.dot(u), b = u.dot(v), c = v.dot(v), du = u.dot(w), dv = v.dot(w);
  const double den = a * c - b * b;
  if (den > 1e-12 * a * c) {
    const double s = (b * dv - c * du) / den, t = (a * dv - b * du) / den;
    if (s > 0 && s < 1 && t > 0 && t < 1) st[4] = {s, t};
  }
  double best = std::numeric_limits<double>::infinity();
  for (const auto& [s, t] : st) {
    const double d = (w + s * u - t * v).norm();
    if (d < best) {
      best = d;
      if (on_p != nullptr) *on_p = p0 + s * u;
      if (on_q != nullptr) *on_q = q0 + t * v;
    }
  }
  return best;
}

// Whether q, a point of the plane of (a, b, c), lies inside the triangle (n its normal).
bool in_triangle(const V3& q, const V3& a, const V3& b, const V3& c, const V3& n) {
  return (b - a).cross(q - a).dot(n) >= 0 && (c - b).cross(q - b).dot(n) >= 0 && (a - c).cross(q - c).dot(n) >= 0;
}

double point_triangle_distance(const V3& p, const V3& a, const V3& b, const V3& c) {
  const V3 n = (b - a).cross(c - a);
  const double n2 = n.squaredNorm();
  if (n2 > 0) {
    const double h = (p - a).dot(n) / n2;
    if (in_triangle(p - h * n, a, b, c, n)) return std::abs(h) * std::sqrt(n2);  // above the inside
  }
  return std::min(std::min(point_segment_distance(p, a, b), point_segment_distance(p, b, c)),
                  point_segment_distance(p, c, a));
}

// Zero when the segment pierces the triangle; otherwise the minimum lies on the boundary of segment x triangle: an end
// of the segment against the triangle, or the segment against an edge (convexity, as for two segments; a minimum
// inside with a positive distance means a direction along which the distance is constant, which reaches it).
double segment_triangle_distance(const V3& p0, const V3& p1, const V3& a, const V3& b, const V3& c) {
  const V3 n = (b - a).cross(c - a);
  const double h0 = (p0 - a).dot(n), h1 = (p1 - a).dot(n);
  if (((h0 < 0 && h1 > 0) || (h0 > 0 && h1 < 0)) && in_triangle(p0 + (h0 / (h0 - h1)) * (p1 - p0), a, b, c, n)) {
    return 0;
  }
  return std::min({point_triangle_distance(p0, a, b, c), point_triangle_distance(p1, a, b, c),
                   segment_distance(p0, p1, a, b), segment_distance(p0, p1, b, c), segment_distance(p0, p1, c, a)});
}

using Pair = std::tuple<int, int, int>;  // kind, segment, segment or triangle (2 cell + t)

// Every tested pair closer than `bound - tol` (must be found), and every tested pair closer than `bound + tol` (may
// be found: rounding at the contact distance decides), by the distances above over all pairs. Only pairs whose
// bounding spheres (centre of the element's corners, farthest corner) are apart by the bound are left out.
void reference_pairs(const CollisionTopology& topo, const Eigen::Matrix3Xd& x, double margin, double tol,
                     std::set<Pair>& must, std::set<Pair>& may) {
  must.clear();
  may.clear();
  auto seg = [&](int a, int end) { return V3(x.col(topo.node(0, a + end))); };
  const double seg_bound = 2 * topo.intestine_radius + margin;
  const double tri_bound = topo.intestine_radius + topo.mesentery_half_thickness + margin;
  auto note = [&](const Pair& p, double d, double bound) {
    if (d < bound - tol) must.insert(p);
    if (d < bound + tol) may.insert(p);
  };
  auto sphere_apart = [&](const V3& c0, double r0, const V3& c1, double r1, double bound) {
    return (c0 - c1).norm() - r0 - r1 >= bound + tol;
  };
  for (int a = 0; a < topo.segments(); ++a) {
    const V3 pa = seg(a, 0), qa = seg(a, 1), ca = 0.5 * (pa + qa);
    const double ra = 0.5 * (qa - pa).norm();
    for (int b = a + 1; b < topo.segments(); ++b) {
      if (!topo.segments_tested(a, b)) continue;
      const V3 pb = seg(b, 0), qb = seg(b, 1);
      if (sphere_apart(ca, ra, 0.5 * (pb + qb), 0.5 * (qb - pb).norm(), seg_bound)) continue;
      note({static_cast<int>(ContactKind::kSegmentSegment), a, b}, segment_distance(pa, qa, pb, qb), seg_bound);
    }
    for (int cell = 0; cell < topo.cells(); ++cell) {
      if (!topo.cell_tested(a, cell)) continue;
      for (int t = 2 * cell; t < 2 * cell + 2; ++t) {
        int n[3];
        topo.triangle(t, n);
        const V3 u = x.col(n[0]), v = x.col(n[1]), w = x.col(n[2]), ct = (u + v + w) / 3;
        const double rt = std::max({(u - ct).norm(), (v - ct).norm(), (w - ct).norm()});
        if (sphere_apart(ca, ra, ct, rt, tri_bound)) continue;
        note({static_cast<int>(ContactKind::kSegmentTriangle), a, t}, segment_triangle_distance(pa, qa, u, v, w),
             tri_bound);
      }
    }
  }
}

// What the detector found at one step, checked against the all-pairs reference: nothing within the contact distance
// missed, nothing found beyond it, and the contacts of detect_brute_force value for value. Returns the contacts.
long check_step(BroadPhaseDetector& broad, const Eigen::Matrix3Xd& x, double margin, const std::string& where,
                long& asleep) {
  static ContactList found(20000), truth(20000);
  found.clear();
  truth.clear();
  const BroadPhaseStats st = broad.detect(x, found, margin);
  asleep += st.asleep;
  EXPECT_EQ(st.overflow, 0) << where;
  std::set<Pair> got, must, may;
  for (const auto& c : found) got.insert({static_cast<int>(c.kind), c.element_a, c.element_b});
  EXPECT_EQ(got.size(), static_cast<std::size_t>(found.size())) << where << ": a pair reported twice";
  reference_pairs(broad.topology(), x, margin, 1e-9, must, may);
  std::ostringstream missed, extra;
  for (const Pair& p : must) {
    if (!got.count(p)) missed << " (" << std::get<0>(p) << ", " << std::get<1>(p) << ", " << std::get<2>(p) << ")";
  }
  for (const Pair& p : got) {
    if (!may.count(p)) extra << " (" << std::get<0>(p) << ", " << std::get<1>(p) << ", " << std::get<2>(p) << ")";
  }
  EXPECT_TRUE(missed.str().empty()) << where
                                    << ": pairs within the contact distance missed (kind, a, b):" << missed.str();
  EXPECT_TRUE(extra.str().empty()) << where << ": pairs beyond the contact distance reported:" << extra.str();
  detect_brute_force(broad.topology(), x, truth, margin);
  EXPECT_EQ(keys(found), keys(truth)) << where;
  return static_cast<long>(must.size());
}

// Uniform in [0, 1) from the generator's bits (std's distributions differ between standard libraries).
double uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

V3 unit_vector(std::mt19937_64& rng) {
  for (;;) {
    const V3 v(2 * uniform(rng) - 1, 2 * uniform(rng) - 1, 2 * uniform(rng) - 1);
    const double n = v.norm();
    if (n > 0.1 && n <= 1) return v / n;
  }
}

// The folds pressed together by the scripted probe: a body with contacts of both kinds and many near misses.
Eigen::Matrix3Xd folded_state(const IntestineModel& model) {
  IntestineState state(model, 1);
  StepReport report;
  for (int s = 0; s < 900; ++s) step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
  return state.x;
}

// Nodes teleport: each step some nodes (or runs of whole columns) jump far in one step - onto another part of the
// body, far away, or back where they were - every 20 steps all of them jump back, and now and then the whole body
// jumps 100 m and back. Pairs asleep for a long gap are woken by one jump and found at once; every step is checked
// against the all-pairs reference.
TEST(BroadPhaseTest, NoContactMissedWhenNodesTeleport) {
  const IntestineModel model(IntestineParams{});
  const CollisionTopology& topo = model.topology();
  const Eigen::Matrix3Xd base = folded_state(model);
  std::mt19937_64 rng(7);
  for (const double margin : {0.0, 0.01}) {
    BroadPhaseDetector broad(topo);
    Eigen::Matrix3Xd x = base;
    long asleep = 0, contacts = 0, sleeping_steps = 0;
    for (int s = 0; s < 240; ++s) {
      const int events = 1 + static_cast<int>(uniform(rng) * 4);
      for (int e = 0; e < events; ++e) {
        const double kind = uniform(rng);
        // A run of whole columns (every row: segments and cells) or a single node.
        const int c0 = static_cast<int>(uniform(rng) * topo.cols);
        const int width = kind < 0.3 ? 1 + static_cast<int>(uniform(rng) * 6) : 1;
        const int r0 = width > 1 ? 0 : static_cast<int>(uniform(rng) * topo.rows);
        const int r1 = width > 1 ? topo.rows : r0 + 1;
        const int anchor = topo.node(0, static_cast<int>(uniform(rng) * topo.cols));
        const V3 target = kind < 0.6   ? V3(x.col(anchor) + 0.02 * unit_vector(rng))  // onto another part
                          : kind < 0.8 ? V3(x.col(anchor) + 0.5 * unit_vector(rng))   // far away
                                       : V3::Zero();                                  // back where it was
        const int first = topo.node(r0, c0);
        const V3 shift = target - x.col(first);
        for (int c = c0; c < std::min(topo.cols, c0 + width); ++c) {
          for (int r = r0; r < r1; ++r) {
            const int n = topo.node(r, c);
            x.col(n) = kind < 0.8 ? V3(x.col(n) + shift) : V3(base.col(n));
          }
        }
      }
      if (s % 20 == 19) x = base;                           // every jumped node back at once
      if (s % 60 == 30) x.colwise() += V3(100, -100, 100);  // the whole body jumps away ...
      if (s % 60 == 31) x.colwise() -= V3(100, -100, 100);  // ... and back
      const long asleep_before = asleep;
      contacts +=
          check_step(broad, x, margin, "margin " + std::to_string(margin) + " step " + std::to_string(s), asleep);
      sleeping_steps += asleep > asleep_before ? 1 : 0;
      if (HasFailure()) return;
    }
    std::printf("margin %g: %ld contacts, %ld pairs asleep, %ld steps with sleeping pairs\n", margin, contacts, asleep,
                sleeping_steps);
    EXPECT_GT(contacts, 1000) << "margin " << margin;       // the jumps make contacts to find
    EXPECT_GT(sleeping_steps, 100) << "margin " << margin;  // and pairs do sleep between them
  }
}

// Jumps of one margin: every step each node moves with probability 1/2, by a jump of about the margin (within
// 1e-3 of it) in a random direction (kept within a few margins of the folded body): pairs whose gap is a few jumps
// sleep for about as many steps and wake as the last jump closes it.
TEST(BroadPhaseTest, NoContactMissedWithJumpsOfOneMargin) {
  const IntestineModel model(IntestineParams{});
  const CollisionTopology& topo = model.topology();
  const Eigen::Matrix3Xd base = folded_state(model);
  std::mt19937_64 rng(11);
  for (const double margin : {0.004, 0.01}) {
    BroadPhaseDetector broad(topo);
    Eigen::Matrix3Xd x = base;
    long asleep = 0, contacts = 0;
    for (int s = 0; s < 240; ++s) {
      for (Eigen::Index n = 0; n < x.cols(); ++n) {
        if (uniform(rng) < 0.5) continue;
        const double jump = margin * (0.999 + 0.002 * uniform(rng));
        V3 offset = x.col(n) - base.col(n);
        offset += jump * (offset.norm() > 4 * margin ? V3(-offset.normalized()) : unit_vector(rng));
        x.col(n) = base.col(n) + offset;
      }
      contacts +=
          check_step(broad, x, margin, "margin " + std::to_string(margin) + " step " + std::to_string(s), asleep);
      if (HasFailure()) return;
    }
    std::printf("margin %g: %ld contacts, %ld pairs asleep\n", margin, contacts, asleep);
    EXPECT_GT(contacts, 1000) << "margin " << margin;
    EXPECT_GT(asleep, 100000) << "margin " << margin;  // the sleeping pairs are what this exercises
  }
}

// Pairs closing head on: a run of whole columns moves rigidly, one margin a step, straight towards another segment
// along the line between their closest points, so their gap shrinks by exactly what they travel (the bound a
// sleeping pair relies on, with no slack to spare); the pair is found the step it comes within the contact distance.
// Then the run jumps back and another pair closes.
TEST(BroadPhaseTest, PairsClosingHeadOnAreFoundTheStepTheyTouch) {
  const IntestineModel model(IntestineParams{});
  const CollisionTopology& topo = model.topology();
  const Eigen::Matrix3Xd base = folded_state(model);
  std::mt19937_64 rng(5);
  auto end = [&](const Eigen::Matrix3Xd& x, int a, int k) { return V3(x.col(topo.node(0, a + k))); };
  for (const double margin : {0.003, 0.01}) {
    const double bound = 2 * topo.intestine_radius + margin;
    BroadPhaseDetector broad(topo);
    Eigen::Matrix3Xd x = base;
    long asleep = 0;
    int closed = 0;
    int a = -1, b = -1;  // the moving segment (its run: columns a - 1 .. a + 2) and its target
    for (int s = 0; s < 400; ++s) {
      if (a < 0) {
        // A new pair: a segment and a target between 4 and 12 jumps beyond the contact distance.
        x = base;
        for (int tries = 0; tries < 1000 && a < 0; ++tries) {
          const int ca = 1 + static_cast<int>(uniform(rng) * (topo.segments() - 3));
          const int cb = static_cast<int>(uniform(rng) * topo.segments());
          if (std::abs(ca - cb) < 8) continue;
          const double d = segment_distance(end(x, ca, 0), end(x, ca, 1), end(x, cb, 0), end(x, cb, 1));
          if (d > bound + 4 * margin && d < bound + 12 * margin) {
            a = ca;
            b = cb;
          }
        }
        ASSERT_GE(a, 0) << "no pair to close";
      } else {
        V3 on_a = V3::Zero(), on_b = V3::Zero();
        segment_distance(end(x, a, 0), end(x, a, 1), end(x, b, 0), end(x, b, 1), &on_a, &on_b);
        const V3 jump = margin * (on_b - on_a).normalized();
        for (int c = a - 1; c <= a + 2; ++c) {
          for (int r = 0; r < topo.rows; ++r) x.col(topo.node(r, c)) += jump;
        }
      }
      check_step(broad, x, margin, "margin " + std::to_string(margin) + " step " + std::to_string(s), asleep);
      if (HasFailure()) return;
      if (segment_distance(end(x, a, 0), end(x, a, 1), end(x, b, 0), end(x, b, 1)) < bound) {
        ++closed;
        a = b = -1;
      }
    }
    std::printf("margin %g: %d pairs closed head on, %ld pairs asleep\n", margin, closed, asleep);
    EXPECT_GT(closed, 20) << "margin " << margin;
    EXPECT_GT(asleep, 100000) << "margin " << margin;
  }
}

TEST(BroadPhaseTest, DetectAllocatesNothing) {
  const IntestineModel model(IntestineParams{});
  IntestineState state(model, 1);
  StepReport report;
  for (int s = 0; s < 600; ++s) step(model, state, test::scripted_probe(s * 1e-3), 1e-3, report);
  BroadPhaseDetector broad(model.topology());
  ContactList out(4096);
  broad.detect(state.x, out);  // first sort
  surgsim::test::AllocationCounter counter;
  for (int s = 0; s < 20; ++s) {
    out.clear();
    broad.detect(state.x, out);
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_GT(out.size(), 0);
}

}  // namespace
}  // namespace surgsim::intestine
