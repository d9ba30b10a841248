// A direct solve of linear elasticity under linear constraints on surface nodes, independent of the precomputed
// tensors and of CHOLMOD: K_ff (assembled by fem/fem.h) factored by Eigen's sparse LDLT, the constraints imposed by
// Lagrange multipliers. Used to check that the contact solve of several instruments is the exact one: the
// liver two-hands test and two_hands_bench.
#pragma once
#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>
#include <vector>

#include "fem/fem.h"
#include "contact/tool_contacts.h"

namespace surgsim::test {

/// One linear constraint on the organ: sum_i w_i d . u_i = b over nodes i (d unit), and whose it is.
struct ConstraintRow {
  std::vector<int> nodes;
  std::vector<double> weights;
  Eigen::Vector3d d = Eigen::Vector3d::UnitZ();
  double b = 0;
  int instrument = 0;
  // The tip's near field in series (contact/near_field.h): rows of one patch (the same group >= 0) add
  // d_r^T near d_l to the constraint compliance.
  int group = -1;
  Eigen::Matrix3d near = Eigen::Matrix3d::Zero();
};

/// The rows ToolContacts (patch model) imposed for point i of instrument t in its last step: the patch's normal row
/// (a sliding contact), or three Cartesian rows (a grasp or sticking contact: a 3-D constraint, basis-independent).
inline void add_patch_rows(const contact::ToolContacts& c, int i, int t, bool three_d,
                           std::vector<ConstraintRow>& rows) {
  const contact::PointPatch& p = c.patch(i, t);
  const contact::PointContact& pc = c.point(i, t);
  const Eigen::Vector3d dirs[3] = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ()};
  for (int r = 0; r < (three_d ? 3 : 1); ++r) {
    ConstraintRow row;
    row.nodes.assign(p.nodes.begin(), p.nodes.begin() + p.count);
    row.weights.assign(p.weights.begin(), p.weights.begin() + p.count);
    row.d = three_d ? dirs[r] : p.normal;
    row.b = row.d.dot(pc.offset);
    row.instrument = t;
    row.group = t * tool::kMaxShaftPoints + i;
    row.near = p.near_tangent * Eigen::Matrix3d::Identity() +
               (p.near_normal - p.near_tangent) * p.normal * p.normal.transpose();
    rows.push_back(row);
  }
}

class DirectConstraintSolver {
 public:
  /// Factors K_ff of `model` (which must outlive this).
  explicit DirectConstraintSolver(const fem::ElasticModel& model) : model_(model), ldlt_(model.k_ff) {}
  bool ok() const { return ldlt_.info() == Eigen::Success; }

  /// Minimum energy with every row imposed: S = A K_ff^-1 A^T (plus each patch's near field), mu = S^-1 b; row r pushes
  /// the ORGAN with mu_r d_r (its weights sum to 1). Returns the force on each of `instruments` instruments: minus its
  /// rows' forces on the organ.
  std::vector<Eigen::Vector3d> forces(const std::vector<ConstraintRow>& rows, int instruments) const {
    const auto& free_index = model_.fixed.free_index();
    const Eigen::Index m = static_cast<Eigen::Index>(rows.size());
    Eigen::MatrixXd at = Eigen::MatrixXd::Zero(model_.k_ff.rows(), m);
    Eigen::VectorXd b(m);
    for (Eigen::Index r = 0; r < m; ++r) {
      const ConstraintRow& row = rows[static_cast<std::size_t>(r)];
      for (std::size_t e = 0; e < row.nodes.size(); ++e)
        for (int k = 0; k < 3; ++k) {
          const int f = free_index[static_cast<std::size_t>(3 * row.nodes[e] + k)];
          if (f >= 0) at(f, r) += row.weights[e] * row.d[k];
        }
      b[r] = row.b;
    }
    Eigen::MatrixXd s = at.transpose() * ldlt_.solve(at);
    for (Eigen::Index r = 0; r < m; ++r)
      for (Eigen::Index l = 0; l < m; ++l) {
        const ConstraintRow &x = rows[static_cast<std::size_t>(r)], &y = rows[static_cast<std::size_t>(l)];
        if (x.group >= 0 && x.group == y.group) s(r, l) += x.d.dot(x.near * y.d);
      }
    const Eigen::VectorXd mu = s.ldlt().solve(b);
    std::vector<Eigen::Vector3d> force(static_cast<std::size_t>(instruments), Eigen::Vector3d::Zero());
    for (Eigen::Index r = 0; r < m; ++r) {
      const ConstraintRow& row = rows[static_cast<std::size_t>(r)];
      force[static_cast<std::size_t>(row.instrument)] -= mu[r] * row.d;
    }
    return force;
  }

 private:
  const fem::ElasticModel& model_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
};

}  // namespace surgsim::test
