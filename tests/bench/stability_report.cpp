// stability_report: runs every case of the stability suite (tests/stability/stability_cases.h) and writes
// DIR/stability.csv, then prints the table. The same cases are asserted by the stability_test ctest.
//   build/bench/stability_report [--out DIR] [--group liver|intestine]
// Exit status: 0 when no case failed, 1 when some case ended in "failed" (see its message), 2 on a bad argument or
// an output file that cannot be written.
#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "stability_cases.h"

int main(int argc, char** argv) {
  using surgsim::stability::CaseResult;
  namespace stab = surgsim::stability;
  CLI::App app{
      "Stability suite: runs every edge case of the liver and intestine models and writes "
      "DIR/stability.csv (group,case,parameter,outcome,residual,condition,max_force_n,max_displacement_m,"
      "all_finite,message) and a table on stdout"};
  std::string out_dir = "out/stability";
  std::string group;
  app.add_option("--out", out_dir, "folder for stability.csv (created)");
  app.add_option("--group", group, "only this group")->check(CLI::IsMember({"liver", "intestine"}));
  CLI11_PARSE(app, argc, argv);

  const auto t0 = std::chrono::steady_clock::now();
  std::vector<CaseResult> rows;
  if (group.empty()) {
    rows = stab::all_cases();
  } else {
    using Group = std::vector<CaseResult> (*)();
    const std::vector<Group> liver = {stab::liver_poisson_cases, stab::liver_young_cases, stab::liver_sliver_cases,
                                      stab::liver_contact_cases, stab::liver_large_displacement_cases,
                                      stab::liver_tool_speed_cases};
    const std::vector<Group> intestine = {stab::intestine_spring_cases, stab::intestine_yank_cases};
    for (Group g : group == "liver" ? liver : intestine) {
      const std::vector<CaseResult> part = g();
      rows.insert(rows.end(), part.begin(), part.end());
    }
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  const std::string path = (std::filesystem::path(out_dir) / "stability.csv").string();
  std::ofstream csv(path);
  if (!csv) {
    std::fprintf(stderr, "stability_report: cannot write %s\n", path.c_str());
    return 2;
  }
  csv << stab::kCsvHeader << '\n';
  for (const CaseResult& r : rows) csv << stab::csv_row(r) << '\n';
  csv.close();
  if (!csv) {
    std::fprintf(stderr, "stability_report: error while writing %s\n", path.c_str());
    return 2;
  }

  int failed = 0, nonfinite = 0;
  std::printf("%-10s %-20s %-42s %-9s %9s %9s %9s %9s %s\n", "group", "case", "parameter", "outcome", "residual",
              "condition", "force_N", "disp_m", "finite");
  for (const CaseResult& r : rows) {
    std::printf("%-10s %-20s %-42s %-9s %9.2e %9.2e %9.3g %9.3g %s\n", r.group.c_str(), r.name.c_str(),
                r.parameter.c_str(), stab::to_string(r.outcome), r.residual, r.condition, r.max_force_n,
                r.max_displacement_m, r.all_finite ? "yes" : "NO");
    std::printf("           %s\n", r.message.c_str());
    failed += r.outcome == stab::Outcome::kFailed ? 1 : 0;
    nonfinite += r.all_finite ? 0 : 1;
  }
  std::printf("\n%zu cases, %d failed, %d with a non-finite output; %.1f s; wrote %s\n", rows.size(), failed,
              nonfinite, seconds, path.c_str());
  return failed > 0 ? 1 : 0;
}
