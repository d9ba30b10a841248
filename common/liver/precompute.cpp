#include "liver/precompute.h"

#include <Eigen/IterativeLinearSolvers>
#include <algorithm>
#include <chrono>
#include <cstdio>

#include "liver/cholmod_solver.h"
#include "core/error.h"

namespace surgsim {

const char* to_string(Precision precision) { return precision == Precision::kFloat ? "float" : "double"; }

Precision parse_precision(const std::string& text) {
  if (text == "float") return Precision::kFloat;
  if (text == "double") return Precision::kDouble;
  throw_error("unknown precision '", text, "' (expected float or double)");
}

Eigen::Matrix3d TensorBlock::block3(int r, int c) const {
  if (g.size()) return g.block<3, 3>(3 * r, 3 * c);
  return g_float.block<3, 3>(3 * r, 3 * c).cast<double>();
}

const TensorBlock* Tensors::find(const std::string& name) const {
  for (const auto& b : blocks)
    if (b.name == name) return &b;
  return nullptr;
}

std::size_t Tensors::bytes() const {
  std::size_t total = 0;
  for (const auto& b : blocks) total += b.bytes();
  return total;
}

std::string MemoryEstimate::describe() const {
  const double mib = 1024.0 * 1024.0;
  char buf[200];
  std::snprintf(buf, sizeof buf, "%.1f MiB (tensors %.1f, factor %.1f, matrices %.1f, work %.1f)", total() / mib,
                tensors / mib, factor / mib, matrix / mib, work / mib);
  return buf;
}

std::vector<int> contactable_nodes(const TetMesh& mesh, const FixedSet& fixed) {
  std::vector<int> out;
  for (int n : boundary_surface(mesh).nodes)
    if (fixed.node_fully_free(n)) out.push_back(n);
  return out;
}

std::vector<RowSet> standard_row_sets(const TetMesh& mesh, const std::vector<int>& contact_nodes) {
  std::vector<int> contacts = contact_nodes;
  std::sort(contacts.begin(), contacts.end());
  return {RowSet{"haptic", contacts}, RowSet{"visual", boundary_surface(mesh).nodes}};
}

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::size_t tensor_bytes(int contact_count, const std::vector<RowSet>& rows, Precision precision) {
  std::size_t r = 0;
  for (const auto& set : rows) r += set.nodes.size();
  return 9 * r * static_cast<std::size_t>(contact_count) * static_cast<std::size_t>(precision);
}

MemoryEstimate base_estimate(const ElasticModel& model, int contact_count, const std::vector<RowSet>& rows,
                             const PrecomputeOptions& options) {
  MemoryEstimate m;
  m.tensors = tensor_bytes(contact_count, rows, options.precision);
  const std::size_t entry = sizeof(double) + sizeof(int);
  m.matrix = static_cast<std::size_t>(model.k.nonZeros() + model.k_ff.nonZeros()) * entry;
  const std::size_t nf = static_cast<std::size_t>(model.fixed.free_dof_count());
  if (options.method == SolveMethod::kDirect) {
    m.matrix += static_cast<std::size_t>(model.k_ff.nonZeros()) / 2 * entry;  // CHOLMOD's upper-triangle copy
    // Right-hand sides, our solution block, and CHOLMOD's X, Y, E workspaces.
    const std::size_t block = std::min<std::size_t>(static_cast<std::size_t>(std::max(1, options.block_columns)),
                                                    3 * static_cast<std::size_t>(contact_count));
    m.work = 4 * nf * block * sizeof(double);
  } else {
    m.work = 8 * nf * sizeof(double);  // CG vectors and preconditioner
  }
  return m;
}

void refuse_if_over(const MemoryEstimate& m, const PrecomputeOptions& options) {
  if (options.memory_limit_mb <= 0) return;
  const double mib = static_cast<double>(m.total()) / (1024.0 * 1024.0);
  if (mib > options.memory_limit_mb)
    throw_error("precompute: estimated memory ", m.describe(), " exceeds the limit of ", options.memory_limit_mb,
                " MiB; raise it with --memory-limit-mb (PrecomputeOptions::memory_limit_mb), store floats with "
                "--precision float, or use a coarser mesh");
}

// Checks a node list: in range, unique; contacts must also be fully free.
void check_nodes(const ElasticModel& model, const std::vector<int>& nodes, const std::string& what, bool must_be_free) {
  const int n = model.node_count();
  std::vector<char> seen(static_cast<std::size_t>(n), 0);
  for (int i : nodes) {
    if (i < 0 || i >= n) throw_error("precompute: ", what, " node ", i, " is out of range (0..", n - 1, ")");
    if (seen[static_cast<std::size_t>(i)]) throw_error("precompute: ", what, " node ", i, " is listed twice");
    seen[static_cast<std::size_t>(i)] = 1;
    if (must_be_free && !model.fixed.node_fully_free(i))
      throw_error("precompute: contact node ", i, " is fixed; contactable nodes must be free on all components");
  }
}

}  // namespace

