// One place that turns a liver scene + its mesh into the tensor inputs (fixed set, contactable nodes, row sets,
// options, cache key and path), so that the haptic node, the visual node and surgsim-precompute always agree on
// the cache they share.
#pragma once
#include <cstddef>
#include <iosfwd>
#include <string>
#include <vector>

#include "fem/fixed_set.h"
#include "compliance/precompute.h"
#include "fem/material.h"
#include "mesh/mesh.h"
#include "compliance/tensor_cache.h"

namespace surgsim::liver {

/// Scenes store their tensors in float once double would take more than this (MiB: 1 GiB), so that patient-size
/// livers fit.
inline constexpr std::size_t kFloatAboveMiB = 1024;

/// The precision of a scene's tensors that take `double_bytes` in double: double up to `float_above_mib` MiB, float
/// beyond (a 21k-node liver: 2.2 GiB in double, 1.1 GiB in float, relative error ~1e-7). The decision apart from the
/// tensors, so that it is tested on both sides without allocating a gibibyte.
compliance::Precision scene_precision(std::size_t double_bytes, std::size_t float_above_mib = kFloatAboveMiB);

/// The precompute options of a scene: direct, the "haptic" block as one packed half, and scene_precision of the
/// size the tensors would take in double (estimate_tensor_bytes).
compliance::PrecomputeOptions scene_precompute_options(int contact_count, const std::vector<compliance::RowSet>& rows);

struct LiverTensorSetup {
  fem::FixedSet fixed;
  std::vector<int> contacts;     // contactable (free surface) nodes
  std::vector<compliance::RowSet> rows;   // "haptic" (surface x surface) and "visual" (boundary x surface)
  compliance::PrecomputeOptions options;  // direct, symmetric haptic block, double (float above kFloatAboveMiB)
  compliance::TensorCacheKey key;
  std::string cache_path;        // <cache_dir>/tensors-<combined key, hex>.bin
};

/// Resolves the fixed region on the mesh and derives everything the tensors depend on (the material enters the key).
/// Throws surgsim::core::Error (e.g. a fixed set leaving a rigid mode free) naming `where` (the scene file).
LiverTensorSetup liver_tensor_setup(const fem::Material& material, const fem::FixedRegion& fixed,
                                    const mesh::TetMesh& mesh, const std::string& cache_dir, const std::string& where);

/// Loads the cached tensors keeping only `blocks` ("haptic", "visual"; empty = all), or, when the cache is missing,
/// stale or corrupt, precomputes them (progress with ETA on `log`), saves the cache and keeps `blocks`. Concurrent
/// callers on the same cache serialize on a lock file, so the work is done once. Throws surgsim::core::Error.
compliance::Tensors load_liver_tensors(const LiverTensorSetup& setup, const mesh::TetMesh& mesh,
                                       const fem::Material& material, const std::vector<std::string>& blocks,
                                       std::ostream* log, compliance::CacheOutcome* outcome = nullptr,
                                       const std::string& where = "");

}  // namespace surgsim::liver
