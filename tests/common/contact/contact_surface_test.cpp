// ContactSurface::footprint (contact/contact_surface.h): the tip's weights are the shape functions integrated against
// the punch pressure over its disc. On a flat face they sum to 1 and their first moment is the tip's centre (P1
// shape functions reproduce linear fields; the pressure is axisymmetric), they change continuously with the centre,
// the weights of fixed nodes and of faces turned away are left out.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <vector>

#include "contact/contact_surface.h"
#include "mesh/box_mesh.h"

using namespace surgsim;
using namespace surgsim::contact;
using namespace surgsim::mesh;

namespace {

struct Box {
  TetMesh mesh;
  SurfaceMesh surface;
  std::vector<std::uint8_t> free;
  Box() {
    mesh = make_box_mesh(10, 10, 2, {0.1, 0.1, 0.02});  // 1 cm cells, top at z = 0.02
    surface = boundary_surface(mesh);
    free.assign(static_cast<std::size_t>(mesh.nodes.rows()), 0);
    for (int v : surface.nodes) free[static_cast<std::size_t>(v)] = mesh.nodes(v, 0) > 0.0051 ? 1 : 0;  // x = 0 fixed
  }
};

struct Weights {
  int count = 0, dropped = 0, fixed = 0;
  std::map<int, double> w;
};

Weights footprint(const Box& b, const ContactSurface& s, const Eigen::Vector3d& c, double a) {
  int nodes[64];
  double weights[64];
  Weights out;
  // The top-face triangle under c (brute force).
  int best = -1;
  double bd = 1e300;
  for (int f = 0; f < b.surface.tris.rows(); ++f) {
    const RestPoint r = s.on_triangle(c, f);
    if (r.distance < bd && r.face_normal.z() > 0.9) bd = r.distance, best = f;
  }
  out.count = s.footprint(c, best, Eigen::Vector3d::UnitZ(), a, 64, nodes, weights, &out.dropped, &out.fixed);
  for (int i = 0; i < out.count; ++i) out.w[nodes[i]] = weights[i];
  return out;
}

}  // namespace

TEST(ContactSurfaceFootprint, WeightsSumToOneWithTheCentreAsFirstMoment) {
  const Box b;
  const ContactSurface s(b.mesh, b.surface, b.free, 0.005);
  for (const Eigen::Vector3d c : {Eigen::Vector3d(0.05, 0.05, 0.02), Eigen::Vector3d(0.0537, 0.0461, 0.02),
                                  Eigen::Vector3d(0.0421, 0.0588, 0.02)}) {
    for (double a : {0.002, 0.005, 0.013}) {
      const Weights w = footprint(b, s, c, a);
      ASSERT_GT(w.count, 0);
      double sum = 0;
      Eigen::Vector3d moment = Eigen::Vector3d::Zero();
      for (const auto& [node, weight] : w.w) {
        EXPECT_GT(weight, 0);
        sum += weight;
        moment += weight * b.mesh.nodes.row(node).transpose();
      }
      EXPECT_NEAR(sum, 1.0, 1e-12);
      EXPECT_NEAR((moment - c).norm(), 0.0, 1e-12) << "a " << a << " at " << c.transpose();
      EXPECT_EQ(w.fixed, 0);
      EXPECT_EQ(w.dropped, 0);
    }
  }
  // A tip smaller than a cell, centred on a node: the node holds most of the load.
  const Weights on = footprint(b, s, {0.05, 0.05, 0.02}, 0.002);
  double largest = 0;
  for (const auto& [node, weight] : on.w) largest = std::max(largest, weight);
  EXPECT_GT(largest, 0.7);
}

TEST(ContactSurfaceFootprint, ContinuousInTheCentre) {
  const Box b;
  const ContactSurface s(b.mesh, b.surface, b.free, 0.005);
  Weights prev = footprint(b, s, {0.0400, 0.0537, 0.02}, 0.005);
  for (int k = 1; k <= 200; ++k) {  // 2 cm in 0.1 mm steps, across two cells
    const Weights w = footprint(b, s, {0.0400 + 1e-4 * k, 0.0537, 0.02}, 0.005);
    std::map<int, double> all = prev.w;
    for (const auto& [node, weight] : w.w) all[node] += 0;
    double change = 0;
    for (const auto& [node, unused] : all) {
      const double a = prev.w.count(node) ? prev.w.at(node) : 0.0, c = w.w.count(node) ? w.w.at(node) : 0.0;
      change = std::max(change, std::abs(c - a));
    }
    // 0.1 mm of a 1 cm cell: a weight moves by about 1e-2; a jump (a node entering whole) would be much larger.
    EXPECT_LT(change, 0.03) << "step " << k;
    prev = w;
  }
}

TEST(ContactSurfaceFootprint, LeavesOutFixedNodesAndFacesTurnedAway) {
  const Box b;
  const ContactSurface s(b.mesh, b.surface, b.free, 0.005);
  // Near the fixed edge x = 0: the weights of its nodes are left out, the others renormalized.
  const Weights edge = footprint(b, s, {0.004, 0.05, 0.02}, 0.005);
  EXPECT_GT(edge.fixed, 0);
  double sum = 0;
  for (const auto& [node, weight] : edge.w) {
    EXPECT_GT(b.mesh.nodes(node, 0), 0.0051);
    sum += weight;
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  // Over the top face's far edge x = 0.1: the disc's outer half falls off the face (the side face is turned 90
  // degrees away from the pressing direction): only top nodes carry weight.
  const Weights off = footprint(b, s, {0.098, 0.05, 0.02}, 0.005);
  ASSERT_GT(off.count, 0);
  for (const auto& [node, weight] : off.w) EXPECT_NEAR(b.mesh.nodes(node, 2), 0.02, 1e-12);
  // No tip: nothing.
  int nodes[4];
  double weights[4];
  EXPECT_EQ(s.footprint({0.05, 0.05, 0.02}, 0, Eigen::Vector3d::UnitZ(), 0.0, 4, nodes, weights, nullptr, nullptr), 0);
}
