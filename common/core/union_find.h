// Union-find root with path halving over a parent array (parent[i] == i at a root). Used by the mesh topology
// checks (triangle surfaces, mechanically independent parts of a tetrahedral mesh).
#pragma once
#include <cstddef>
#include <vector>

namespace surgsim::core {

/// Root of i's set; halves the path on the way.
inline int find_root(std::vector<int>& parent, int i) {
  while (parent[static_cast<std::size_t>(i)] != i) {
    parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
    i = parent[static_cast<std::size_t>(i)];
  }
  return i;
}

}  // namespace surgsim::core
