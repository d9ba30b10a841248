// intestine_error_bench --smoke: the program runs its tiny configuration and writes the four CSV files with the
// documented columns and finite values; the figures that do not depend on the machine's speed are checked for what
// they must show (the reference has no error against itself, a larger step errs more, the LOD's vertices lie on the
// skinned surface and a finer LOD is closer to it). No timing assertion.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

// A CSV file as columns of text cells.
struct Csv {
  std::vector<std::string> header;
  std::vector<std::map<std::string, std::string>> rows;
  double num(std::size_t row, const std::string& column) const { return std::stod(rows.at(row).at(column)); }
};

Csv read_csv(const fs::path& path) {
  Csv csv;
  std::ifstream in(path);
  std::string line;
  if (!std::getline(in, line)) return csv;
  std::stringstream hs(line);
  for (std::string cell; std::getline(hs, cell, ',');) csv.header.push_back(cell);
  while (std::getline(in, line)) {
    std::stringstream ls(line);
    std::map<std::string, std::string> row;
    std::size_t i = 0;
    for (std::string cell; std::getline(ls, cell, ','); ++i) {
      if (i < csv.header.size()) row[csv.header[i]] = cell;
    }
    EXPECT_EQ(i, csv.header.size()) << path << ": " << line;
    csv.rows.push_back(row);
  }
  return csv;
}

// Reads one output file and checks every cell but the named text columns is a finite number.
Csv table(const fs::path& dir, const std::string& name, const std::vector<std::string>& columns,
          const std::vector<std::string>& text = {}) {
  const Csv csv = read_csv(dir / (name + ".csv"));
  EXPECT_EQ(csv.header, columns) << name;
  EXPECT_FALSE(csv.rows.empty()) << name;
  for (const auto& row : csv.rows) {
    for (const auto& [column, cell] : row) {
      if (std::find(text.begin(), text.end(), column) != text.end()) continue;
      char* end = nullptr;
      const double v = std::strtod(cell.c_str(), &end);
      EXPECT_TRUE(end != cell.c_str() && *end == '\0' && std::isfinite(v)) << name << " " << column << " = " << cell;
    }
  }
  return csv;
}

// intestine_timestep.csv and its series: errors against the reference.
void check_timestep(const fs::path& dir) {
  const Csv csv =
      table(dir, "intestine_timestep",
            {"self_collisions", "dt_ms", "steps", "compared_times", "step_us_p50", "step_us_p99", "cpu_s_per_sim_s",
             "pos_rms_error_mm", "pos_max_error_mm", "end_rms_error_mm", "end_max_error_mm", "settle_rms_error_mm",
             "force_rms_error_n", "force_ref_rms_n", "faults", "stable"});
  // Smoke: reference 0.5 ms, then 1, 2 and 10 ms, without then with self-collisions.
  ASSERT_EQ(csv.rows.size(), 8u);
  for (std::size_t r = 0; r < csv.rows.size(); ++r) {
    EXPECT_GT(csv.num(r, "compared_times"), 0) << r;
    EXPECT_EQ(csv.num(r, "stable"), 1) << r;
  }
  // The reference against itself; then, while the folds settle under gravity alone (no contact events, no random
  // pairs), a larger step errs more.
  EXPECT_EQ(csv.num(0, "dt_ms"), 0.5);
  EXPECT_EQ(csv.num(0, "pos_max_error_mm"), 0);
  EXPECT_EQ(csv.num(4, "pos_max_error_mm"), 0);
  EXPECT_GT(csv.num(1, "settle_rms_error_mm"), 0);
  EXPECT_LT(csv.num(1, "settle_rms_error_mm"), csv.num(2, "settle_rms_error_mm"));
  EXPECT_LT(csv.num(2, "settle_rms_error_mm"), csv.num(3, "settle_rms_error_mm"));
  EXPECT_LE(csv.num(1, "pos_rms_error_mm"), csv.num(1, "pos_max_error_mm"));

  // The series: one line per compared time of each run.
  const Csv series = table(
      dir, "intestine_timestep_series",
      {"self_collisions", "dt_ms", "t_s", "pos_rms_error_mm", "pos_max_error_mm", "force_error_n", "force_ref_n"});
  double compared = 0;
  for (std::size_t r = 0; r < csv.rows.size(); ++r) compared += csv.num(r, "compared_times");
  EXPECT_EQ(static_cast<double>(series.rows.size()), compared);
}

