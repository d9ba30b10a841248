#include "compliance/precompute.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>

#include "fem/cholmod_solver.h"
#include "core/error.h"
#include "support/liver_test_util.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::intestine;

namespace surgsim {
namespace {

std::vector<int> all_nodes(int n) {
  std::vector<int> v(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) v[static_cast<std::size_t>(i)] = i;
  return v;
}

TEST(Precompute, ColumnsAreSolvesOfKff) {
  auto organ = test::box_organ(5, 4, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  ASSERT_GT(contacts.size(), 10u);
  PrecomputeOptions opts;
  opts.block_columns = 50;
  const auto rows = std::vector<RowSet>{{"all", all_nodes(static_cast<int>(organ->mesh.nodes.rows()))}};
  PrecomputeReport report;
  const Tensors t = precompute_tensors(organ->model, contacts, rows, opts, &report);
  ASSERT_EQ(t.column_count(), static_cast<int>(contacts.size()));
  const TensorBlock& b = *t.find("all");
  EXPECT_EQ(b.g.rows(), 3 * organ->mesh.nodes.rows());
  EXPECT_EQ(b.g.cols(), 3 * t.column_count());
  EXPECT_GT(report.memory.factor, 0u);
  EXPECT_EQ(report.memory.tensors, b.bytes());

  // Column of a unit force on contact c, component a = K_ff^-1 e, scattered to nodes (0 on fixed dofs).
  CholmodSolver solver(organ->model.k_ff);
  const auto& fixed = organ->fixed;
  for (int c : {0, t.column_count() / 2, t.column_count() - 1})
    for (int a = 0; a < 3; ++a) {
      Eigen::VectorXd e = Eigen::VectorXd::Zero(fixed.free_dof_count());
      e[fixed.free_index()[static_cast<std::size_t>(3 * t.contact_nodes[static_cast<std::size_t>(c)] + a)]] = 1;
      const Eigen::VectorXd x = solver.solve(Eigen::MatrixXd(e));
      Eigen::VectorXd full = Eigen::VectorXd::Zero(fixed.dof_count());
      for (int f = 0; f < fixed.free_dof_count(); ++f) full[fixed.free_dofs()[static_cast<std::size_t>(f)]] = x[f];
      EXPECT_LT(test::rel_error(b.g.col(3 * c + a), full), 1e-12);
    }
  // G_SS is symmetric (rows = all nodes: compare the contact-row sub-block with its transpose).
  double asym = 0;
  for (int i = 0; i < t.column_count(); i += 3)
    for (int j = 0; j < t.column_count(); j += 5) {
      const int ri = t.contact_nodes[static_cast<std::size_t>(i)], rj = t.contact_nodes[static_cast<std::size_t>(j)];
      asym = std::max(asym, (b.block3(ri, j) - b.block3(rj, i).transpose()).norm());
    }
  EXPECT_LT(asym, 1e-12 * b.g.cwiseAbs().maxCoeff());
}

TEST(Precompute, StandardRowSetsAndFloatStorage) {
  auto organ = test::box_organ(4, 3, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  const auto rows = standard_row_sets(organ->mesh, contacts);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].name, "haptic");
  EXPECT_EQ(rows[0].nodes, contacts);
  EXPECT_EQ(rows[1].name, "visual");
  EXPECT_GT(rows[1].nodes.size(), contacts.size());  // the clamped bottom face is visible but not contactable
  PrecomputeOptions opts;
  const Tensors d = precompute_tensors(organ->model, contacts, rows, opts);
  opts.precision = Precision::kFloat;
  const Tensors f = precompute_tensors(organ->model, contacts, rows, opts);
  for (const char* name : {"haptic", "visual"}) {
    const TensorBlock& bd = *d.find(name);
    const TensorBlock& bf = *f.find(name);
    EXPECT_EQ(bf.g.size(), 0);
    EXPECT_EQ(bf.bytes() * 2, bd.bytes());
    EXPECT_LT(test::rel_error(bf.g_float.cast<double>(), bd.g), 1e-6) << name;
  }
  // Fixed rows of the visual block are zero.
  const TensorBlock& v = *d.find("visual");
  for (int r = 0; r < v.row_count(); ++r)
    if (organ->fixed.node_touched(v.row_nodes[static_cast<std::size_t>(r)])) {
      EXPECT_EQ(v.g.middleRows<3>(3 * r).norm(), 0);
    }
}

TEST(Precompute, CgPerColumnAgreesWithDirectWithinTolerance) {
  auto organ = test::box_organ(4, 3, 2);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  const auto rows = standard_row_sets(organ->mesh, contacts);
  const Tensors d = precompute_tensors(organ->model, contacts, rows, PrecomputeOptions());
  PrecomputeOptions opts;
  opts.method = SolveMethod::kCg;
  opts.cg_tolerance = 1e-9;
  PrecomputeReport report;
  const Tensors c = precompute_tensors(organ->model, contacts, rows, opts, &report);
  EXPECT_TRUE(report.cg_all_converged);
  EXPECT_GT(report.cg_max_iterations, 0);
  EXPECT_LE(report.cg_max_residual, 1e-9);
  EXPECT_EQ(c.method, SolveMethod::kCg);
  EXPECT_LT(test::rel_error(c.find("visual")->g, d.find("visual")->g), 1e-5);
}

TEST(Precompute, ProgressReportsFractionAndEta) {
  auto organ = test::box_organ(4, 3, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  PrecomputeOptions opts;
  opts.block_columns = 30;
  std::vector<PrecomputeProgress> seen;
  opts.progress = [&](const PrecomputeProgress& p) { seen.push_back(p); };
  precompute_tensors(organ->model, contacts, standard_row_sets(organ->mesh, contacts), opts);
  ASSERT_GE(seen.size(), 3u);
  EXPECT_EQ(seen.front().columns_done, 0);
  EXPECT_EQ(seen.back().columns_done, 3 * static_cast<int>(contacts.size()));
  EXPECT_DOUBLE_EQ(seen.back().fraction, 1.0);
  EXPECT_DOUBLE_EQ(seen.back().eta_s, 0.0);
  for (std::size_t i = 1; i < seen.size(); ++i) {
    EXPECT_GT(seen[i].fraction, seen[i - 1].fraction);
    EXPECT_GE(seen[i].eta_s, 0.0);
  }
}

TEST(Precompute, MemoryLimitRefusesWithTheEstimate) {
  auto organ = test::box_organ(6, 5, 4);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  const auto rows = standard_row_sets(organ->mesh, contacts);
  PrecomputeOptions opts;
  const MemoryEstimate est = estimate_precompute_memory(organ->model, static_cast<int>(contacts.size()), rows, opts);
  std::size_t r = 0;
  for (const auto& s : rows) r += s.nodes.size();
  EXPECT_EQ(est.tensors, 9 * r * contacts.size() * sizeof(double));
  EXPECT_GT(est.factor, 0u);
  opts.memory_limit_mb = 0.5 * static_cast<double>(est.total()) / (1024.0 * 1024.0);
  bool called = false;
  opts.progress = [&](const PrecomputeProgress&) { called = true; };
  try {
    precompute_tensors(organ->model, contacts, rows, opts);
    FAIL() << "expected a refusal";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("exceeds the limit"), std::string::npos) << m;
    EXPECT_NE(m.find("--memory-limit-mb"), std::string::npos) << m;
    EXPECT_NE(m.find("MiB (tensors"), std::string::npos) << m;
  }
  EXPECT_FALSE(called);  // refused before solving anything
}

TEST(Precompute, BadNodeSetsAreErrors) {
  auto organ = test::box_organ(3, 2, 2);
  const std::vector<RowSet> rows = {{"haptic", {5}}};
  EXPECT_THROW(precompute_tensors(organ->model, {0}, rows, PrecomputeOptions()), Error);  // node 0 is fixed
  EXPECT_THROW(precompute_tensors(organ->model, {30, 30}, rows, PrecomputeOptions()), Error);
  EXPECT_THROW(precompute_tensors(organ->model, {30}, {{"a", {1000}}}, PrecomputeOptions()), Error);
  EXPECT_THROW(precompute_tensors(organ->model, {30}, {{"a", {1}}, {"a", {2}}}, PrecomputeOptions()), Error);
}

TEST(Precompute, IsDeterministic) {
  auto organ = test::box_organ(4, 3, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  const auto rows = standard_row_sets(organ->mesh, contacts);
  const Tensors a = precompute_tensors(organ->model, contacts, rows, PrecomputeOptions());
  const Tensors b = precompute_tensors(organ->model, contacts, rows, PrecomputeOptions());
  const auto& ga = a.find("visual")->g;
  const auto& gb = b.find("visual")->g;
  EXPECT_EQ(0, std::memcmp(ga.data(), gb.data(), sizeof(double) * static_cast<std::size_t>(ga.size())));
}

// G on every contact column at every node (0 on fixed components), from CHOLMOD's own blocked solve.
Eigen::MatrixXd full_g(const test::Organ& organ, const std::vector<int>& contacts) {
  std::vector<int> sorted = contacts;
  std::sort(sorted.begin(), sorted.end());
  const auto& fixed = organ.fixed;
  Eigen::MatrixXd e = Eigen::MatrixXd::Zero(fixed.free_dof_count(), 3 * static_cast<Eigen::Index>(sorted.size()));
  for (std::size_t c = 0; c < sorted.size(); ++c)
    for (int a = 0; a < 3; ++a)
      e(fixed.free_index()[static_cast<std::size_t>(3 * sorted[c] + a)], 3 * static_cast<Eigen::Index>(c) + a) = 1;
  CholmodSolver solver(organ.model.k_ff);
  const Eigen::MatrixXd x = solver.solve(e);
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(fixed.dof_count(), e.cols());
  for (int f = 0; f < fixed.free_dof_count(); ++f) g.row(fixed.free_dofs()[static_cast<std::size_t>(f)]) = x.row(f);
  return g;
}

// Largest |stored - full| over the block's rows, relative to the largest |full| entry.
double block_error(const TensorBlock& b, const Eigen::MatrixXd& full) {
  double err = 0, scale = 0;
  for (int r = 0; r < b.row_count(); ++r)
    for (int a = 0; a < 3; ++a)
      for (Eigen::Index j = 0; j < full.cols(); ++j) {
        const double want = full(3 * b.row_nodes[static_cast<std::size_t>(r)] + a, j);
        err = std::max(err, std::abs(b.at(3 * r + a, j) - want));
        scale = std::max(scale, std::abs(want));
      }
  return err / scale;
}

TEST(Precompute, StoredBlocksEqualTheFullComputation) {
  auto organ = test::box_organ(5, 4, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  const auto rows = standard_row_sets(organ->mesh, organ->fixed, contacts);
  const Eigen::MatrixXd full = full_g(*organ, contacts);
  // The visual rows are the boundary nodes that can move: no fully fixed node, every contact node.
  const auto boundary = boundary_surface(organ->mesh).nodes;
  std::size_t movable = 0;
  for (int n : boundary) movable += organ->fixed.mask(n) == 7 ? 0 : 1;
  EXPECT_EQ(rows[1].nodes.size(), movable);
  EXPECT_LT(movable, boundary.size());  // the clamped bottom face is gone
  PrecomputeOptions bad;
  bad.symmetric_blocks = {"visual", "haptic"};
  const std::vector<RowSet> wider = standard_row_sets(organ->mesh, contacts);  // visual: every boundary node
  EXPECT_THROW(precompute_tensors(organ->model, contacts, wider, bad), Error);
  for (Precision precision : {Precision::kDouble, Precision::kFloat}) {
    PrecomputeOptions opts;
    opts.symmetric_blocks = {"haptic"};
    opts.precision = precision;
    opts.block_columns = 7;  // many blocks, the last one partial
    opts.threads = 2;
    PrecomputeReport report;
    const Tensors t = precompute_tensors(organ->model, contacts, rows, opts, &report);
    const TensorBlock& h = *t.find("haptic");
    const TensorBlock& v = *t.find("visual");
    const auto s = static_cast<std::size_t>(t.column_count());
    EXPECT_TRUE(h.symmetric);
    EXPECT_FALSE(v.symmetric);
    EXPECT_EQ(h.stored_entries(), 9 * s * (s + 1) / 2);
    EXPECT_EQ(h.g.size() + h.g_float.size(), 0);
    EXPECT_EQ(report.memory.tensors, t.bytes());
    EXPECT_EQ(estimate_tensor_bytes(t.column_count(), rows, opts), t.bytes());
    const double bound = precision == Precision::kDouble ? 1e-12 : 1e-6;
    EXPECT_LT(block_error(h, full), bound) << to_string(precision);
    EXPECT_LT(block_error(v, full), bound) << to_string(precision);
    if (precision == Precision::kFloat) {
      EXPECT_GT(block_error(v, full), 1e-12);  // float is not double
    }
    // The packed half reads back symmetric, block by block.
    for (int i = 0; i < h.row_count(); i += 3)
      for (int j = 0; j < h.row_count(); j += 4)
        if (i != j) {
          EXPECT_EQ(h.block3(i, j), h.block3(j, i).transpose());
        }
  }
}

TEST(Precompute, ThreadCountDoesNotChangeABit) {
  auto organ = test::box_organ(5, 4, 3);
  const auto contacts = contactable_nodes(organ->mesh, organ->fixed);
  const auto rows = standard_row_sets(organ->mesh, organ->fixed, contacts);
  PrecomputeOptions opts;
  opts.symmetric_blocks = {"haptic"};
  opts.block_columns = 11;
  opts.threads = 1;
  const Tensors one = precompute_tensors(organ->model, contacts, rows, opts);
  for (int threads : {2, 3, 2}) {
    opts.threads = threads;
    PrecomputeReport report;
    const Tensors many = precompute_tensors(organ->model, contacts, rows, opts, &report);
    EXPECT_EQ(report.threads, threads);
    const auto& ph = one.find("haptic")->packed;
    const auto& qh = many.find("haptic")->packed;
    ASSERT_EQ(ph.size(), qh.size());
    EXPECT_EQ(0, std::memcmp(ph.data(), qh.data(), ph.size() * sizeof(double))) << threads << " threads";
    const auto& gv = one.find("visual")->g;
    const auto& hv = many.find("visual")->g;
    EXPECT_EQ(0, std::memcmp(gv.data(), hv.data(), sizeof(double) * static_cast<std::size_t>(gv.size())));
  }
  // Another block size changes only the rounding.
  opts.block_columns = 64;
  const Tensors other = precompute_tensors(organ->model, contacts, rows, opts);
  EXPECT_LT(test::rel_error(other.find("visual")->g, one.find("visual")->g), 1e-12);
}

}  // namespace
}  // namespace surgsim
