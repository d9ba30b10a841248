// The visual node's deformation equals the reference solve, and a rendered dent changes pixels near the contact only.
#include "views/surface_deformer.h"

#include <gtest/gtest.h>

#include <random>

#include "mesh/box_mesh.h"
#include "core/error.h"
#include "fem/fem.h"
#include "fem/fixed_set.h"
#include "nonlinear/nonlinear_law.h"
#include "compliance/precompute.h"
#include "render/renderer.h"
#include "fem/static_solver.h"

using namespace surgsim::core;
using namespace surgsim::mesh;
using namespace surgsim::fem;
using namespace surgsim::compliance;
using namespace surgsim::nonlinear;
using namespace surgsim::scene;

namespace surgsim {
namespace {

class SurfaceDeformerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    mesh_ = new TetMesh(make_box_mesh(8, 8, 3, {0.2, 0.2, 0.06}, {-0.1, -0.1, -0.06}));
    surface_ = new SurfaceMesh(boundary_surface(*mesh_));
    FixedRegion region;
    region.has_plane = true;
    region.plane_point = {0, 0, -0.059};
    region.plane_normal = {0, 0, -1};
    fixed_ = new FixedSet(fixed_set_from_region(*mesh_, region));
    model_ = new ElasticModel(build_elastic_model(*mesh_, Material{3000.0, 0.45}, *fixed_));
    const std::vector<int> contacts = contactable_nodes(*mesh_, *fixed_);
    tensors_ = new Tensors(precompute_tensors(*model_, contacts, standard_row_sets(*mesh_, contacts), {}));
  }
  static void TearDownTestSuite() {
    delete tensors_;
    delete model_;
    delete fixed_;
    delete surface_;
    delete mesh_;
  }
  // Top-face node closest to (x, y).
  static int top_node(double x, double y) {
    int best = -1;
    double d = 1e9;
    for (int n = 0; n < mesh_->nodes.rows(); ++n) {
      if (mesh_->nodes(n, 2) < -1e-9) continue;
      const double e = std::hypot(mesh_->nodes(n, 0) - x, mesh_->nodes(n, 1) - y);
      if (e < d) d = e, best = n;
    }
    return best;
  }
  static TetMesh* mesh_;
  static SurfaceMesh* surface_;
  static FixedSet* fixed_;
  static ElasticModel* model_;
  static Tensors* tensors_;
};
TetMesh* SurfaceDeformerTest::mesh_ = nullptr;
SurfaceMesh* SurfaceDeformerTest::surface_ = nullptr;
FixedSet* SurfaceDeformerTest::fixed_ = nullptr;
ElasticModel* SurfaceDeformerTest::model_ = nullptr;
Tensors* SurfaceDeformerTest::tensors_ = nullptr;

TEST_F(SurfaceDeformerTest, VisibleShapeEqualsReferenceSolve) {
  // The haptic side's lambda for imposed displacements, then the visual side's deformation from (node, lambda).
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.004, 0.004);
  const std::vector<int> nodes = {top_node(-0.03, 0.02), top_node(0.04, -0.01), top_node(0.0, 0.05)};
  std::vector<Contact> contacts;
  std::vector<ImposedDisplacement> imposed;
  for (int n : nodes) {
    const Eigen::Vector3d d(u(rng), u(rng), -0.005 + u(rng));
    contacts.push_back({n, d});
    imposed.push_back({n, d, 7});
  }
  Superposition haptic(*tensors_, "haptic", 8);
  ContactSolution sol;
  ASSERT_EQ(haptic.solve(contacts.data(), static_cast<int>(contacts.size()), sol), ContactStatus::kOk);

  Tensors visual_only = *tensors_;
  visual_only.blocks.erase(std::remove_if(visual_only.blocks.begin(), visual_only.blocks.end(),
                                          [](const TensorBlock& b) { return b.name != "visual"; }),
                           visual_only.blocks.end());
  SurfaceDeformer deformer(*mesh_, *surface_, &visual_only);
  ASSERT_EQ(deformer.apply(sol.nodes.data(), sol.lambda.data(), sol.count), ContactStatus::kOk);

  StaticSolver reference(*model_, {});
  const StaticSolution ref = reference.solve(imposed);
  double max_err = 0, max_u = 0;
  for (std::size_t v = 0; v < deformer.visible_nodes().size(); ++v) {
    const int n = deformer.visible_nodes()[v];
    const Eigen::Vector3d got = (deformer.positions().row(static_cast<Eigen::Index>(v)).cast<double>() -
                                 mesh_->nodes.row(n)).transpose();
    max_err = std::max(max_err, (got - ref.displacement.row(n).transpose()).norm());
    max_u = std::max(max_u, ref.displacement.row(n).norm());
  }
  // Positions are stored as float for the GPU: agreement to float precision of the coordinates (~1e-8 m here).
  EXPECT_LT(max_err, 2e-8) << "max |u| " << max_u;
  EXPECT_GT(max_u, 0.004);
  EXPECT_NEAR(deformer.max_displacement(), max_u, 1e-6);

  // No contacts: the rest shape again.
  ASSERT_EQ(deformer.apply(nullptr, nullptr, 0), ContactStatus::kOk);
  EXPECT_EQ(deformer.positions(), deformer.rest());
}

