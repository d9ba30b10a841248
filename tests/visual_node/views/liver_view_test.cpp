// LiverView with liver.deformation multirate, without DDS or GL: the tracker's shape given as a BodyState
// (a known displacement field on the boundary nodes, SurfaceMesh order) is what is drawn, on the boundary and on an
// embedded finer surface; states of another scene, with another point count or with a NaN are ignored and counted by
// reason (one stderr line each); before the first state the linear deformer draws the contact frame. On the shipped
// plate (mesh and tensors from the test cache). The same states over real Fast DDS to the real visual node:
// tests/integration/visual_multirate_test.cpp.
#include "views/liver_view.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#include "core/clock.h"
#include "render/renderer.h"
#include "support/alloc_counter.h"
#include "support/contact_frame_util.h"
#include "surgsim_types.h"

using namespace surgsim::core;
using namespace surgsim::compliance;
using namespace surgsim::scene;

namespace surgsim {
namespace {

Scene plate(LiverDeformation deformation) {
  Scene scene = load_scene(std::string(SURGSIM_TEST_CONFIG_DIR) + "/plate.yaml");
  scene.liver.deformation = deformation;
  return scene;
}

OrganViewOptions test_options() {
  OrganViewOptions o;
  o.cache_dir = SURGSIM_TEST_CACHE_DIR;
  return o;
}

// A smooth displacement field of a few mm (m) at a rest point: bending, shear and a twist, so that no node is left
// where the linear deformer or the rest shape would put it.
Eigen::Vector3d field(const Eigen::Vector3d& x) {
  return {0.02 * x.y() + 0.5 * x.x() * x.y(), -0.03 * x.x(), 0.004 - 0.3 * (x.x() * x.x() + x.y() * x.y())};
}

// The BodyState positions of that field: rest + u for every boundary node, in the deformer's (SurfaceMesh) order.
std::vector<double> body_positions(const LiverView& view) {
  const Eigen::MatrixX3f& rest = view.deformer().rest();
  std::vector<double> xyz(3 * static_cast<std::size_t>(rest.rows()));
  for (Eigen::Index v = 0; v < rest.rows(); ++v) {
    const Eigen::Vector3d x = rest.row(v).transpose().cast<double>();
    const Eigen::Vector3d p = x + field(x);
    for (int k = 0; k < 3; ++k) xyz[3 * static_cast<std::size_t>(v) + static_cast<std::size_t>(k)] = p[k];
  }
  return xyz;
}

// Largest distance between the drawn boundary and the body state's positions (m).
double drawn_error(const LiverView& view, const std::vector<double>& xyz) {
  double err = 0;
  const Eigen::MatrixX3f& p = view.deformer().positions();
  for (Eigen::Index v = 0; v < p.rows(); ++v) {
    const Eigen::Vector3d want(xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]);
    err = std::max(err, (p.row(v).transpose().cast<double>() - want).norm());
  }
  return err;
}

nlohmann::json multirate_stats(const LiverView& view) {
  nlohmann::json j;
  view.add_stats(j);
  return j["multirate"];
}

TEST(LiverViewMultirate, DrawsTheBodyStatesShapeOnTheBoundary) {
  const Scene scene = plate(LiverDeformation::kMultirate);
  LiverView view(scene, test_options());
  ASSERT_TRUE(view.multirate());
  EXPECT_EQ(view.scene_hash(), visual_scene_hash(scene, view.mesh_hash()));
  const std::vector<double> xyz = body_positions(view);
  const int count = static_cast<int>(xyz.size() / 3);

  ASSERT_TRUE(view.take_body_state(xyz.data(), count, view.scene_hash(), monotonic_ns(), 7));
  EXPECT_TRUE(view.body_shown());
  view.update(nullptr, false);
  // Every boundary node where the state puts it (float rounding of the drawn vertices).
  EXPECT_LT(drawn_error(view, xyz), 1e-8);
  EXPECT_FALSE(view.deformer().embedded());
  EXPECT_EQ(&view.deformer().drawn_positions(), &view.deformer().positions());
  double max_u = 0;
  for (Eigen::Index v = 0; v < view.deformer().rest().rows(); ++v)
    max_u = std::max(max_u, field(view.deformer().rest().row(v).transpose().cast<double>()).norm());
  EXPECT_NEAR(view.max_displacement(), max_u, 1e-6);

  // A contact frame whose contact node is imposed where the state has it (u_tilde, multirate) leaves the state as it is
  // and places its marker on it.
  const int vertex = static_cast<int>(view.deformer().visible_nodes().size() / 2);
  const int node = view.deformer().visible_nodes()[static_cast<std::size_t>(vertex)];
  const Eigen::Vector3d rest_v = view.deformer().rest().row(vertex).transpose().cast<double>();
  msg::ContactFrame frame = testing::press_frame(node, -0.2);
  const Eigen::Vector3d in_state = field(rest_v);
  frame.contacts()[0].u_tilde().x(in_state.x());
  frame.contacts()[0].u_tilde().y(in_state.y());
  frame.contacts()[0].u_tilde().z(in_state.z());
  view.update(&frame, true);
  EXPECT_LT(drawn_error(view, xyz), 1e-8) << "the linear deformer ran over the tracker's shape";
  EXPECT_EQ(view.contacts_shown(), 1);
  auto renderer = make_renderer("null", 64, 48);
  renderer->begin_frame(scene.visual.camera);
  view.draw(*renderer);
  view.draw_markers(*renderer);
  renderer->end_frame();
  EXPECT_EQ(renderer->counts().surfaces, 1u);
  EXPECT_EQ(renderer->counts().points, 1u);
  EXPECT_EQ(renderer->counts().rejected, 0u);

  const nlohmann::json m = multirate_stats(view);
  EXPECT_EQ(m["body_states_shown"].get<int>(), 1);
  EXPECT_EQ(m["body_states_rejected"]["total"].get<int>(), 0);
  EXPECT_EQ(m["last_seq_shown"].get<int>(), 7);
  EXPECT_EQ(m["surface_nodes"].get<int>(), count);
  EXPECT_EQ(m["frames_body_state"].get<int>(), 2);
  EXPECT_EQ(m["carry_failures"].get<int>(), 0);
  EXPECT_EQ(m["frames_linear_fallback"].get<int>(), 0);
  EXPECT_EQ(m["shape_age_ms"]["count"].get<int>(), 2);
  EXPECT_EQ(m["shape_age_first_draw_ms"]["count"].get<int>(), 1);  // one state, drawn in two frames
  EXPECT_GE(m["shape_age_ms"]["p50"].get<double>(), 0.0);
  std::ostringstream summary;
  nlohmann::json j;
  view.add_stats(j);
  view.print_summary(summary, j);
  EXPECT_NE(summary.str().find("visual_node: multirate liver: 1 body states shown of 0 received (ignored: 0 other "
                               "scene, 0 wrong count, 0 non-finite)"),
            std::string::npos)
      << summary.str();
}

// The tracker publishes a few states a second; every frame carries the last one to its contacts: a contact node
// imposed 3 mm below its place in the state is drawn exactly there (u_tilde), the shape around it follows, the far
// side of the organ barely moves, and the next frame with the node back where the state has it draws the state again.
TEST(LiverViewMultirate, EachFrameCarriesTheLastStateToItsContacts) {
  const Scene scene = plate(LiverDeformation::kMultirate);
  LiverView view(scene, test_options());
  const std::vector<double> xyz = body_positions(view);
  const int count = static_cast<int>(xyz.size() / 3);
  ASSERT_TRUE(view.take_body_state(xyz.data(), count, view.scene_hash(), monotonic_ns(), 1));
  const SurfaceDeformer& d = view.deformer();
  const int vertex = static_cast<int>(d.visible_nodes().size() / 2);
  const int node = d.visible_nodes()[static_cast<std::size_t>(vertex)];
  const Eigen::Vector3d rest_v = d.rest().row(vertex).transpose().cast<double>();
  const Eigen::Vector3d shift(0, 0, -0.003);
  const Eigen::Vector3d imposed = field(rest_v) + shift;
  msg::ContactFrame frame = testing::press_frame(node, -0.2);
  frame.contacts()[0].u_tilde().x(imposed.x());
  frame.contacts()[0].u_tilde().y(imposed.y());
  frame.contacts()[0].u_tilde().z(imposed.z());
  view.update(&frame, true);

  EXPECT_LT((d.positions().row(vertex).transpose().cast<double>() - (rest_v + imposed)).norm(), 1e-7)
      << "the contact node is not where the tool holds it";
  // Every other node moved by the linear response to that 3 mm: about 3 mm at most (a neighbour of a point
  // constraint may move a little more than the node itself), some of them visibly, the furthest node least.
  double largest = 0, furthest = -1, furthest_move = 0;
  for (Eigen::Index v = 0; v < d.positions().rows(); ++v) {
    if (v == vertex) continue;
    const Eigen::Vector3d want(xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]);
    const double move = (d.positions().row(v).transpose().cast<double>() - want).norm();
    largest = std::max(largest, move);
    const double dist = (d.rest().row(v).transpose().cast<double>() - rest_v).norm();
    if (dist > furthest) {
      furthest = dist;
      furthest_move = move;
    }
  }
  EXPECT_LT(largest, 1.5 * shift.norm());
  EXPECT_GT(largest, 0.3 * shift.norm()) << "the shape around the contact did not follow it";
  EXPECT_LT(furthest_move, 0.2 * largest);
  EXPECT_EQ(multirate_stats(view)["carry_failures"].get<int>(), 0);

