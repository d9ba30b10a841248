// liver_error_bench --smoke (box meshes, a few seconds): the program writes its five CSV files with the documented
// columns and finite numbers, and the figures that do not depend on the machine's speed show what they must: the
// direct and double-tensor methods agree with the reference to round-off, float to single precision, CG errs less at
// a tighter tolerance, the finest mesh is its own reference, Newton converges and linear errs more at deeper
// indentation. No timing assertion.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> cells;
  std::string cell;
  std::istringstream in(line);
  while (std::getline(in, cell, ',')) cells.push_back(cell);
  if (!line.empty() && line.back() == ',') cells.emplace_back();
  return cells;
}

// One output table: its header and rows, with the cells of the text columns kept as text, the others as numbers.
struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> text;
  std::vector<std::vector<double>> value;  // NaN in text columns

  int column(const std::string& name) const {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return static_cast<int>(i);
    ADD_FAILURE() << "no column " << name;
    return 0;
  }
  double at(std::size_t row, const std::string& name) const { return value.at(row).at(static_cast<std::size_t>(column(name))); }
  const std::string& str(std::size_t row, const std::string& name) const { return text.at(row).at(static_cast<std::size_t>(column(name))); }
  // The first row whose `key` column equals `v`, or -1.
  int find(const std::string& key, const std::string& v) const {
    for (std::size_t r = 0; r < text.size(); ++r)
      if (str(r, key) == v) return static_cast<int>(r);
    return -1;
  }
};

class LiverErrorBench : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::path(::testing::TempDir()) / ("surgsim_liver_error_bench_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    log_ = dir_.string() + ".log";
    const std::string cmd = std::string(SURGSIM_LIVER_ERROR_BENCH) + " --smoke --out " + dir_.string() + " >" + log_ + " 2>&1";
    status_ = std::system(cmd.c_str());
  }
  static void TearDownTestSuite() {
    fs::remove_all(dir_);
    fs::remove(log_);
  }

  static Table read(const std::string& name, const std::string& header, const std::set<std::string>& text_columns) {
    Table t;
    EXPECT_EQ(status_, 0) << "see " << log_;
    std::ifstream in(dir_ / (name + ".csv"));
    std::string line;
    EXPECT_TRUE(std::getline(in, line)) << name << ".csv missing or empty";
    EXPECT_EQ(line, header) << name;
    t.header = split(line);
    while (std::getline(in, line)) {
      const auto cells = split(line);
      EXPECT_EQ(cells.size(), t.header.size()) << name << ": " << line;
      std::vector<double> values;
      for (std::size_t i = 0; i < cells.size() && i < t.header.size(); ++i) {
        if (text_columns.count(t.header[i])) {
          values.push_back(std::nan(""));
          continue;
        }
        char* end = nullptr;
        const double v = std::strtod(cells[i].c_str(), &end);
        EXPECT_TRUE(!cells[i].empty() && *end == '\0' && std::isfinite(v)) << name << " " << t.header[i] << " = '" << cells[i] << "'";
        values.push_back(v);
      }
      t.text.push_back(cells);
      t.value.push_back(values);
    }
    EXPECT_FALSE(t.text.empty()) << name << " has no rows";
    return t;
  }

  static fs::path dir_;
  static std::string log_;
  static int status_;
};

fs::path LiverErrorBench::dir_;
std::string LiverErrorBench::log_;
int LiverErrorBench::status_ = -1;

TEST_F(LiverErrorBench, SummaryHasEveryFamilyWithFiniteValues) {
  const Table t = read("liver_error_time",
                       "family,variant,time_per_frame_us_p50,time_per_frame_us_p99,disp_rel_error,force_rel_error,memory_mib",
                       {"family", "variant"});
  std::set<std::string> families;
  for (std::size_t r = 0; r < t.text.size(); ++r) {
    families.insert(t.str(r, "family"));
    EXPECT_GE(t.at(r, "time_per_frame_us_p99"), t.at(r, "time_per_frame_us_p50"));
    EXPECT_GT(t.at(r, "memory_mib"), 0);
  }
  for (const char* f : {"full_solve", "prefactored", "cg", "tensors_double", "tensors_float", "tensors_dropped", "mesh",
                        "linear_vs_nonlinear"})
    EXPECT_TRUE(families.count(f)) << f;

  const auto error_of = [&](const std::string& variant) {
    const int r = t.find("variant", variant);
    EXPECT_GE(r, 0) << variant;
    return r < 0 ? 1.0 : t.at(static_cast<std::size_t>(r), "disp_rel_error");
  };
  EXPECT_LT(error_of("factor_and_solve"), 1e-12);
  EXPECT_LT(error_of("direct"), 1e-12);
  const int td = t.find("family", "tensors_double"), tf = t.find("family", "tensors_float");
  ASSERT_GE(td, 0);
  ASSERT_GE(tf, 0);
  EXPECT_LT(t.at(static_cast<std::size_t>(td), "disp_rel_error"), 1e-12);
  EXPECT_LT(t.at(static_cast<std::size_t>(tf), "disp_rel_error"), 1e-5);
  EXPECT_GT(t.at(static_cast<std::size_t>(tf), "disp_rel_error"), 1e-12);  // float is not double
  EXPECT_LT(t.at(static_cast<std::size_t>(tf), "memory_mib"), t.at(static_cast<std::size_t>(td), "memory_mib"));
  EXPECT_GT(error_of("tol_1e-02"), error_of("tol_1e-08"));
  EXPECT_LT(error_of("tol_1e-08"), 1e-5);
}

