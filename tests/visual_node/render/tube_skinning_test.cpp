// GPU two-matrix skinning of the intestine tube (OsMesaRenderer::draw_skinned_tube, docs/DESIGN.md, section 'Intestine
// rendering') against the CPU skinning of TubeBuilder: the transformed vertices read back by transform feedback, and
// the pictures of both paths.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "intestine/intestine_model.h"
#include "render/renderer.h"
#include "intestine/tube_geometry.h"

using namespace surgsim::intestine;
using namespace surgsim::scene;

namespace surgsim {
namespace {

using intestine::TubeBuilder;
using intestine::TubeMesh;
using intestine::TubePrimitive;

constexpr int kWidth = 320;
constexpr int kHeight = 240;
const Eigen::Vector3f kPink(0.86f, 0.46f, 0.42f);  // the visual node's bowel colour

Scene shipped_intestine() { return load_scene(std::string(SURGSIM_TEST_CONFIG_DIR) + "/intestine.yaml"); }

// The folded curve: the intestine's rest shape (its crests bend tighter than the tube, so the ring guard tilts and
// narrows rings there), the points of row 0 of the grid.
std::vector<double> folded_curve(const Scene& scene) {
  const intestine::IntestineModel model(scene.intestine.params);
  return std::vector<double>(model.rest().data(), model.rest().data() + 3 * model.columns());
}

// The CPU mesh as the renderer's surface input.
void as_surface(const TubeMesh& mesh, Eigen::MatrixX3f& positions, Eigen::MatrixX3i& tris) {
  positions.resize(mesh.vertex_count, 3);
  for (int v = 0; v < mesh.vertex_count; ++v) {
    for (int c = 0; c < 3; ++c) positions(v, c) = mesh.positions[static_cast<std::size_t>(3 * v + c)];
  }
  tris.resize(mesh.index_count / 3, 3);
  for (int t = 0; t < mesh.index_count / 3; ++t) {
    for (int c = 0; c < 3; ++c) tris(t, c) = static_cast<int>(mesh.indices[static_cast<std::size_t>(3 * t + c)]);
  }
}

bool is_background(const Image& image, int x, int y) {
  const std::uint8_t* p = image.at(x, y);
  return p[0] == kBackgroundRgb[0] && p[1] == kBackgroundRgb[1] && p[2] == kBackgroundRgb[2];
}

class TubeSkinningTest : public ::testing::Test {
 protected:
  void SetUp() override {
    scene_ = shipped_intestine();
    points_ = folded_curve(scene_);
    renderer_ = make_renderer("osmesa", kWidth, kHeight);
    ASSERT_TRUE(renderer_->gpu_skinning()) << renderer_->info();
  }
  int columns() const { return static_cast<int>(points_.size() / 3); }
  intestine::TubeParams params() const {
    intestine::TubeParams p;
    p.radius = scene_.intestine.params.intestine_radius;
    return p;
  }
  Scene scene_;
  std::vector<double> points_;
  std::unique_ptr<Renderer> renderer_;
};

// Transform feedback reads back what the vertex shader computed: every vertex of every interval (caps included)
// matches the CPU skinning to float precision (1e-5 of the tube's size), with the same normals.
TEST_F(TubeSkinningTest, ShaderVerticesMatchTheCpuSkinning) {
  TubeBuilder builder(params(), columns());
  TubeMesh mesh = builder.make_mesh(intestine::kTubeMaxLod);
  for (int lod = 0; lod <= intestine::kTubeMaxLod; ++lod) {
    builder.reset_frames();
    ASSERT_TRUE(builder.build(points_.data(), columns(), lod, mesh, intestine::TubeSkinning::kCpu));
    const TubePrimitive& prim = builder.primitive(lod);
    std::vector<float> gpu_positions, gpu_normals;
    ASSERT_TRUE(renderer_->capture_skinned_tube(prim, mesh.skin.data(), mesh.intervals, gpu_positions, gpu_normals));
    const int per_instance = prim.body_vertex_count + 2 * prim.cap_vertex_count;
    ASSERT_EQ(gpu_positions.size(), static_cast<std::size_t>(3 * per_instance * mesh.intervals));

    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
    for (int v = 0; v < mesh.vertex_count; ++v) {
      const Eigen::Vector3d p(mesh.positions[3 * v], mesh.positions[3 * v + 1], mesh.positions[3 * v + 2]);
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const double size = (hi - lo).norm();
    const int sides = prim.lod.sides, q = prim.lod.rings;
    double worst_position = 0, worst_normal = 0;
    int compared = 0;
    for (int k = 0; k < mesh.intervals; ++k) {
      for (int i = 0; i < per_instance; ++i) {
        // Where the CPU mesh has this vertex: rings are shared between intervals, caps belong to the end intervals.
        int target = -1;
        if (i < prim.body_vertex_count) {
          const int j = i / sides;
          if (j < q || k + 1 == mesh.intervals) target = (k * q + j) * sides + i % sides;
        } else if (i < prim.body_vertex_count + prim.cap_vertex_count) {
          if (k == 0) target = mesh.body_vertex_count + (i - prim.body_vertex_count);
        } else if (k + 1 == mesh.intervals) {
          target = mesh.body_vertex_count + (i - prim.body_vertex_count);
        }
        if (target < 0) continue;
        const auto g = static_cast<std::size_t>(3 * (k * per_instance + i)), c = static_cast<std::size_t>(3 * target);
        const Eigen::Vector3d gp(gpu_positions[g], gpu_positions[g + 1], gpu_positions[g + 2]);
        const Eigen::Vector3d cp(mesh.positions[c], mesh.positions[c + 1], mesh.positions[c + 2]);
        const Eigen::Vector3d gn(gpu_normals[g], gpu_normals[g + 1], gpu_normals[g + 2]);
        const Eigen::Vector3d cn(mesh.normals[c], mesh.normals[c + 1], mesh.normals[c + 2]);
        ASSERT_TRUE(gp.allFinite() && gn.allFinite()) << "lod " << lod << " interval " << k << " vertex " << i;
        worst_position = std::max(worst_position, (gp - cp).norm());
        worst_normal = std::max(worst_normal, (gn - cn).norm());
        ++compared;
      }
    }
    EXPECT_EQ(compared, mesh.vertex_count) << "every CPU vertex has its shader counterpart";
    EXPECT_LT(worst_position, 1e-5 * size) << "lod " << lod << " (tube size " << size << " m)";
    EXPECT_LT(worst_normal, 1e-4) << "lod " << lod;
    char figure[32];
    std::snprintf(figure, sizeof figure, "%.3g", worst_position);
    RecordProperty("worst_position_m_lod" + std::to_string(lod), figure);
  }
}

// The same folded tube drawn by both paths: the same pixels are covered (IoU of the masks > 0.98) and the colours
// agree (the CPU path's normals are recomputed from the triangles by draw_surface, the shader's are the analytic
// skinned ones: small shading differences only).
TEST_F(TubeSkinningTest, GpuAndCpuPathsDrawTheSamePicture) {
  TubeBuilder builder(params(), columns());
  TubeMesh mesh = builder.make_mesh(intestine::kTubeMaxLod);
  Eigen::MatrixX3f positions;
  Eigen::MatrixX3i tris;
  Image cpu, gpu;
  for (int lod : {0, 3, intestine::kTubeMaxLod}) {
    builder.reset_frames();
    ASSERT_TRUE(builder.build(points_.data(), columns(), lod, mesh, intestine::TubeSkinning::kCpu));
    as_surface(mesh, positions, tris);
    renderer_->begin_frame(scene_.visual.camera);
    renderer_->draw_surface(positions, tris, kPink);
    renderer_->end_frame();
    ASSERT_TRUE(renderer_->read_image(cpu));
    renderer_->begin_frame(scene_.visual.camera);
    renderer_->draw_skinned_tube(builder.primitive(lod), mesh.skin.data(), mesh.intervals, kPink);
    renderer_->end_frame();
    ASSERT_TRUE(renderer_->read_image(gpu));
    EXPECT_EQ(renderer_->counts().rejected, 0u);
    EXPECT_EQ(renderer_->counts().gl_errors, 0u);

    long both = 0, either = 0;
    double colour = 0;
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        const bool c = !is_background(cpu, x, y), g = !is_background(gpu, x, y);
        either += c || g;
        both += c && g;
        if (c && g) {
          for (int k = 0; k < 3; ++k) colour += std::abs(int(cpu.at(x, y)[k]) - int(gpu.at(x, y)[k]));
        }
      }
    }
    ASSERT_GT(both, kWidth * kHeight / 50) << "lod " << lod << ": the tube is in the picture";
    const double iou = static_cast<double>(both) / static_cast<double>(either);
    const double mean = colour / (3.0 * static_cast<double>(both));
    EXPECT_GT(iou, 0.98) << "lod " << lod;
    EXPECT_LT(mean, 6.0) << "lod " << lod << ": mean colour difference (0..255) over the tube";
    RecordProperty("iou_lod" + std::to_string(lod), std::to_string(iou));
    RecordProperty("mean_colour_difference_lod" + std::to_string(lod), std::to_string(mean));
  }
}

// The caps are drawn by the shader path too: a straight tube seen along its axis from beyond its end shows a filled
// disc (the cap), not a ring with the background through the open end.
TEST_F(TubeSkinningTest, CapsCloseTheEndsInTheShaderPath) {
  std::vector<double> straight;
  for (int i = 0; i < 5; ++i) straight.insert(straight.end(), {0.05 * i, 0.0, 0.0});
  TubeBuilder builder(params(), 5);
  TubeMesh mesh = builder.make_mesh(intestine::kTubeMaxLod);
  ASSERT_TRUE(builder.build(straight.data(), 5, 4, mesh, intestine::TubeSkinning::kGpu));
  Camera along;
  along.eye = {0.6, 0, 0};
  along.target = {0, 0, 0};
  along.up = {0, 0, 1};
  along.fov_deg = 30;
  Image image;
  renderer_->begin_frame(along);
  renderer_->draw_skinned_tube(builder.primitive(4), mesh.skin.data(), mesh.intervals, kPink);
  renderer_->end_frame();
  ASSERT_TRUE(renderer_->read_image(image));
  // The axis projects to the image centre: covered, and so is everything within half the tube's radius of it.
  const Eigen::Vector2f centre = project_to_pixel(along, kWidth, kHeight, Eigen::Vector3f(0.2f, 0, 0));
  const Eigen::Vector2f rim =
      project_to_pixel(along, kWidth, kHeight, Eigen::Vector3f(0.2f, 0, 0.5f * static_cast<float>(params().radius)));
  const int reach = static_cast<int>(std::abs(rim.y() - centre.y()));
  ASSERT_GT(reach, 3);
  for (int dy = -reach; dy <= reach; ++dy) {
    for (int dx = -reach; dx <= reach; ++dx) {
      if (dx * dx + dy * dy > reach * reach) continue;
      ASSERT_FALSE(is_background(image, static_cast<int>(centre.x()) + dx, static_cast<int>(centre.y()) + dy))
          << "a hole in the cap at " << dx << "," << dy;
    }
  }
}

TEST_F(TubeSkinningTest, BadInputIsRejectedNotDrawn) {
  TubeBuilder builder(params(), columns());
  TubeMesh mesh = builder.make_mesh(2);
  ASSERT_TRUE(builder.build(points_.data(), columns(), 2, mesh, intestine::TubeSkinning::kGpu));
  renderer_->begin_frame(scene_.visual.camera);
  renderer_->draw_skinned_tube(builder.primitive(2), mesh.skin.data(), 0, kPink);
  std::vector<float> skin(mesh.skin.begin(), mesh.skin.begin() + 24 * mesh.intervals);
  skin[30] = std::numeric_limits<float>::quiet_NaN();
  renderer_->draw_skinned_tube(builder.primitive(2), skin.data(), mesh.intervals, kPink);
  intestine::TubePrimitive odd = builder.primitive(2);
  odd.vertices.pop_back();
  renderer_->draw_skinned_tube(odd, mesh.skin.data(), mesh.intervals, kPink);
  renderer_->end_frame();
  EXPECT_EQ(renderer_->counts().rejected, 3u);
  EXPECT_EQ(renderer_->counts().surfaces, 0u);
  EXPECT_EQ(renderer_->counts().gl_errors, 0u);
}

}  // namespace
}  // namespace surgsim
