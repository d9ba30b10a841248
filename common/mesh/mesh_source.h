// Where an organ's tetrahedral mesh comes from (a scene's `mesh:` key): a file or the project's generator.
#pragma once
#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

namespace surgsim::mesh {

/// Where the organ's tetrahedral mesh comes from: a file, or the project's own generator.
struct MeshSource {
  std::string file;          // absolute path (resolved against the scene's folder); empty when generated
  std::string generate;      // "liver" | "plate" | "cylinder"; empty when `file` is set
  int target_nodes = 1500;   // approximate node count of a generated mesh, 100..100000
};

}  // namespace surgsim::mesh