TEST_F(LiverErrorBench, DetailedTablesAreWritten) {
  const Table frames = read("liver_error_frames",
                            "family,variant,contacts,frames,time_per_frame_us_p50,time_per_frame_us_p99,"
                            "disp_rel_error_max,disp_rel_error_median,force_rel_error_max,cg_iterations_max",
                            {"family", "variant"});
  std::set<double> counts;
  for (std::size_t r = 0; r < frames.value.size(); ++r) counts.insert(frames.at(r, "contacts"));
  EXPECT_EQ(counts, (std::set<double>{1, 3, 10}));

  const Table dropped = read("liver_error_dropped",
                             "threshold_rel,blocks_kept_fraction,memory_dense_mib,memory_sparse_mib,saved_fraction,"
                             "saved_mib,disp_rel_error,force_rel_error,time_per_frame_us_p50",
                             {});
  ASSERT_GE(dropped.value.size(), 2u);
  // A larger threshold drops more and errs more.
  EXPECT_LE(dropped.at(1, "blocks_kept_fraction"), dropped.at(0, "blocks_kept_fraction"));
  EXPECT_GE(dropped.at(1, "disp_rel_error"), dropped.at(0, "disp_rel_error"));
  for (std::size_t r = 0; r < dropped.value.size(); ++r)
    EXPECT_NEAR(dropped.at(r, "saved_fraction"), 1 - dropped.at(r, "memory_sparse_mib") / dropped.at(r, "memory_dense_mib"), 1e-4);
}

TEST_F(LiverErrorBench, FinestMeshIsTheReference) {
  const Table mesh = read("liver_mesh_convergence",
                          "nodes,tets,visible_nodes,indenter_nodes,force_n,force_rel_error,disp_rel_error,"
                          "samples_outside,factor_ms,solve_ms,precompute_s,tensor_mib,tensor_frame_us_p50,"
                          "tensor_frame_us_p99",
                          {});
  ASSERT_EQ(mesh.value.size(), 3u);
  EXPECT_LT(mesh.at(0, "nodes"), mesh.at(2, "nodes"));
  EXPECT_EQ(mesh.at(2, "force_rel_error"), 0);
  EXPECT_EQ(mesh.at(2, "disp_rel_error"), 0);
  EXPECT_GT(mesh.at(0, "disp_rel_error"), 0);
  for (std::size_t r = 0; r < mesh.value.size(); ++r) EXPECT_GT(mesh.at(r, "indenter_nodes"), 0);
}

TEST_F(LiverErrorBench, NewtonConvergesAndLinearErrsMoreWhenDeeper) {
  const Table nl = read("liver_nonlinear",
                        "indentation_percent,indentation_mm,indenter_nodes,newton_force_n,linear_force_n,quasi_force_n,"
                        "linear_force_rel_error,quasi_force_rel_error,linear_disp_rel_error,quasi_disp_rel_error,"
                        "newton_converged,newton_load_steps,newton_iterations,newton_ms,linear_frame_us_p50,"
                        "quasi_frame_us_p50,q_extrapolated",
                        {});
  ASSERT_EQ(nl.value.size(), 2u);
  for (std::size_t r = 0; r < 2; ++r) {
    EXPECT_EQ(nl.at(r, "newton_converged"), 1);
    EXPECT_GT(nl.at(r, "newton_iterations"), nl.at(r, "newton_load_steps"));
  }
  EXPECT_GT(nl.at(1, "linear_force_rel_error"), nl.at(0, "linear_force_rel_error"));
  EXPECT_GT(nl.at(1, "linear_disp_rel_error"), nl.at(0, "linear_disp_rel_error"));
  // The neo-Hookean punch stiffens: more force than linear at 30 %.
  EXPECT_GT(nl.at(1, "newton_force_n"), nl.at(1, "linear_force_n"));
}

}  // namespace