  // Back where the state has it: the state itself.
  frame.contacts()[0].u_tilde().z(field(rest_v).z());
  view.update(&frame, true);
  EXPECT_LT(drawn_error(view, xyz), 1e-8);
  // No contact: the state itself.
  const msg::ContactFrame none;
  view.update(&none, true);
  EXPECT_LT(drawn_error(view, xyz), 1e-8);
}

// Until the first body state the multirate liver is drawn by the linear deformer from the contact frame, exactly as a
// linear liver is; the first state replaces that shape.
TEST(LiverViewMultirate, LinearDeformerDrawsTheContactFrameUntilTheFirstBodyState) {
  LiverView multirate(plate(LiverDeformation::kMultirate), test_options());
  LiverView linear(plate(LiverDeformation::kLinear), test_options());
  const int node = multirate.deformer().visible_nodes()[multirate.deformer().visible_nodes().size() / 2];
  const msg::ContactFrame frame = testing::press_frame(node, -0.2);
  EXPECT_GE(multirate.update(&frame, true), 0.0);
  EXPECT_GE(linear.update(&frame, true), 0.0);
  EXPECT_FALSE(multirate.body_shown());
  EXPECT_GT(multirate.max_displacement(), 1e-4);
  EXPECT_EQ(multirate.deformer().positions(), linear.deformer().positions());
  EXPECT_EQ(multirate_stats(multirate)["frames_linear_fallback"].get<int>(), 1);
  EXPECT_FALSE(nlohmann::json(linear.multirate()).get<bool>());

  const std::vector<double> xyz = body_positions(multirate);
  ASSERT_TRUE(multirate.take_body_state(xyz.data(), static_cast<int>(xyz.size() / 3), multirate.scene_hash(),
                                        monotonic_ns(), 1));
  multirate.update(nullptr, false);  // no contact to carry it to (EachFrameCarriesTheLastStateToItsContacts)
  EXPECT_LT(drawn_error(multirate, xyz), 1e-8);
}