TEST_F(SurfaceDeformerTest, BadFrameKeepsTheLastShape) {
  SurfaceDeformer deformer(*mesh_, *surface_, tensors_);
  const int node = top_node(0, 0);
  const Eigen::Vector3d lambda(0, 0, -0.5);
  ASSERT_EQ(deformer.apply(&node, &lambda, 1), ContactStatus::kOk);
  const Eigen::MatrixX3f before = deformer.positions();
  const int interior = 0;  // a fixed bottom node: no column
  EXPECT_NE(deformer.apply(&interior, &lambda, 1), ContactStatus::kOk);
  const Eigen::Vector3d nan(std::nan(""), 0, 0);
  EXPECT_NE(deformer.apply(&node, &nan, 1), ContactStatus::kOk);
  EXPECT_EQ(deformer.positions(), before);
}

// Several instruments: the contacts of all instruments deform the surface together (the linear sum), and
// the non-linear law bends each instrument's share about that instrument's own direction.
TEST_F(SurfaceDeformerTest, EachInstrumentsShareIsBentAboutItsOwnDirection) {
  NonlinearSpec spec;  // the shipped liver's curves (E 3000 Pa, nu 0.45, as this block)
  spec.displacement_curve = std::string(SURGSIM_TEST_CONFIG_DIR) + "/curves/liver_dr.csv";
  spec.force_curve = std::string(SURGSIM_TEST_CONFIG_DIR) + "/curves/liver_force.csv";
  const NonlinearLaw law = load_nonlinear_law(spec);
  ASSERT_FALSE(law.identity());

  // Instrument 0 presses straight down on the left, instrument 1 pushes obliquely on the right.
  const int nodes[2] = {top_node(-0.05, 0.0), top_node(0.05, 0.0)};
  const Eigen::Vector3d lambda[2] = {{0, 0, -1.2}, {0.8, 0, -0.9}};
  const Eigen::Vector3d dirs[2] = {{0, 0, -1}, Eigen::Vector3d(0.6, 0, -0.8)};
  const int instrument[2] = {0, 1};
  // Displacement of every visible vertex (m).
  const auto u = [](const SurfaceDeformer& d) { return Eigen::MatrixX3d((d.positions() - d.rest()).cast<double>()); };

  SurfaceDeformer both(*mesh_, *surface_, tensors_, &law);
  ASSERT_EQ(both.apply(nodes, lambda, instrument, 2, dirs, 2), ContactStatus::kOk);
  SurfaceDeformer first(*mesh_, *surface_, tensors_, &law), second(*mesh_, *surface_, tensors_, &law);
  ASSERT_EQ(first.apply(&nodes[0], &lambda[0], 1, dirs[0]), ContactStatus::kOk);
  ASSERT_EQ(second.apply(&nodes[1], &lambda[1], 1, dirs[1]), ContactStatus::kOk);
  const Eigen::MatrixX3d shares = u(first) + u(second);
  EXPECT_GT(shares.rowwise().norm().maxCoeff(), 0.004);
  // Positions are floats: the sum of the shares up to float rounding of the coordinates.
  EXPECT_LT((u(both) - shares).cwiseAbs().maxCoeff(), 1e-7);

  // One direction for both contacts is another shape: the law really acts per instrument.
  SurfaceDeformer one_axis(*mesh_, *surface_, tensors_, &law);
  ASSERT_EQ(one_axis.apply(nodes, lambda, 2, dirs[0]), ContactStatus::kOk);
  const double per_instrument_effect = (u(one_axis) - u(both)).cwiseAbs().maxCoeff();
  EXPECT_GT(per_instrument_effect, 1e-5);

  // All contacts of one instrument: exactly the single-direction call.
  const int same[2] = {1, 1};
  SurfaceDeformer one_instrument(*mesh_, *surface_, tensors_, &law), reference(*mesh_, *surface_, tensors_, &law);
  ASSERT_EQ(one_instrument.apply(nodes, lambda, same, 2, dirs, 2), ContactStatus::kOk);
  ASSERT_EQ(reference.apply(nodes, lambda, 2, dirs[1]), ContactStatus::kOk);
  EXPECT_EQ(one_instrument.positions(), reference.positions());

  // A contact of an instrument outside the list (or without a direction) is superposed linearly.
  const int outside[2] = {0, 7};
  SurfaceDeformer mixed(*mesh_, *surface_, tensors_, &law), linear_second(*mesh_, *surface_, tensors_);
  ASSERT_EQ(mixed.apply(nodes, lambda, outside, 2, dirs, 2), ContactStatus::kOk);
  ASSERT_EQ(linear_second.apply(&nodes[1], &lambda[1], 1), ContactStatus::kOk);
  EXPECT_LT((u(mixed) - (u(first) + u(linear_second))).cwiseAbs().maxCoeff(), 1e-7);

  // Without a law the instruments change nothing: the linear sum, bit for bit.
  SurfaceDeformer linear_both(*mesh_, *surface_, tensors_), linear(*mesh_, *surface_, tensors_);
  ASSERT_EQ(linear_both.apply(nodes, lambda, instrument, 2, dirs, 2), ContactStatus::kOk);
  ASSERT_EQ(linear.apply(nodes, lambda, 2), ContactStatus::kOk);
  EXPECT_EQ(linear_both.positions(), linear.positions());

  // A bad contact in any instrument's share keeps the last shape.
  const Eigen::MatrixX3f before = both.positions();
  const int bad_nodes[2] = {nodes[0], 0};  // node 0: a fixed bottom node, no column
  EXPECT_NE(both.apply(bad_nodes, lambda, instrument, 2, dirs, 2), ContactStatus::kOk);
  EXPECT_EQ(both.positions(), before);
  std::printf("per-instrument law: largest difference from one axis %.3g m\n", per_instrument_effect);
}

