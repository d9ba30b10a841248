// The reference the multirate liver's force is measured against (multirate_node_bench, the haptic node's integration
// test): the neo-Hookean Newton solve (fem/hyperelastic.h) of the tick's contact targets, the solution's nodes and
// the displacements the tracker is handed, on the scene's mesh, material and fixed set as the tensors resolve it; the
// force on the tool is minus its reaction sum. The error is large_deformation_bench's measure,
// |F - F_ref| / max(|F_ref|, floor), the floor 5 % of the largest |F_ref| of a run (0 for a single sample).
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <string>
#include <vector>

#include "fem/fem.h"
#include "fem/hyperelastic.h"
#include "fem/static_solver.h"
#include "liver/liver_setup.h"
#include "mesh/mesh.h"
#include "scene/scene.h"

namespace surgsim::test {

class NewtonReference {
 public:
  /// `mesh` (the scene's, as the organ loads it) must outlive this object; the fixed set is the tensors' own
  /// (liver_tensor_setup on `cache`). Throws surgsim::core::Error on a bad model.
  NewtonReference(const scene::Scene& scene, const mesh::TetMesh& mesh, const std::string& cache)
      : model_(fem::build_elastic_model(
            mesh, scene.material, liver::liver_tensor_setup(scene.material, scene.fixed, mesh, cache, scene.file).fixed,
            scene.file)),
        newton_(model_) {}
  NewtonReference(const NewtonReference&) = delete;
  NewtonReference& operator=(const NewtonReference&) = delete;

  /// The force on the tool (N) for these targets (every component imposed); false when Newton did not converge.
  bool tool_force(const std::vector<fem::ImposedDisplacement>& targets, Eigen::Vector3d& force) const {
    const fem::HyperelasticSolution ref = newton_.solve(targets);
    force = -ref.total_reaction;
    return ref.converged();
  }

 private:
  fem::ElasticModel model_;
  fem::HyperelasticSolver newton_;
};

/// |f - ref| / max(|ref|, floor).
inline double relative_error(const Eigen::Vector3d& f, const Eigen::Vector3d& ref, double floor = 0) {
  return (f - ref).norm() / std::max(ref.norm(), floor);
}

}  // namespace surgsim::test