// Another scene's hash, another point count, a NaN: each ignored (the shape drawn stays), counted by reason, and
// named once on stderr with what was expected.
TEST(LiverViewMultirate, IgnoresAndCountsStatesOfAnotherSceneCountOrWithANaN) {
  LiverView view(plate(LiverDeformation::kMultirate), test_options());
  std::vector<double> xyz = body_positions(view);
  const int count = static_cast<int>(xyz.size() / 3);
  ASSERT_TRUE(view.take_body_state(xyz.data(), count, view.scene_hash(), monotonic_ns(), 1));
  std::vector<double> other = xyz;
  for (double& c : other) c += 0.01;

  ::testing::internal::CaptureStderr();
  for (int k = 0; k < 2; ++k) {
    EXPECT_FALSE(view.take_body_state(other.data(), count, view.scene_hash() ^ 1u, monotonic_ns(), 2));
    EXPECT_FALSE(view.take_body_state(other.data(), count - 1, view.scene_hash(), monotonic_ns(), 3));
  }
  other[3 * (count / 2) + 1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(view.take_body_state(other.data(), count, view.scene_hash(), monotonic_ns(), 4));
  other[3 * (count / 2) + 1] = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(view.take_body_state(other.data(), count, view.scene_hash(), monotonic_ns(), 5));
  const std::string err = ::testing::internal::GetCapturedStderr();
  view.update(nullptr, false);
  EXPECT_LT(drawn_error(view, xyz), 1e-8) << "an ignored state changed the shape";

  EXPECT_EQ(view.body_states_rejected(LiverView::BodyRejection::kWrongScene), 2u);
  EXPECT_EQ(view.body_states_rejected(LiverView::BodyRejection::kWrongCount), 2u);
  EXPECT_EQ(view.body_states_rejected(LiverView::BodyRejection::kNonFinite), 2u);
  EXPECT_EQ(view.body_states_shown(), 1u);
  const nlohmann::json m = multirate_stats(view);
  EXPECT_EQ(m["body_states_rejected"]["total"].get<int>(), 6);
  EXPECT_EQ(m["body_states_rejected"]["wrong_scene"].get<int>(), 2);
  EXPECT_EQ(m["body_states_rejected"]["wrong_count"].get<int>(), 2);
  EXPECT_EQ(m["body_states_rejected"]["non_finite"].get<int>(), 2);

  // One line per reason, naming what was expected.
  const auto line = [&](const std::string& start) {
    const auto at = err.find(start);
    EXPECT_NE(at, std::string::npos) << err;
    EXPECT_EQ(err.find(start, at + 1), std::string::npos) << "said once\n" << err;
    return at == std::string::npos ? std::string() : err.substr(at, err.find('\n', at) - at);
  };
  EXPECT_NE(line("visual_node: body state 2 ignored: scene hash").find(std::to_string(view.scene_hash())),
            std::string::npos);
  EXPECT_NE(line("visual_node: body state 3 ignored: " + std::to_string(count - 1) + " positions")
                .find("has " + std::to_string(count) + " boundary surface nodes"),
            std::string::npos);
  EXPECT_NE(line("visual_node: body state 4 ignored: a position is not finite").find("plate.yaml"),
            std::string::npos);
}

// visual.surface: a finer surface embedded in the boundary (here the boundary with each triangle split at its
// centroid) follows the body state: a vertex on a node is that node's position, a centroid the mean of its three.
TEST(LiverViewMultirate, EmbeddedFinerSurfaceFollowsTheBodyState) {
  Scene scene = plate(LiverDeformation::kMultirate);
  const std::string obj =
      (std::filesystem::temp_directory_path() / ("surgsim_liver_view_fine_" + std::to_string(::getpid()) + ".obj"))
          .string();
  int nodes = 0, faces = 0;
  {
    // The boundary as the view sees it (rest, SurfaceMesh order), from a plain linear view of the same scene.
    const LiverView coarse(plate(LiverDeformation::kLinear), test_options());
    const Eigen::MatrixX3f& rest = coarse.deformer().rest();
    const Eigen::MatrixX3i& tris = coarse.deformer().tris();
    nodes = static_cast<int>(rest.rows());
    faces = static_cast<int>(tris.rows());
    std::FILE* f = std::fopen(obj.c_str(), "w");
    ASSERT_NE(f, nullptr);
    for (int v = 0; v < nodes; ++v) std::fprintf(f, "v %.9g %.9g %.9g\n", rest(v, 0), rest(v, 1), rest(v, 2));
    for (int t = 0; t < faces; ++t) {
      const Eigen::Vector3f c = (rest.row(tris(t, 0)) + rest.row(tris(t, 1)) + rest.row(tris(t, 2))) / 3.0f;
      std::fprintf(f, "v %.9g %.9g %.9g\n", c.x(), c.y(), c.z());
    }
    for (int t = 0; t < faces; ++t) {
      const int c = nodes + t + 1, a = tris(t, 0) + 1, b = tris(t, 1) + 1, d = tris(t, 2) + 1;
      std::fprintf(f, "f %d %d %d\nf %d %d %d\nf %d %d %d\n", a, b, c, b, d, c, d, a, c);
    }
    std::fclose(f);
  }
  scene.visual.surface = obj;
  LiverView view(scene, test_options());
  std::filesystem::remove(obj);
  ASSERT_TRUE(view.deformer().embedded());
  ASSERT_EQ(view.deformer().drawn_positions().rows(), nodes + faces);

  const std::vector<double> xyz = body_positions(view);
  ASSERT_TRUE(view.take_body_state(xyz.data(), nodes, view.scene_hash(), monotonic_ns(), 1));
  view.update(nullptr, false);
  const Eigen::MatrixX3f& fine = view.deformer().drawn_positions();
  const auto body = [&](int v) { return Eigen::Vector3d(xyz[3 * v], xyz[3 * v + 1], xyz[3 * v + 2]); };
  double node_err = 0, centroid_err = 0, moved = 0;
  for (int v = 0; v < nodes; ++v) node_err = std::max(node_err, (fine.row(v).transpose().cast<double>() - body(v)).norm());
  const Eigen::MatrixX3i& tris = view.deformer().tris();
  for (int t = 0; t < faces; ++t) {
    const Eigen::Vector3d want = (body(tris(t, 0)) + body(tris(t, 1)) + body(tris(t, 2))) / 3.0;
    const Eigen::Vector3d got = fine.row(nodes + t).transpose().cast<double>();
    centroid_err = std::max(centroid_err, (got - want).norm());
    moved = std::max(moved, (got - view.deformer().rest().row(tris(t, 0)).transpose().cast<double>()).norm());
  }
  std::printf("embedded: %d nodes, %d centroids: error %.3g m (nodes), %.3g m (centroids)\n", nodes, faces, node_err,
              centroid_err);
  EXPECT_LT(node_err, 1e-6);
  EXPECT_LT(centroid_err, 1e-6);  // within the embedding's float offset along the normal
  EXPECT_GT(moved, 1e-3);
}

// Taking a state and drawing frames with it allocates nothing.
TEST(LiverViewMultirate, TakesABodyStateWithoutAllocating) {
  LiverView view(plate(LiverDeformation::kMultirate), test_options());
  std::vector<double> xyz = body_positions(view);
  const int count = static_cast<int>(xyz.size() / 3);
  const int node = view.deformer().visible_nodes()[0];
  const msg::ContactFrame frame = testing::press_frame(node, -0.2);
  ASSERT_TRUE(view.take_body_state(xyz.data(), count, view.scene_hash(), monotonic_ns(), 1));
  view.update(&frame, true);
  ::testing::internal::CaptureStderr();
  view.take_body_state(xyz.data(), count, view.scene_hash() ^ 1u, monotonic_ns(), 2);  // the one-time line first
  ::testing::internal::GetCapturedStderr();
  long allocations = 0;
  {
    test::AllocationCounter counter;
    for (int k = 0; k < 20; ++k) {
      xyz[0] += 1e-4;
      view.take_body_state(xyz.data(), count, view.scene_hash(), monotonic_ns(), 3 + static_cast<std::uint64_t>(k));
      view.take_body_state(xyz.data(), count, view.scene_hash() ^ 1u, monotonic_ns(), 100);
      view.update(&frame, k % 2 == 0);
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0);
  EXPECT_EQ(view.body_states_shown(), 21u);
}

}  // namespace
}  // namespace surgsim
