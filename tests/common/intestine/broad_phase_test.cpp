// The exact broad phase (intestine/broad_phase.h) against the brute-force reference: the same contacts, value for
// value, over the scripted run and on crafted membrane crossings; no allocation once built.
#include "intestine/broad_phase.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <tuple>
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
