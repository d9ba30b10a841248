// Makes the seeds of the cache targets with the code that writes the caches, so that they are valid files of the
// current formats: a tensor cache in each precision (one dense block, one symmetric) and an organ-curve cache.
// Usage: fuzz_make_seeds OUT_FOLDER   (writes OUT/fuzz_tensor_cache/{double,float}.bin and
// OUT/fuzz_organ_curves/curves.csv; the ctest fuzz_cache_seeds_are_current compares them with the committed ones)
#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>

#include "compliance/tensor_cache.h"
#include "nonlinear/organ_curves.h"

using namespace surgsim;

namespace {

// Four nodes, two contactable (1 and 3), node 0 fully fixed; the responses are made-up numbers (the fuzz target
// reads the file, it does not solve).
compliance::Tensors tiny_tensors(compliance::Precision precision) {
  compliance::Tensors t;
  t.node_count = 4;
  t.contact_nodes = {1, 3};
  t.column_of_node = {-1, 0, -1, 1};
  t.fixed_mask = {7, 0, 0, 0};
  t.precision = precision;
  compliance::TensorBlock dense;
  dense.name = "surface";
  dense.row_nodes = {0, 2, 3};
  dense.g = Eigen::MatrixXd::Zero(9, 6);
  for (Eigen::Index i = 0; i < dense.g.size(); ++i) dense.g(i) = 1e-4 * static_cast<double>(i % 7 + 1);
  compliance::TensorBlock sym;
  sym.name = "contact";
  sym.symmetric = true;
  sym.row_nodes = t.contact_nodes;
  sym.packed.resize(27);
  for (std::size_t i = 0; i < sym.packed.size(); ++i) sym.packed[i] = 2e-4 * static_cast<double>(i % 5 + 1);
  if (precision == compliance::Precision::kFloat) {
    dense.g_float = dense.g.cast<float>();
    dense.g.resize(0, 0);
    sym.packed_float.assign(sym.packed.begin(), sym.packed.end());
    sym.packed.clear();
  }
  t.blocks = {dense, sym};
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_make_seeds OUT_FOLDER\n");
    return 2;
  }
  try {
    const std::filesystem::path out(argv[1]);
    std::filesystem::create_directories(out / "fuzz_tensor_cache");
    const compliance::TensorCacheKey key{0x1111, 0x2222, 0x3333, 0x4444};
    compliance::save_tensor_cache((out / "fuzz_tensor_cache" / "double.bin").string(),
                                  tiny_tensors(compliance::Precision::kDouble), key);
    compliance::save_tensor_cache((out / "fuzz_tensor_cache" / "float.bin").string(),
                                  tiny_tensors(compliance::Precision::kFloat), key);

    nonlinear::OrganCurves curves;
    curves.key = 0x0123456789abcdefull;
    for (int i = 0; i < 3; ++i) {
      nonlinear::OrganCurveSample s;
      s.site_x = 0.01 * i;
      s.site_y = -0.02;
      s.centre = Eigen::Vector3d(0.01 * i, -0.02, 0.04);
      s.thickness = 0.06;
      s.lever = 0.05;
      s.depth = 0.002 * (i + 1);
      s.nodes = 5 + i;
      s.linear_force = 0.1 * (i + 1);
      s.newton_force = 0.11 * (i + 1);
      s.converged = i != 2;
      curves.samples.push_back(s);
    }
    nonlinear::save_organ_curves((out / "fuzz_organ_curves" / "curves.csv").string(), curves);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fuzz_make_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
