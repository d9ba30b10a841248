// Precomputation of the elementary responses (docs/DESIGN.md, section 'Liver: precomputed linear elasticity'):
// G = K_ff^-1 restricted to the columns of the contactable nodes (free surface nodes) and to the rows each consumer
// needs. K_ff is factored once with CHOLMOD and the 3S right-hand sides are solved in blocks; or, as in the paper, each
// column by CG to a tolerance.
#pragma once
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "fem/fem.h"
#include "fem/static_solver.h"

namespace surgsim::compliance {

/// Storage precision of the tensors.
enum class Precision : std::uint8_t { kFloat = 4, kDouble = 8 };
const char* to_string(Precision precision);
/// "float" | "double"; throws surgsim::core::Error otherwise.
Precision parse_precision(const std::string& text);

/// A named set of row nodes ("haptic": the contactable nodes; "visual": the visible nodes).
struct RowSet {
  std::string name;
  std::vector<int> nodes;  // 0-based node indices, unique (any order; fixed nodes get zero rows)
};

/// G restricted to the rows of one RowSet and to every contactable column: the 3x3 block G(r, c) is the
/// displacement (m) of node row_nodes[r] for a unit force (N) on contact node c, so G is in m/N.
/// Dense (the default): exactly one of g / g_float holds data, by the owning Tensors' precision.
/// Symmetric (PrecomputeOptions::symmetric_blocks, for a block whose rows are the contact nodes in column
/// order, i.e. "haptic"): G is symmetric, so only the node blocks on and below the diagonal are stored, packed node
/// column by node column (column c holds rows c..R-1, each 3x3 block column-major) in packed / packed_float; g and
/// g_float are empty. Read either layout through at() and block3().
struct TensorBlock {
  std::string name;
  std::vector<int> row_nodes;       // R nodes; row r covers matrix rows 3r..3r+2 (x, y, z)
  std::vector<int> row_of_node;     // #V: the row of each node, or -1 when it is not a row of this block
  Eigen::MatrixXd g;                // 3R x 3S, m/N (double precision, dense), column-major
  Eigen::MatrixXf g_float;          // 3R x 3S, m/N (float precision, dense), column-major
  bool symmetric = false;           // packed lower half instead of g / g_float (then R = S)
  std::vector<double> packed;       // 9 R (R + 1) / 2, m/N (double precision, symmetric)
  std::vector<float> packed_float;  // 9 R (R + 1) / 2, m/N (float precision, symmetric)

  int row_count() const { return static_cast<int>(row_nodes.size()); }
  /// Index into packed / packed_float of entry (i, j) of a symmetric block (either triangle).
  std::size_t packed_index(Eigen::Index i, Eigen::Index j) const {
    Eigen::Index r = i / 3, c = j / 3, a = i % 3, b = j % 3;
    if (r < c) {
      std::swap(r, c);
      std::swap(a, b);
    }
    const auto n = static_cast<std::size_t>(row_nodes.size());
    const auto cc = static_cast<std::size_t>(c);
    return 9 * (cc * n - cc * (cc - 1) / 2 + static_cast<std::size_t>(r - c)) + static_cast<std::size_t>(a + 3 * b);
  }
  /// Entry (i, j) of the 3R x 3S matrix, as double.
  double at(Eigen::Index i, Eigen::Index j) const {
    if (symmetric) {
      const std::size_t k = packed_index(i, j);
      return packed.empty() ? static_cast<double>(packed_float[k]) : packed[k];
    }
    return g.size() ? g(i, j) : static_cast<double>(g_float(i, j));
  }
  /// The 3x3 block for row r and column c.
  Eigen::Matrix3d block3(int r, int c) const {
    Eigen::Matrix3d m;
    if (symmetric) {  // one index computation for the 9 entries; below the diagonal the stored block transposed
      const bool lower = r >= c;
      const std::size_t hi = static_cast<std::size_t>(lower ? r : c), lo = static_cast<std::size_t>(lower ? c : r);
      const std::size_t base = 9 * (lo * row_nodes.size() - lo * (lo - 1) / 2 + hi - lo);
      for (int b = 0; b < 3; ++b)
        for (int a = 0; a < 3; ++a) {
          const std::size_t k = base + static_cast<std::size_t>(lower ? a + 3 * b : b + 3 * a);
          m(a, b) = packed.empty() ? static_cast<double>(packed_float[k]) : packed[k];
        }
    } else if (g.size()) {
      m = g.block<3, 3>(3 * r, 3 * c);
    } else {
      m = g_float.block<3, 3>(3 * r, 3 * c).cast<double>();
    }
    return m;
  }
  /// Column j of the 3R x 3S matrix, as double (out: 3R entries).
  void column(Eigen::Index j, double* out) const;
  /// Entries stored (dense 9 R S; symmetric 9 R (R + 1) / 2).
  std::size_t stored_entries() const;
  std::size_t bytes() const {
    return static_cast<std::size_t>(g.size()) * sizeof(double) +
           static_cast<std::size_t>(g_float.size()) * sizeof(float) + packed.size() * sizeof(double) +
           packed_float.size() * sizeof(float);
  }
};

/// The precomputed tensors of one organ. Immutable once built or loaded; shared read-only by the loops.
struct Tensors {
  int node_count = 0;                    // #V of the mesh
  std::vector<int> contact_nodes;        // S contactable nodes, ascending; column c covers 3c..3c+2
  std::vector<int> column_of_node;       // #V: column of each node, or -1 when not contactable
  std::vector<std::uint8_t> fixed_mask;  // #V: fixed components of each node (bit c = component c)
  Precision precision = Precision::kDouble;
  fem::SolveMethod method = fem::SolveMethod::kDirect;
  double cg_tolerance = 0;  // relative residual per column when method == kCg
  std::vector<TensorBlock> blocks;
  /// The material the responses were computed with (set by precompute_tensors, load_or_build_tensors and the
  /// liver's tensor setup; not stored in the cache file, whose key holds it). The contact's near-field term needs it.
  std::optional<fem::Material> material;

