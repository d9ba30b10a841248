// The stability suite: every case runs real product code (FEM assembly, CHOLMOD, precomputed tensors,
// superposition, the haptic node's liver contacts, the intestine's mass-spring step) at the edge of its range and
// returns a record of what happened. The ctest (stability_test.cpp) asserts the outcomes; the report program
// (tests/bench/stability_report.cpp) writes them as a CSV table. Deterministic: no random input, no clocks.
//
// Groups and what each case shows:
//   liver/poisson     nu = 0 .. 0.4999 converge (residual, cond(K_ff) estimate); 0.5 and 0.6 are refused
//   liver/young       E = 1 Pa .. 1 GPa: forces scale with E, displacements do not; E = 0 and NaN refused
//   liver/sliver      one tet flattened towards zero volume: quality, validate_mesh verdict, finite solve or refusal
//   liver/contacts    contacts on adjacent nodes, the same node twice, a fixed node, an interior node, NaN input
//   liver/large_disp  a displacement of 0.5..3 element edges at one node: inverted tets detected and counted
//   liver/tool_speed  the haptic node's continuous collision with the tool at 0.1, 1, 10 m/s: contact found on the
//                     tick the tip crosses the surface (no tunnelling), force clamped to the scene's limit
//   intestine/springs springs of 10 .. 1e6 N/m at dt = 1 ms: implicit never gains energy (with self-collisions:
//                     ends below its start; the response may add some for a step), explicit diverges where it does
//   intestine/yank    a probe pulled out of a deep contact at 10 m/s (and plunged in): no explosion, force clamped
#pragma once
#include <string>
#include <vector>

namespace surgsim::stability {

/// What a case ended in.
enum class Outcome {
  kConverged,  // solved; the outputs are finite and the checks of the case hold
  kClamped,    // solved, and a force reached a limit and was clamped to it
  kRefused,    // the input was refused with an error (message) before anything was computed
  kDetected,   // solved, and a problem was detected and reported (e.g. inverted tets)
  kIgnored,    // the input was dropped with a report (e.g. a contact on a fixed node), the rest solved
  kMerged,     // duplicate input merged into one (the same contact node twice)
  kDiverged,   // the run blew up (explicit integrator beyond its stability limit); the state guard held
  kFailed,     // something the case did not expect: an exception or a check that does not hold (see message)
};
const char* to_string(Outcome outcome);

/// One row of the report. NaN in residual / condition when the case has none.
struct CaseResult {
  std::string group;      // "liver" | "intestine"
  std::string name;       // e.g. "poisson", "tool_speed"
  std::string parameter;  // e.g. "nu=0.49", "v=10 m/s"
  Outcome outcome = Outcome::kFailed;
  std::string message;    // the error text when refused; otherwise what was observed
  double residual = 0;    // liver: relative residual |K_ff u - f| / |f| of the reference solve; intestine: largest
                          // energy gain over the run / (m g R); see the message
  double condition = 0;   // condition estimate: 1 / rcond of the factor (CHOLMOD for K_ff, or G_CC / the implicit
                          // matrix from their Cholesky diagonals)
  double max_force_n = 0;         // largest |force| that reached an output (N)
  double max_displacement_m = 0;  // largest |displacement| that reached an output (m)
  bool all_finite = true;         // every output checked element-wise was finite
};

std::vector<CaseResult> liver_poisson_cases();
std::vector<CaseResult> liver_young_cases();
std::vector<CaseResult> liver_sliver_cases();
std::vector<CaseResult> liver_contact_cases();
std::vector<CaseResult> liver_large_displacement_cases();
std::vector<CaseResult> liver_tool_speed_cases();
std::vector<CaseResult> intestine_spring_cases();
std::vector<CaseResult> intestine_yank_cases();

/// Every group above, in that order.
std::vector<CaseResult> all_cases();

/// The CSV header and one row (RFC 4180 quoting of the message).
extern const char* const kCsvHeader;  // "group,case,parameter,outcome,residual,condition,max_force_n,..."
std::string csv_row(const CaseResult& r);

}  // namespace surgsim::stability
