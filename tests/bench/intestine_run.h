// intestine_run.h: the intestine benchmarks' scripted run (intestine_bench, intestine_error_bench): the default
// model stepped along the scripted probe (tests/support/intestine_test_util.h), each phase of the step timed, the
// stochastic detector compared with the brute-force reference on the same positions.
#pragma once
#include <algorithm>
#include <cstdint>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "bench_util.h"
#include "intestine/intestine_model.h"
#include "support/intestine_test_util.h"

namespace surgsim::intestine::bench {

struct RunResult {
  std::vector<double> total, dynamics, detection, response;  // wall clock per step, us
  std::vector<double> cpu;                                   // thread CPU time per step, us
  intestine::RecallStats recall;                             // summed over the compared steps
  intestine::RecallStats
      recall_kind[2];    // the same, intestine-intestine [0] and intestine-mesentery [1] contacts apart
  int compared = 0;      // steps compared with the reference
  double residual = 0;   // m, largest brute-force penetration after the response (compared steps)
  double contacts_mean = 0;
  int contacts_max = 0;
  int faults = 0;
  // Time to detect: a reference contact (element pair) that appears at a compared step starts an onset; it ends when
  // the detector reports that pair (latency in steps, 0 when at once) or when the pair leaves the reference first
  // (undetected; also those still waiting at the end). Resolution: the comparison period.
  long onsets = 0;
  long undetected = 0;
  std::vector<double> detect_steps;  // latency of each detected onset, steps
};

namespace detail {

// Identity of a contact as compare_with_reference counts it: kind, segment, segment or mesentery cell.
inline std::int64_t contact_key(const intestine::CollisionContact& c) {
  const int b = c.kind == intestine::ContactKind::kSegmentSegment ? c.element_b : c.element_b / 2;
  return (static_cast<std::int64_t>(c.kind) << 40) | (static_cast<std::int64_t>(c.element_a) << 20) | b;
}

// Onsets of reference contacts and their latency until the detector reports them.
class DetectLatency {
 public:
  void compare(int step, const intestine::ContactList& found, const intestine::ContactList& truth, RunResult& r) {
    reported_.clear();
    for (const auto& c : found) reported_.insert(contact_key(c));
    current_.clear();
    for (const auto& c : truth) {
      const std::int64_t k = contact_key(c);
      if (!current_.insert(k).second) continue;
      const bool seen = previous_.count(k) > 0;
      const bool hit = reported_.count(k) > 0;
      if (!seen) {
        ++r.onsets;
        if (hit) {
          r.detect_steps.push_back(0);
        } else {
          waiting_[k] = step;
        }
      } else if (hit) {
        const auto w = waiting_.find(k);
        if (w != waiting_.end()) {
          r.detect_steps.push_back(step - w->second);
          waiting_.erase(w);
        }
      }
    }
    // Pairs that left the reference before being reported.
    for (auto w = waiting_.begin(); w != waiting_.end();) {
      if (current_.count(w->first) == 0) {
        ++r.undetected;
        w = waiting_.erase(w);
      } else {
        ++w;
      }
    }
    previous_.swap(current_);
  }
  void finish(RunResult& r) {
    r.undetected += static_cast<long>(waiting_.size());
    waiting_.clear();
  }

 private:
  std::unordered_set<std::int64_t> reported_, current_, previous_;
  std::unordered_map<std::int64_t, int> waiting_;
};

}  // namespace detail

/// The scripted run (gravity folds the intestine onto itself, the probe pushes and lifts the folds): `steps` steps
/// of `dt` (s) of the model of `params`, the probe at test::scripted_probe(s dt) for step s; times each phase and,
/// every `every` steps (0: never), compares the stochastic contacts with the brute force on the same positions
/// (recall, time to detect) and measures the penetration left by the response. after_step(s, state, report) is
/// called after each step, outside the timed parts.
template <class AfterStep>
RunResult scripted_run(const intestine::IntestineParams& params, int steps, int every, double dt,
                       AfterStep&& after_step) {
  using surgsim::bench::thread_cpu_us;
  using surgsim::bench::us_since;
  using surgsim::bench::WallClock;
  const intestine::IntestineModel model(params);
  intestine::IntestineState state(model, 1);
  intestine::StepReport report;
  intestine::ContactList truth(100000), kind_found(100000), kind_truth(100000);
  detail::DetectLatency latency;
  RunResult r;
  for (auto* v : {&r.total, &r.dynamics, &r.detection, &r.response, &r.cpu}) {
    v->reserve(static_cast<std::size_t>(steps));
  }
  long contacts = 0;
  for (int s = 0; s < steps; ++s) {
    const intestine::Probe probe = test::scripted_probe(s * dt);
    const bool compare = every > 0 && s % every == 0;
    const double c0 = thread_cpu_us();
    const auto t0 = WallClock::now();
    intestine::step_dynamics(model, state, probe, dt, report);
    const double d0 = us_since(t0);
    const auto t1 = WallClock::now();
    intestine::step_detection(model, state, report);
    const double d1 = us_since(t1);
    const double c1 = thread_cpu_us();
    if (compare) {
      truth.clear();
      intestine::detect_brute_force(model.topology(), state.x, truth);
      r.recall += intestine::compare_with_reference(model.topology(), state.contacts(), truth);
      for (int k = 0; k < 2; ++k) {
        const intestine::ContactKind kind =
            k == 0 ? intestine::ContactKind::kSegmentSegment : intestine::ContactKind::kSegmentTriangle;
        kind_found.clear();
        kind_truth.clear();
        for (const auto& c : state.contacts()) {
          if (c.kind == kind) kind_found.push(c);
        }
        for (const auto& c : truth) {
          if (c.kind == kind) kind_truth.push(c);
        }
        r.recall_kind[k] += intestine::compare_with_reference(model.topology(), kind_found, kind_truth);
      }
      latency.compare(s, state.contacts(), truth, r);
      ++r.compared;
    }
    const auto t2 = WallClock::now();
    const double c2 = thread_cpu_us();
    intestine::step_response(model, state, report);
    const double d2 = us_since(t2);
    r.cpu.push_back((c1 - c0) + (thread_cpu_us() - c2));
    r.faults += report.status != intestine::StepStatus::kOk;
    if (compare) {
      truth.clear();
      intestine::detect_brute_force(model.topology(), state.x, truth);
      for (const auto& c : truth) r.residual = std::max(r.residual, c.radius_sum - c.distance);
    }
    r.dynamics.push_back(d0);
    r.detection.push_back(d1);
    r.response.push_back(d2);
    r.total.push_back(d0 + d1 + d2);
    contacts += report.contacts;
    r.contacts_max = std::max(r.contacts_max, report.contacts);
    after_step(s, static_cast<const intestine::IntestineState&>(state),
               static_cast<const intestine::StepReport&>(report));
  }
  latency.finish(r);
  r.contacts_mean = steps > 0 ? static_cast<double>(contacts) / steps : 0.0;
  return r;
}

/// The scripted run at dt = 1 ms with nothing observed after the steps.
inline RunResult scripted_run(const intestine::IntestineParams& params, int steps, int every) {
  return scripted_run(params, steps, every, 1e-3,
                      [](int, const intestine::IntestineState&, const intestine::StepReport&) {});
}

}  // namespace surgsim::intestine::bench