  int column_count() const { return static_cast<int>(contact_nodes.size()); }
  /// The block with this name, or nullptr.
  const TensorBlock* find(const std::string& name) const;
  std::size_t bytes() const;
};

struct PrecomputeProgress {
  int columns_done = 0;  // right-hand sides solved so far (3 per contact node)
  int columns_total = 0;
  double fraction = 0;   // 0..1
  double elapsed_s = 0;  // since the start (analysis included)
  double eta_s = 0;      // estimated seconds to go
};

struct PrecomputeOptions {
  Precision precision = Precision::kDouble;
  fem::SolveMethod method = fem::SolveMethod::kDirect;
  double cg_tolerance = 1e-10;  // CG: relative residual per column
  int cg_max_iterations = 0;    // CG: 0 = 10 x the free dofs
  int block_columns = 96;       // direct: unit right-hand sides per blocked supernodal solve
  int threads = 0;              // direct: solving threads (0: every core); same result for any count
  /// Row sets stored as one packed half (TensorBlock::symmetric; each must be the contact nodes, ascending), e.g.
  /// {"haptic"}. The visual block stays dense even when its rows are the contacts: the visual node reads columns.
  std::vector<std::string> symmetric_blocks;
  double memory_limit_mb = 4096;  // refuse when the estimate exceeds this (MiB); <= 0: no limit
  /// Called after each block (direct: from the solving threads, one call at a time, columns_done increasing) or
  /// column (CG).
  std::function<void(const PrecomputeProgress&)> progress;
};

/// Memory the precomputation will hold at its peak, in bytes.
struct MemoryEstimate {
  std::size_t tensors = 0;  // the stored blocks
  std::size_t factor = 0;   // CHOLMOD's factor (exact after analysis; 0 for CG)
  std::size_t matrix = 0;   // K, K_ff and CHOLMOD's copy
  std::size_t work = 0;     // right-hand-side / solution blocks and solver workspace
  std::size_t total() const { return tensors + factor + matrix + work; }
  /// e.g. "1234.5 MiB (tensors 1100.0, factor 80.2, matrices 20.1, work 34.2)".
  std::string describe() const;
};

struct PrecomputeReport {
  MemoryEstimate memory;
  double analyze_s = 0, factor_s = 0, solve_s = 0, total_s = 0;  // wall-clock seconds
  int threads = 1;                                               // direct: solving threads used
  int cg_max_iterations = 0;                                     // CG: the most iterations any column needed
  double cg_max_residual = 0;                                    // CG: the worst relative residual
  bool cg_all_converged = true;  // CG: false if some column stopped at the iteration limit
};

/// Free boundary nodes (boundary_surface(mesh).nodes with no fixed component): the nodes a tool may touch.
std::vector<int> contactable_nodes(const mesh::TetMesh& mesh, const fem::FixedSet& fixed);

/// The standard consumers: "haptic" (rows = contact nodes: surface x surface, for G_CC and nearby displacements)
/// and "visual" (rows = every boundary node: visible x surface).
std::vector<RowSet> standard_row_sets(const mesh::TetMesh& mesh, const std::vector<int>& contact_nodes);
/// The same without the rows that are always zero (store only what is read): "visual" keeps the boundary
/// nodes with a free component (a fully fixed node does not move; the readers take it at rest).
std::vector<RowSet> standard_row_sets(const mesh::TetMesh& mesh, const fem::FixedSet& fixed,
                                      const std::vector<int>& contact_nodes);

/// Bytes the stored blocks take (symmetric packing and precision of `options`).
std::size_t estimate_tensor_bytes(int contact_count, const std::vector<RowSet>& rows, const PrecomputeOptions& options);

/// Estimate without factorizing (the factor size comes from CHOLMOD's symbolic analysis when direct).
MemoryEstimate estimate_precompute_memory(const fem::ElasticModel& model, int contact_count,
                                          const std::vector<RowSet>& rows, const PrecomputeOptions& options);

/// Computes the tensors. Direct: K_ff is factored once (CHOLMOD, supernodal); the unit right-hand sides of the
/// contact dofs, sorted in the factor's order, are solved in blocks of block_columns on `threads` threads sharing
/// the factor read-only; each forward solve visits only the supernodes its columns reach and each backward solve
/// only those holding a stored row or an ancestor of one (CholmodSolver::solve_unit_columns). contact_nodes: unique,
/// fully free nodes (any order; stored ascending). Throws surgsim::core::Error for bad node sets, or before any heavy
/// work when the memory estimate exceeds the limit (the message gives the estimate, the limit and the option that
/// raises it).
Tensors precompute_tensors(const fem::ElasticModel& model, const std::vector<int>& contact_nodes,
                           const std::vector<RowSet>& rows, const PrecomputeOptions& options,
                           PrecomputeReport* report = nullptr);

}  // namespace surgsim::compliance