// intestine_pairs.csv: recall against n.
void check_pairs(const fs::path& dir) {
  const Csv csv =
      table(dir, "intestine_pairs",
            {"random_pairs", "steps", "compared_steps", "pair_recall", "region_recall", "depth_recall", "max_missed_mm",
             "residual_mm", "onsets", "detect_steps_mean", "detect_steps_p50", "detect_steps_p90", "detect_steps_max",
             "undetected_fraction", "contacts_mean", "step_us_p50", "step_us_p99", "detect_us_p50", "detect_us_p99"});
  ASSERT_EQ(csv.rows.size(), 2u);  // n = 0 and 10
  for (std::size_t r = 0; r < csv.rows.size(); ++r) {
    for (const char* c : {"pair_recall", "region_recall", "depth_recall", "undetected_fraction"}) {
      EXPECT_GE(csv.num(r, c), 0) << c;
      EXPECT_LE(csv.num(r, c), 1) << c;
    }
  }
  // Without random pairs nothing is ever found; with them the folds' contacts are.
  EXPECT_GT(csv.num(0, "onsets"), 0);
  EXPECT_EQ(csv.num(0, "pair_recall"), 0);
  EXPECT_GT(csv.num(1, "pair_recall"), 0.5);
}

// intestine_lod.csv: geometric error and frames per LOD.
void check_lod(const fs::path& dir) {
  const Csv csv = table(
      dir, "intestine_lod",
      {"lod", "sides", "rings", "intervals_mean", "vertices_mean", "triangles_mean", "geom_max_error_mm",
       "geom_rms_error_mm", "geom_max_error_pct_radius", "geom_rms_error_pct_radius", "vertex_check_mm", "build_us_p50",
       "build_us_p99", "frames", "render_ms_p50", "render_ms_p99", "frame_ms_p50", "frame_ms_p99", "renderer"},
      {"renderer"});
  ASSERT_EQ(csv.rows.size(), 7u);
  for (std::size_t r = 0; r < csv.rows.size(); ++r) {
    EXPECT_LT(csv.num(r, "vertex_check_mm"), 0.01) << r;  // the measure's model of the mesh is the mesh
    EXPECT_GT(csv.num(r, "frames"), 0) << r;
    EXPECT_GT(csv.num(r, "render_ms_p50"), 0) << r;
    if (r > 0) {
      EXPECT_GT(csv.num(r, "triangles_mean"), csv.num(r - 1, "triangles_mean")) << r;
      EXPECT_LE(csv.num(r, "geom_max_error_mm"), csv.num(r - 1, "geom_max_error_mm") * 1.0001) << r;
    }
  }
  // 16 sides (LOD 0: the coarsest level still round) alone miss the circle by r (1 - cos(pi / 16)) ~ 1.9 %
  // at mid-side, two rings per interval add the bend between them; 48 sides (LOD 6) by r (1 - cos(pi / 48)) ~ 0.2 %,
  // plus the bend between rings.
  EXPECT_GT(csv.num(0, "geom_max_error_pct_radius"), 1.9);
  EXPECT_LT(csv.num(0, "geom_max_error_pct_radius"), 25);
  EXPECT_GT(csv.num(6, "geom_max_error_pct_radius"), 0.2);
  EXPECT_LT(csv.num(6, "geom_max_error_pct_radius"), 5);
  EXPECT_EQ(csv.rows[0].at("renderer").rfind("osmesa", 0), 0u);
}

// intestine_frame_rate.csv: the controller on the renderer.
void check_frame_rate(const fs::path& dir) {
  const Csv csv =
      table(dir, "intestine_frame_rate",
            {"target_fps", "frames", "fps_mean", "work_ms_p50", "work_ms_p99", "lod_mean", "lod_min", "lod_max",
             "lod_final", "frames_to_settle", "samples", "triangles_mean", "renderer", "skinning"},
            {"renderer", "skinning"});
  ASSERT_EQ(csv.rows.size(), 1u);
  EXPECT_GT(csv.num(0, "fps_mean"), 0);
  EXPECT_GE(csv.num(0, "lod_min"), 0);
  EXPECT_LE(csv.num(0, "lod_max"), 6);
  EXPECT_GT(csv.num(0, "samples"), 1);
}

// One run of the program (a few seconds), all four tables checked.
TEST(IntestineErrorBench, SmokeRunWritesTheTables) {
  const fs::path dir = fs::path(::testing::TempDir()) / ("surgsim_intestine_error_bench_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const std::string log = dir.string() + ".log";
  const std::string cmd =
      std::string(SURGSIM_INTESTINE_ERROR_BENCH) + " --smoke --series --out " + dir.string() + " > " + log + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << "see " << log;
  {
    SCOPED_TRACE("intestine_timestep");
    check_timestep(dir);
  }
  {
    SCOPED_TRACE("intestine_pairs");
    check_pairs(dir);
  }
  {
    SCOPED_TRACE("intestine_lod");
    check_lod(dir);
  }
  {
    SCOPED_TRACE("intestine_frame_rate");
    check_frame_rate(dir);
  }
  if (!HasFailure()) {
    fs::remove_all(dir);
    fs::remove(log);
  }
}

}  // namespace