// A contact frame may name nodes this mesh does not have (another scene, a corrupt sample): the marker lookup the
// visual node makes for each contact node says "not visible" instead of reading past the table.
TEST_F(SurfaceDeformerTest, VertexOfANodeOutsideTheMeshIsNone) {
  SurfaceDeformer deformer(*mesh_, *surface_, tensors_);
  const int nodes = static_cast<int>(mesh_->nodes.rows());
  EXPECT_EQ(deformer.vertex_of(-1), -1);
  EXPECT_EQ(deformer.vertex_of(nodes), -1);
  EXPECT_EQ(deformer.vertex_of(1 << 30), -1);
  EXPECT_GE(deformer.vertex_of(top_node(0, 0)), 0);
}

TEST_F(SurfaceDeformerTest, RenderedDentChangesPixelsNearTheContactOnly) {
  SurfaceDeformer deformer(*mesh_, *surface_, tensors_);
  auto renderer = make_renderer("osmesa", 320, 240);
  Camera cam;
  cam.eye = {0.0, -0.25, 0.22};
  cam.target = {0, 0, -0.02};
  cam.up = {0, 0, 1};
  cam.fov_deg = 40;
  auto draw = [&](Image& img) {
    renderer->begin_frame(cam);
    renderer->draw_surface(deformer.positions(), deformer.tris(), kLiverRgb);
    renderer->end_frame();
    ASSERT_TRUE(renderer->read_image(img));
  };
  Image rest, dented;
  draw(rest);
  const int node = top_node(0.0, 0.0);
  const Eigen::Vector3d lambda(0, 0, -1.3);  // pushes the top centre down by about a centimetre
  ASSERT_EQ(deformer.apply(&node, &lambda, 1), ContactStatus::kOk);
  ASSERT_GT(deformer.max_displacement(), 0.008);
  draw(dented);

  const Eigen::Vector2f c = project_to_pixel(cam, 320, 240, mesh_->nodes.row(node).cast<float>().transpose());
  long near_changed = 0, far_changed = 0, far_total = 0;
  for (int y = 0; y < 240; ++y) {
    for (int x = 0; x < 320; ++x) {
      int diff = 0;
      for (int ch = 0; ch < 3; ++ch) {
        diff = std::max(diff, std::abs(int(rest.rgb[3 * (y * 320 + x) + ch]) - int(dented.rgb[3 * (y * 320 + x) + ch])));
      }
      const float r = std::hypot(x + 0.5f - c.x(), y + 0.5f - c.y());
      // With smooth normals on 25 mm cells the dent changes the shading by a few levels over a 2-cell radius.
      if (r < 60 && diff >= 2) ++near_changed;
      if (r > 110) {
        ++far_total;
        if (diff >= 2) ++far_changed;
      }
    }
  }
  EXPECT_GT(near_changed, 500) << "the dent is visible around the contact at " << c.transpose();
  EXPECT_LT(far_changed, far_total / 100) << "far from the contact the image is (almost) unchanged";
}

}  // namespace
}  // namespace surgsim

