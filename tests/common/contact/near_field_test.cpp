// NearField (contact/near_field.h): its hat-function interaction integrals against an independent rasterized
// quadrature, its scale (I ~ 1/h), and the near field's limits: positive and close to the whole punch compliance on a
// mesh much coarser than the tip, small on a mesh that resolves it, never negative.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "contact/near_field.h"
#include "mesh/box_mesh.h"

using namespace surgsim;
using namespace surgsim::contact;
using namespace surgsim::mesh;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Box {
  TetMesh mesh;
  SurfaceMesh surface;
  Box(int n, double size) {
    mesh = make_box_mesh(n, n, 2, {size, size, 0.2 * size});
    surface = boundary_surface(mesh);
  }
  // The top-face node nearest (x, y).
  int node_at(double x, double y) const {
    int best = -1;
    double bd = 1e300;
    for (int v : surface.nodes) {
      const Eigen::Vector3d p = mesh.nodes.row(v).transpose();
      if (std::abs(p.z() - mesh.nodes.col(2).maxCoeff()) > 1e-12) continue;
      const double d = std::hypot(p.x() - x, p.y() - y);
      if (d < bd) bd = d, best = v;
    }
    return best;
  }
};

// Hat function of top node `v` on the flat top face, evaluated at (x, y) from the surface triangles (independent of
// NearField's sub-triangle clouds): barycentric weight of v in the top triangle holding the point.
double hat(const Box& b, int v, double x, double y) {
  const double top = b.mesh.nodes.col(2).maxCoeff();
  for (Eigen::Index f = 0; f < b.surface.tris.rows(); ++f) {
    Eigen::Vector3d p[3];
    int at = -1;
    bool flat = true;
    for (int k = 0; k < 3; ++k) {
      p[k] = b.mesh.nodes.row(b.surface.tris(f, k)).transpose();
      flat &= std::abs(p[k].z() - top) < 1e-12;
      if (b.surface.tris(f, k) == v) at = k;
    }
    if (!flat || at < 0) continue;
    const double d = (p[1].x() - p[0].x()) * (p[2].y() - p[0].y()) - (p[1].y() - p[0].y()) * (p[2].x() - p[0].x());
    const double l1 = ((x - p[0].x()) * (p[2].y() - p[0].y()) - (y - p[0].y()) * (p[2].x() - p[0].x())) / d;
    const double l2 = ((p[1].x() - p[0].x()) * (y - p[0].y()) - (p[1].y() - p[0].y()) * (x - p[0].x())) / d;
    const double l[3] = {1 - l1 - l2, l1, l2};
    if (l[0] < -1e-12 || l[1] < -1e-12 || l[2] < -1e-12) continue;
    return l[at];
  }
  return 0;
}

// int int phi_i phi_j / |x - y| with the hats normalized to unit integral, on a fine raster (cell centres; a cell's
// self term is that of the square, 4 ln(1 + sqrt 2) / h_cell ... times its area squared, exactly:
// int int_{square s} 1/|x-y| = s^3 * (4/3) (1 - sqrt 2) + 4 s^3 ln(1 + sqrt 2)).
double raster_interaction(const Box& b, int i, int j, double cell, int n) {
  const Eigen::Vector3d ci = b.mesh.nodes.row(i).transpose(), cj = b.mesh.nodes.row(j).transpose();
  struct P {
    double x, y, w;
  };
  const auto sample = [&](int v, const Eigen::Vector3d& c) {
    std::vector<P> out;
    const double h = 2 * cell / n;
    double sum = 0;
    for (int a = 0; a < n; ++a)
      for (int k = 0; k < n; ++k) {
        const double x = c.x() - cell + (a + 0.5) * h, y = c.y() - cell + (k + 0.5) * h;
        const double w = hat(b, v, x, y) * h * h;
        if (w > 0) out.push_back({x, y, w}), sum += w;
      }
    for (P& p : out) p.w /= sum;
    return out;
  };
  const std::vector<P> a = sample(i, ci), c = sample(j, cj);
  const double h = 2 * cell / n;
  const double self =
      (4.0 / 3.0 * (1 - std::sqrt(2.0)) + 4 * std::log(1 + std::sqrt(2.0))) * h * h * h / (h * h * h * h);
  double s = 0;
  for (const P& p : a)
    for (const P& q : c) {
      const double d = std::hypot(p.x - q.x, p.y - q.y);
      s += p.w * q.w * (d < 1e-12 ? self : 1.0 / d);
    }
  return s;
}

}  // namespace

TEST(NearField, InteractionsMatchAnIndependentQuadrature) {
  const Box b(10, 0.1);  // 1 cm cells
  const NearField nf(b.mesh, b.surface, {3000.0, 0.45});
  const int i = b.node_at(0.05, 0.05), j = b.node_at(0.06, 0.05), k = b.node_at(0.06, 0.06);
  for (const auto& [p, q] : {std::pair{i, i}, std::pair{i, j}, std::pair{i, k}}) {
    const double ref = raster_interaction(b, p, q, 0.01, 160);
    EXPECT_NEAR(nf.interaction(p, q) / ref, 1.0, 0.02)
        << p << "," << q << ": " << nf.interaction(p, q) << " vs " << ref;
  }
  // Pairs that are not neighbours: the point formula.
  const int far = b.node_at(0.08, 0.05);
  EXPECT_DOUBLE_EQ(nf.interaction(i, far), 1.0 / 0.03);
  EXPECT_DOUBLE_EQ(nf.interaction(i, j), nf.interaction(j, i));
}

TEST(NearField, ScalesWithTheElementAndVanishesWhenTheMeshResolvesTheTip) {
  const Box coarse(10, 0.1), fine(10, 0.05);  // 1 cm and 5 mm cells, the same pattern
  const NearField nc(coarse.mesh, coarse.surface, {3000.0, 0.45}), nfine(fine.mesh, fine.surface, {3000.0, 0.45});
  const int ic = coarse.node_at(0.05, 0.05), ifine = fine.node_at(0.025, 0.025);
  EXPECT_NEAR(nfine.interaction(ifine, ifine) / nc.interaction(ic, ic), 2.0, 1e-9);
  const double kernel = (1 - 0.45 * 0.45) / (kPi * 3000.0);
  EXPECT_DOUBLE_EQ(nc.kernel(), kernel);
  const double w = 1.0;
  // A tip of 1 mm on 1 cm cells: nearly the whole punch compliance is missing from the mesh.
  const double small = nc.normal(&ic, &w, 1, 0.001);
  EXPECT_GT(small, 0.8 * kernel * kPi / (2 * 0.001));
  EXPECT_LT(small, kernel * kPi / (2 * 0.001));
  // A tip far wider than the element, seen as one node: the hat's own energy exceeds the punch's: clamped at 0.
  EXPECT_EQ(nc.normal(&ic, &w, 1, 0.2), 0.0);
  EXPECT_EQ(nc.tangential(1.0), (2 - 0.45) / (2 * (1 - 0.45)));
  EXPECT_THROW(NearField(coarse.mesh, coarse.surface, {-1.0, 0.45}), std::exception);
}
