#include "compliance/precompute.h"

#include <dlfcn.h>

#include <Eigen/IterativeLinearSolvers>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <exception>
#include <mutex>
#include <numeric>
#include <thread>

#include "fem/cholmod_solver.h"
#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;

namespace surgsim::compliance {

const char* to_string(Precision precision) { return precision == Precision::kFloat ? "float" : "double"; }

Precision parse_precision(const std::string& text) {
  if (text == "float") return Precision::kFloat;
  if (text == "double") return Precision::kDouble;
  throw_error("unknown precision '", text, "' (expected float or double)");
}

void TensorBlock::column(Eigen::Index j, double* out) const {
  const Eigen::Index rows = 3 * static_cast<Eigen::Index>(row_count());
  if (!symmetric && g.size()) {
    Eigen::Map<Eigen::VectorXd>(out, rows) = g.col(j);
  } else if (!symmetric) {
    Eigen::Map<Eigen::VectorXd>(out, rows) = g_float.col(j).cast<double>();
  } else {
    for (Eigen::Index i = 0; i < rows; ++i) out[i] = at(i, j);
  }
}

std::size_t TensorBlock::stored_entries() const {
  if (symmetric) return packed.size() + packed_float.size();
  return static_cast<std::size_t>(g.size() + g_float.size());
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

std::vector<RowSet> standard_row_sets(const TetMesh& mesh, const FixedSet& fixed,
                                      const std::vector<int>& contact_nodes) {
  std::vector<RowSet> sets = standard_row_sets(mesh, contact_nodes);
  auto& visual = sets[1].nodes;
  visual.erase(std::remove_if(visual.begin(), visual.end(), [&](int n) { return fixed.mask(n) == 7; }), visual.end());
  return sets;
}

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Whether `set` is stored as a packed symmetric block (named in options.symmetric_blocks).
bool packs_symmetric(const RowSet& set, const PrecomputeOptions& options) {
  const auto& names = options.symmetric_blocks;
  return std::find(names.begin(), names.end(), set.name) != names.end();
}

std::size_t tensor_bytes(int contact_count, const std::vector<RowSet>& rows, const PrecomputeOptions& options) {
  const auto s = static_cast<std::size_t>(contact_count);
  std::size_t entries = 0;
  for (const auto& set : rows) {
    const bool sym = packs_symmetric(set, options);
    entries += sym ? 9 * s * (s + 1) / 2 : 9 * set.nodes.size() * s;
  }
  return entries * static_cast<std::size_t>(options.precision);
}

// OpenBLAS runs each call on one thread while our own threads solve (no oversubscription; the same bits for any
// thread count); restores its setting after. A no-op with another BLAS.
class BlasSingleThread {
 public:
  BlasSingleThread() {
    set_ = reinterpret_cast<void (*)(int)>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
    auto get = reinterpret_cast<int (*)()>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
    if (set_ && get) {
      saved_ = get();
      set_(1);
    }
  }
  ~BlasSingleThread() {
    if (set_ && saved_ > 0) set_(saved_);
  }
  BlasSingleThread(const BlasSingleThread&) = delete;
  BlasSingleThread& operator=(const BlasSingleThread&) = delete;

 private:
  void (*set_)(int) = nullptr;
  int saved_ = 0;
};

int solving_threads(const PrecomputeOptions& options, int contact_count) {
  int t = options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  const int block = std::max(1, options.block_columns);
  const int blocks = (3 * contact_count + block - 1) / block;
  return std::max(1, std::min(t, blocks));
}

MemoryEstimate base_estimate(const ElasticModel& model, int contact_count, const std::vector<RowSet>& rows,
                             const PrecomputeOptions& options) {
  MemoryEstimate m;
  m.tensors = tensor_bytes(contact_count, rows, options);
  const std::size_t entry = sizeof(double) + sizeof(int);
  m.matrix = static_cast<std::size_t>(model.k.nonZeros() + model.k_ff.nonZeros()) * entry;
  const std::size_t nf = static_cast<std::size_t>(model.fixed.free_dof_count());
  if (options.method == SolveMethod::kDirect) {
    m.matrix += static_cast<std::size_t>(model.k_ff.nonZeros()) / 2 * entry;  // CHOLMOD's upper-triangle copy
    // Per solving thread: the solution block and the gathered off-diagonal rows (at most as many).
    const std::size_t block = std::min<std::size_t>(static_cast<std::size_t>(std::max(1, options.block_columns)),
                                                    3 * static_cast<std::size_t>(contact_count));
    m.work = 2 * nf * block * sizeof(double) * static_cast<std::size_t>(solving_threads(options, contact_count));
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

std::size_t estimate_tensor_bytes(int contact_count, const std::vector<RowSet>& rows,
                                  const PrecomputeOptions& options) {
  return tensor_bytes(contact_count, rows, options);
}

MemoryEstimate estimate_precompute_memory(const ElasticModel& model, int contact_count, const std::vector<RowSet>& rows,
                                          const PrecomputeOptions& options) {
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
  t.material = model.material;
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
    for (std::size_t r = 0; r < set.nodes.size(); ++r)
      b.row_of_node[static_cast<std::size_t>(set.nodes[r])] = static_cast<int>(r);
    const Eigen::Index rr = 3 * static_cast<Eigen::Index>(set.nodes.size());
    // Every entry is written by store() below (zeros for fixed rows): no need to clear.
    b.symmetric = packs_symmetric(set, options);
    if (b.symmetric && set.nodes != t.contact_nodes)
      throw_error("precompute: row set '", set.name,
                  "' is to be stored as one symmetric half, but its nodes are not the ",
                  "contact nodes in ascending order");
    const std::size_t packed = 9 * set.nodes.size() * (set.nodes.size() + 1) / 2;
    if (b.symmetric && options.precision == Precision::kDouble)
      b.packed.resize(packed);
    else if (b.symmetric)
      b.packed_float.resize(packed);
    else if (options.precision == Precision::kDouble)
      b.g.resize(rr, cols);
    else
      b.g_float.resize(rr, cols);
    t.blocks.push_back(std::move(b));
  }
  // For each block, the free index of each matrix row (or -1 for a fixed component).
  std::vector<std::vector<int>> row_free(t.blocks.size());
  for (std::size_t k = 0; k < t.blocks.size(); ++k)
    for (int node : t.blocks[k].row_nodes)
      for (int c = 0; c < 3; ++c)
        row_free[k].push_back(model.fixed.free_index()[static_cast<std::size_t>(3 * node + c)]);

  // Copies solved column j (x: the solution, entry f at x[perm(f)], perm = identity when null) into every block.
  // A symmetric block takes rows 3c.. only (c = j / 3, the node column), the rest being the other half.
  auto store = [&](const double* x, const int* perm, Eigen::Index j) {
    const auto value = [&](int f) { return f < 0 ? 0.0 : x[perm ? perm[f] : f]; };
    for (std::size_t k = 0; k < t.blocks.size(); ++k) {
      TensorBlock& b = t.blocks[k];
      const auto& rf = row_free[k];
      if (b.symmetric) {
        const std::size_t i0 = 3 * static_cast<std::size_t>(j / 3);
        const std::size_t base = b.packed_index(static_cast<Eigen::Index>(i0), j);  // rows i0.. are contiguous by 3s
        for (std::size_t i = i0; i < rf.size(); ++i) {
          const std::size_t at = base + 3 * ((i - i0) / 3) * 3 + (i - i0) % 3;
          const double v = value(rf[i]);
          if (options.precision == Precision::kDouble)
            b.packed[at] = v;
          else
            b.packed_float[at] = static_cast<float>(v);
        }
        continue;
      }
      for (std::size_t i = 0; i < rf.size(); ++i) {
        const double v = value(rf[i]);
        if (options.precision == Precision::kDouble)
          b.g(static_cast<Eigen::Index>(i), j) = v;
        else
          b.g_float(static_cast<Eigen::Index>(i), j) = static_cast<float>(v);
      }
    }
  };
  const auto free_of_column = [&](Eigen::Index j) {
    return model.fixed
        .free_index()[static_cast<std::size_t>(3 * t.contact_nodes[static_cast<std::size_t>(j / 3)] + j % 3)];
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
    // Columns in the factor's row order, so that a block's unit vectors share their supernodes.
    std::vector<int> order(static_cast<std::size_t>(cols)), pos(static_cast<std::size_t>(cols));
    for (Eigen::Index j = 0; j < cols; ++j) pos[static_cast<std::size_t>(j)] = solver.permuted_row(free_of_column(j));
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(),
              [&](int a, int b) { return pos[static_cast<std::size_t>(a)] < pos[static_cast<std::size_t>(b)]; });
    // The rows any block stores: the backward solves visit their supernodes and ancestors only.
    std::vector<int> needed_rows;
    for (const auto& rf : row_free)
      for (int f : rf)
        if (f >= 0) needed_rows.push_back(f);
    std::sort(needed_rows.begin(), needed_rows.end());
    needed_rows.erase(std::unique(needed_rows.begin(), needed_rows.end()), needed_rows.end());
    const std::vector<char> needed = solver.supernodes_for_rows(needed_rows);
    std::vector<int> perm(static_cast<std::size_t>(nf));
    for (Eigen::Index f = 0; f < nf; ++f) perm[static_cast<std::size_t>(f)] = solver.permuted_row(static_cast<int>(f));

    const Eigen::Index block = std::max(1, options.block_columns);
    const Eigen::Index block_count = (cols + block - 1) / block;
    rep.threads = solving_threads(options, s);
    std::atomic<Eigen::Index> next{0};
    std::atomic<bool> failed{false};
    std::mutex progress_mutex;
    Eigen::Index done = 0;
    std::exception_ptr error;
    report_progress(0);
    BlasSingleThread blas_single;
    auto worker = [&]() {
      CholmodSolver::UnitSolveWork work;
      std::vector<int> rhs;
      try {
        for (Eigen::Index k = next++; k < block_count && !failed; k = next++) {
          const Eigen::Index j0 = k * block, nc = std::min(block, cols - j0);
          rhs.clear();
          for (Eigen::Index c = 0; c < nc; ++c) rhs.push_back(free_of_column(order[static_cast<std::size_t>(j0 + c)]));
          solver.solve_unit_columns(rhs.data(), static_cast<int>(nc), needed, work);
          for (Eigen::Index c = 0; c < nc; ++c)
            store(work.x.data() + static_cast<std::size_t>(c) * static_cast<std::size_t>(nf), perm.data(),
                  order[static_cast<std::size_t>(j0 + c)]);
          const std::lock_guard<std::mutex> lock(progress_mutex);
          done += nc;
          report_progress(done);
        }
      } catch (...) {
        const std::lock_guard<std::mutex> lock(progress_mutex);
        if (!error) error = std::current_exception();
        failed = true;
      }
    };
    std::vector<std::thread> pool;
    for (int i = 1; i < rep.threads; ++i) pool.emplace_back(worker);
    worker();
    for (auto& th : pool) th.join();
    if (error) std::rethrow_exception(error);
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
      store(x.data(), nullptr, j);
      report_progress(j + 1);
    }
    rep.solve_s = seconds_since(tsolve);
  }
  rep.total_s = seconds_since(t0);
  return t;
}

}  // namespace surgsim::compliance