MemoryEstimate estimate_precompute_memory(const ElasticModel& model, int contact_count,
                                          const std::vector<RowSet>& rows, const PrecomputeOptions& options) {
  MemoryEstimate m = base_estimate(model, contact_count, rows, options);
  if (options.method == SolveMethod::kDirect) {
    CholmodSolver solver;
    solver.analyze(model.k_ff);
    m.factor = solver.factor_bytes();
  }
  return m;
}

Tensors precompute_tensors(const ElasticModel& model, const std::vector<int>& contact_nodes,
                           const std::vector<RowSet>& rows, const PrecomputeOptions& options,
                           PrecomputeReport* report) {
  const auto t0 = Clock::now();
  PrecomputeReport local;
  PrecomputeReport& rep = report ? *report : local;
  rep = PrecomputeReport();
  const int n = model.node_count();

  check_nodes(model, contact_nodes, "contact", true);
  for (const auto& set : rows) check_nodes(model, set.nodes, "row set '" + set.name + "'", false);
  for (std::size_t a = 0; a < rows.size(); ++a)
    for (std::size_t b = 0; b < a; ++b)
      if (rows[a].name == rows[b].name) throw_error("precompute: row set name '", rows[a].name, "' used twice");

  Tensors t;
  t.node_count = n;
  t.contact_nodes = contact_nodes;
  std::sort(t.contact_nodes.begin(), t.contact_nodes.end());
  t.column_of_node.assign(static_cast<std::size_t>(n), -1);
  for (std::size_t c = 0; c < t.contact_nodes.size(); ++c)
    t.column_of_node[static_cast<std::size_t>(t.contact_nodes[c])] = static_cast<int>(c);
  t.fixed_mask.resize(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) t.fixed_mask[static_cast<std::size_t>(i)] = model.fixed.mask(i);
  t.precision = options.precision;
  t.method = options.method;
  t.cg_tolerance = options.method == SolveMethod::kCg ? options.cg_tolerance : 0;

  const int s = t.column_count();
  const Eigen::Index cols = 3 * static_cast<Eigen::Index>(s);
  const Eigen::Index nf = model.fixed.free_dof_count();

  // Memory: estimate (with the symbolic factor size when direct) and refuse before any heavy allocation.
  rep.memory = base_estimate(model, s, rows, options);
  CholmodSolver::Options copts;
  copts.block_columns = std::max(1, options.block_columns);
  CholmodSolver solver(copts);
  if (options.method == SolveMethod::kDirect) {
    const auto ta = Clock::now();
    solver.analyze(model.k_ff);
    rep.analyze_s = seconds_since(ta);
    rep.memory.factor = solver.factor_bytes();
  } else if (!(options.cg_tolerance > 0)) {
    throw_error("precompute: CG tolerance must be positive, got ", options.cg_tolerance);
  }
  refuse_if_over(rep.memory, options);

  // Output blocks.
  for (const auto& set : rows) {
    TensorBlock b;
    b.name = set.name;
    b.row_nodes = set.nodes;
    b.row_of_node.assign(static_cast<std::size_t>(n), -1);
    for (std::size_t r = 0; r < set.nodes.size(); ++r) b.row_of_node[static_cast<std::size_t>(set.nodes[r])] = static_cast<int>(r);
    const Eigen::Index rr = 3 * static_cast<Eigen::Index>(set.nodes.size());
    // Every entry is written by store() below (zeros for fixed rows): no need to clear.
    if (options.precision == Precision::kDouble)
      b.g.resize(rr, cols);
    else
      b.g_float.resize(rr, cols);
    t.blocks.push_back(std::move(b));
  }
  // For each block, the free index of each matrix row (or -1 for a fixed component).
  std::vector<std::vector<int>> row_free(t.blocks.size());
  for (std::size_t k = 0; k < t.blocks.size(); ++k)
    for (int node : t.blocks[k].row_nodes)
      for (int c = 0; c < 3; ++c) row_free[k].push_back(model.fixed.free_index()[static_cast<std::size_t>(3 * node + c)]);

  // Copies solved columns [j0, j0 + x.cols()) into every block.
  auto store = [&](const Eigen::MatrixXd& x, Eigen::Index j0) {
    for (std::size_t k = 0; k < t.blocks.size(); ++k) {
      TensorBlock& b = t.blocks[k];
      const auto& rf = row_free[k];
      for (Eigen::Index j = 0; j < x.cols(); ++j)
        for (std::size_t i = 0; i < rf.size(); ++i) {
          const double v = rf[i] >= 0 ? x(rf[i], j) : 0.0;
          if (options.precision == Precision::kDouble)
            b.g(static_cast<Eigen::Index>(i), j0 + j) = v;
          else
            b.g_float(static_cast<Eigen::Index>(i), j0 + j) = static_cast<float>(v);
        }
    }
  };
  const auto free_of_column = [&](Eigen::Index j) {
    return model.fixed.free_index()[static_cast<std::size_t>(3 * t.contact_nodes[static_cast<std::size_t>(j / 3)] + j % 3)];
  };
  const auto ts = Clock::now();
  auto report_progress = [&](Eigen::Index done) {
    if (!options.progress) return;
    PrecomputeProgress p;
    p.columns_done = static_cast<int>(done);
    p.columns_total = static_cast<int>(cols);
    p.fraction = cols ? static_cast<double>(done) / static_cast<double>(cols) : 1.0;
    p.elapsed_s = seconds_since(t0);
    const double solving = seconds_since(ts);
    p.eta_s = done > 0 ? solving / static_cast<double>(done) * static_cast<double>(cols - done) : 0.0;
    options.progress(p);
  };

  if (options.method == SolveMethod::kDirect) {
    const auto tf = Clock::now();
    solver.factorize();
    rep.factor_s = seconds_since(tf);
    const auto tsolve = Clock::now();
    const Eigen::Index block = copts.block_columns;
    Eigen::MatrixXd e, x;
    report_progress(0);
    for (Eigen::Index j0 = 0; j0 < cols; j0 += block) {
      const Eigen::Index nc = std::min(block, cols - j0);
      e.setZero(nf, nc);
      for (Eigen::Index j = 0; j < nc; ++j) e(free_of_column(j0 + j), j) = 1;
      x.resize(nf, nc);
      solver.solve(e, x);
      store(x, j0);
      report_progress(j0 + nc);
    }
    rep.solve_s = seconds_since(tsolve);
  } else {
    const auto tsolve = Clock::now();
    Eigen::ConjugateGradient<Eigen::SparseMatrix<double>, Eigen::Lower | Eigen::Upper> cg;
    cg.setTolerance(options.cg_tolerance);
    cg.setMaxIterations(options.cg_max_iterations > 0 ? options.cg_max_iterations : 10 * static_cast<int>(nf));
    cg.compute(model.k_ff);
    Eigen::VectorXd e = Eigen::VectorXd::Zero(nf);
    Eigen::MatrixXd x(nf, 1);
    report_progress(0);
    for (Eigen::Index j = 0; j < cols; ++j) {
      const int f = free_of_column(j);
      e[f] = 1;
      x.col(0) = cg.solve(e);
      e[f] = 0;
      rep.cg_max_iterations = std::max(rep.cg_max_iterations, static_cast<int>(cg.iterations()));
      rep.cg_max_residual = std::max(rep.cg_max_residual, cg.error());
      if (cg.info() != Eigen::Success) rep.cg_all_converged = false;
      store(x, j);
      report_progress(j + 1);
    }
    rep.solve_s = seconds_since(tsolve);
  }
  rep.total_s = seconds_since(t0);
  return t;
}

}  // namespace surgsim
