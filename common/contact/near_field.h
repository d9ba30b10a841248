// The instrument's near field: the part of a tip's indentation compliance that the organ's mesh cannot resolve.
//
// A tip of radius a pressed into the organ is a rigid flat punch: on an elastic half-space its compliance is
// (1 - nu^2) / (2 a E) (Sneddon 1965), about 0.03 m/N for a 5 mm tip in a 3 kPa liver. The precomputed tensors
// (linear P1 elements) see the tip only through the nodal weights w_i of its footprint (the shape functions
// integrated against the punch's pressure, ContactSurface::footprint), and a mesh whose surface edge is as long as the
// tip, or longer, returns a much stiffer w^T G w: the dimple under the tip is smaller than one element. The contact
// keeps what the mesh resolves (the organ's shape, its fixed set, the far field) and replaces what it cannot (the
// field within one element of the tip) by the punch's analytic near field, a compliance in series with the patch
// (PatchConstraints::near_normal):
//
//   dC_n = k pi / (2 a)  -  sum_{i,j neighbours} w_i w_j L_ij  -  sum_{i,j farther} w_i w_j k / |x_i - x_j|,
//   k = (1 - nu^2) / (pi E)  (Boussinesq's kernel),                                                (clamped at >= 0)
//
// so that the patch's total compliance w^T G w + dC_n is the punch's k pi/(2a) plus the mesh's SMOOTH remainder: for
// nodes farther apart than one ring, G_ij - k / r_ij (the mesh's field less the half-space kernel); for a node and its
// ring, L_ij = G_ij - (S_i + S_j) / 2 is the mesh's own local compliance (normal components, symmetrized) less its
// smooth part S_i, which is found by requiring that the mesh's excess over the half-space picture vanish on smooth
// loads: S_i = sum_{j in i and its ring} A_j (G_ij - k I_ij) / sum A_j, with A_j the node's area and I_ij the
// Boussinesq interaction int int phi_i phi_j / |x - y| of the nodes' hat functions normalized to unit integral
// (integrated numerically at init: each incident triangle split into kSplit^2 sub-triangles, a sub-triangle's self
// term that of a disc of equal area). Nodes without a tensor row and column fall back to L_ij = k I_ij.
//
// Assumptions (README, docs/DESIGN.md): the surface is locally flat over the footprint and one ring around it, the
// tissue there homogeneous, and the mesh accurate for loads spread over more than one ring. Checked against the
// bonded-layer solution of Hayes et al. 1972 and across the 1.4k, 5k and 21k livers by build/bench/tool_size_bench.
// Where the mesh resolves the tip, dC_n tends to 0.
//
// Tangential rows (friction, a grasp) get dC_t = dC_n (2 - nu) / (2 (1 - nu)): the ratio of the Cerruti to the
// Boussinesq kernel averaged over directions, exact for an axisymmetric load's self-energy.
//
// Init allocates and reads the tensors once; normal() allocates nothing and never throws.
#pragma once
#include <vector>

#include "compliance/precompute.h"
#include "fem/material.h"
#include "mesh/mesh.h"

namespace surgsim::contact {

class NearField {
 public:
  static constexpr int kSplit = 4;  // sub-triangles per triangle edge in the hat-function integrals

  /// `tensors` (its "haptic" block) give the mesh's own local compliance; null: the hat-function picture alone
  /// (L_ij = k I_ij, S = 0). Throws surgsim::core::Error for a material out of range. The Boussinesq kernel is the
  /// base material's everywhere: the material regions (fem::Material::regions) are in the tensors, not in this
  /// sub-mesh correction (it assumes the tissue homogeneous under the tip and one ring around it).
  NearField(const mesh::TetMesh& mesh, const mesh::SurfaceMesh& surface, const fem::Material& material,
            const compliance::Tensors* tensors = nullptr);

  /// dC_n (m/N) of a punch of radius `a` (m) whose load the mesh sees as `weights` (sum 1) on surface `nodes`.
  double normal(const int* nodes, const double* weights, int count, double a) const noexcept;
  /// dC_t for a given dC_n.
  double tangential(double normal) const noexcept { return tangent_ratio_ * normal; }
  /// (1 - nu^2) / (pi E): Boussinesq's normal kernel factor (m/N times m).
  double kernel() const noexcept { return kernel_; }
  /// I_ij (1/m) of two surface nodes (the self term when i == j; 1/|x_i - x_j| beyond the ring).
  double interaction(int i, int j) const noexcept;
  /// L_ij (m/N) of a node and itself or its ring; k / |x_i - x_j| beyond.
  double local(int i, int j) const noexcept;
  /// S_i (m/N): the smooth part of the mesh's compliance at node i (0 without tensors).
  double smooth(int i) const noexcept { return smooth_[static_cast<std::size_t>(i)]; }

 private:
  const mesh::TetMesh& mesh_;
  double kernel_ = 0, tangent_ratio_ = 1;
  std::vector<double> self_;                // per mesh node: I_ii (0 off the surface)
  std::vector<int> start_, other_;          // CSR per mesh node: neighbouring surface nodes
  std::vector<double> value_;               // I_ij of those pairs
  std::vector<double> self_local_, local_;  // L_ii per node, L_ij per pair (as self_, value_)
  std::vector<double> smooth_;              // S_i
};

}  // namespace surgsim::contact