namespace surgsim {
namespace {

// A finer visual surface (the boundary of a finer box) embedded in the coarse mechanical boundary.
TEST_F(SurfaceDeformerTest, EmbeddedFineSurfaceFollowsTheBoundary) {
  const TetMesh fine_mesh = make_box_mesh(16, 16, 6, {0.2, 0.2, 0.06}, {-0.1, -0.1, -0.06});
  const SurfaceMesh fine_boundary = boundary_surface(fine_mesh);
  // Write it as OBJ and read it back (the path the scene key takes).
  const std::string obj = ::testing::TempDir() + "/fine_box.obj";
  {
    std::FILE* f = std::fopen(obj.c_str(), "w");
    ASSERT_NE(f, nullptr);
    for (int n = 0; n < fine_mesh.nodes.rows(); ++n) {
      std::fprintf(f, "v %.17g %.17g %.17g\n", fine_mesh.nodes(n, 0), fine_mesh.nodes(n, 1), fine_mesh.nodes(n, 2));
    }
    for (int t = 0; t < fine_boundary.tris.rows(); ++t) {
      std::fprintf(f, "f %d %d %d\n", fine_boundary.tris(t, 0) + 1, fine_boundary.tris(t, 1) + 1,
                   fine_boundary.tris(t, 2) + 1);
    }
    std::fclose(f);
  }
  const TriSurface fine = read_obj(obj);
  SurfaceDeformer deformer(*mesh_, *surface_, tensors_);
  deformer.embed(fine, *mesh_, *surface_, 0.001);
  ASSERT_TRUE(deformer.embedded());
  EXPECT_EQ(deformer.drawn_tris().rows(), fine.tris.rows());
  // At rest the fine vertices are where they were (they lie on the coarse faces).
  double rest_err = 0;
  for (int v : fine_boundary.nodes) {
    rest_err = std::max(rest_err, (deformer.drawn_positions().row(v).cast<double>() - fine.vertices.row(v)).norm());
  }
  EXPECT_LT(rest_err, 1e-7);

  // Deformed: fine vertices that sit on coarse nodes move exactly with them.
  const int node = top_node(0.0, 0.0);
  const Eigen::Vector3d lambda(0, 0, -1.0);
  ASSERT_EQ(deformer.apply(&node, &lambda, 1), ContactStatus::kOk);
  const int v_coarse = deformer.vertex_of(node);
  int v_fine = -1;
  for (int v = 0; v < fine.vertices.rows(); ++v) {
    if ((fine.vertices.row(v) - mesh_->nodes.row(node)).norm() < 1e-12) v_fine = v;
  }
  ASSERT_GE(v_fine, 0);
  EXPECT_LT((deformer.drawn_positions().row(v_fine) - deformer.positions().row(v_coarse)).norm(), 1e-6);
  EXPECT_GT((deformer.drawn_positions().row(v_fine).cast<double>() - fine.vertices.row(v_fine)).norm(), 0.005);
}

TEST_F(SurfaceDeformerTest, SurfaceFarFromTheOrganIsRefused) {
  TriSurface far;
  far.source = "far.obj";
  far.vertices.resize(3, 3);
  far.vertices << 0, 0, 0.5, 0.01, 0, 0.5, 0, 0.01, 0.5;  // 50 cm above the block
  far.tris.resize(1, 3);
  far.tris << 0, 1, 2;
  SurfaceDeformer deformer(*mesh_, *surface_, tensors_);
  try {
    deformer.embed(far, *mesh_, *surface_, 0.002);
    FAIL() << "a surface off the organ was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("far.obj: vertex 1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace surgsim
