#include "render/renderer.h"

#include <Eigen/Geometry>
#include <cmath>

#include "core/error.h"
#include "render/osmesa_renderer.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::scene;

namespace surgsim {
namespace {

constexpr float kPi = 3.14159265358979323846f;

/// Does nothing but count, with the same rules for rejected input as the OSMesa backend.
class NullRenderer final : public Renderer {
 public:
  NullRenderer(int width, int height) : Renderer(width, height) {}

  using Renderer::draw_skinned_tube;
  using Renderer::draw_surface;

  void begin_frame(const Camera&) override {}
  void draw_surface(const Eigen::Ref<const Eigen::MatrixX3f>& positions, const Eigen::Ref<const Eigen::MatrixX3i>& tris,
                    const SurfaceLook&, const Eigen::MatrixX3f* tint) override {
    const bool ok = positions.allFinite() &&
                    (tint == nullptr || (tint->rows() == positions.rows() && tint->allFinite())) &&
                    (tris.size() == 0 || (tris.minCoeff() >= 0 && tris.maxCoeff() < positions.rows()));
    ++(ok ? counts_.surfaces : counts_.rejected);
  }
  void draw_membrane(const intestine::MesenterySurface& surface, const MembraneLook& look) override {
    ++(membrane_drawable(surface, look) ? counts_.surfaces : counts_.rejected);
  }
  void draw_backdrop(const Eigen::Vector3f&, const Eigen::Vector3f&) override {}
  void draw_tool(const ToolGeometry& tool, float radius, const Eigen::Vector3f& rgb) override {
    const bool ok = tool.trocar.allFinite() && tool.tip.allFinite() && tool.jaw_tips[0].allFinite() &&
                    tool.jaw_tips[1].allFinite() && std::isfinite(radius) && rgb.allFinite();
    ++(ok ? counts_.tools : counts_.rejected);
  }
  void draw_points(const Eigen::Ref<const Eigen::MatrixX3f>& points, float radius, const Eigen::Vector3f&) override {
    if (points.allFinite() && std::isfinite(radius)) {
      counts_.points += static_cast<std::uint64_t>(points.rows());
    } else {
      ++counts_.rejected;
    }
  }
  void draw_skinned_tube(const intestine::TubePrimitive&, const float* skin, int intervals,
                         const SurfaceLook&) override {
    bool ok = skin != nullptr && intervals >= 1;
    for (int i = 0; ok && i < 24 * intervals; ++i) ok = std::isfinite(skin[i]);
    ++(ok ? counts_.surfaces : counts_.rejected);
  }
  bool gpu_skinning() const override { return true; }  // counted like the OSMesa backend draws it
  bool capture_skinned_tube(const intestine::TubePrimitive&, const float*, int, std::vector<float>&,
                            std::vector<float>&) override {
    return false;
  }
  void end_frame() override { ++counts_.frames; }
  bool read_image(Image&) override { return false; }
  bool read_drawn_image(Image&) override { return false; }
  const char* name() const override { return "null"; }
  std::string info() const override { return "null renderer (no GL context)"; }
};

}  // namespace

std::unique_ptr<Renderer> make_renderer(const std::string& backend, int width, int height) {
  if (width < 16 || width > 8192 || height < 16 || height > 8192) {
    throw_error("renderer: image size ", width, "x", height, " is out of range (16..8192 each)");
  }
  if (backend == "null") return std::make_unique<NullRenderer>(width, height);
  if (backend == "osmesa") return make_osmesa_renderer(width, height);
  throw_error("renderer: unknown backend '", backend, "' (use 'osmesa' or 'null')");
}

Lighting lighting_of(const scene::RenderSpec& render) {
  Lighting l;
  l.scope = render.light == scene::RenderSpec::Light::kScope;
  l.falloff = render.falloff.cast<float>();
  l.wet = static_cast<float>(render.wet);
  return l;
}

bool membrane_drawable(const intestine::MesenterySurface& s, const MembraneLook& look) noexcept {
  const auto n = static_cast<std::size_t>(s.vertex_count);
  if (s.vertex_count < 0 || s.positions.size() < 3 * n || s.normals.size() < 3 * n || s.coords.size() < 2 * n ||
      s.indices.size() % 3 != 0 || !look.rgb.allFinite() || !look.vessel_rgb.allFinite() ||
      !std::isfinite(look.alpha) || !std::isfinite(look.vessels) || !std::isfinite(look.specular) ||
      !std::isfinite(look.shininess)) {
    return false;
  }
  for (std::size_t i = 0; i < 3 * n; ++i) {
    if (!std::isfinite(s.positions[i]) || !std::isfinite(s.normals[i])) return false;
  }
  for (const std::uint32_t i : s.indices) {
    if (i >= n) return false;
  }
  return true;
}

void vertex_normals(const Eigen::Ref<const Eigen::MatrixX3f>& positions, const Eigen::Ref<const Eigen::MatrixX3i>& tris,
                    MatrixX3fView normals) {
  normals.setZero();
  // The cross product's length is twice the face area: summing it weights each face by its area.
  for (Eigen::Index f = 0; f < tris.rows(); ++f) {
    const int a = tris(f, 0), b = tris(f, 1), c = tris(f, 2);
    const Eigen::RowVector3f pa = positions.row(a);
    const Eigen::RowVector3f n = (positions.row(b) - pa).cross(positions.row(c) - pa);
    normals.row(a) += n;
    normals.row(b) += n;
    normals.row(c) += n;
  }
  for (Eigen::Index v = 0; v < normals.rows(); ++v) {
    const float len = normals.row(v).norm();
    if (len > 0.0f && std::isfinite(len)) {
      normals.row(v) /= len;
    } else {
      normals.row(v) = Eigen::RowVector3f(0.0f, 0.0f, 1.0f);
    }
  }
}

Eigen::Matrix4f view_matrix(const Camera& camera) {
  const Eigen::Vector3f eye = camera.eye.cast<float>();
  const Eigen::Vector3f f = (camera.target.cast<float>() - eye).normalized();
  Eigen::Vector3f s = f.cross(camera.up.cast<float>());
  if (s.squaredNorm() < 1e-12f) s = f.unitOrthogonal();  // up parallel to the view direction
  s.normalize();
  const Eigen::Vector3f u = s.cross(f);
  Eigen::Matrix4f m = Eigen::Matrix4f::Identity();
  m.block<1, 3>(0, 0) = s.transpose();
  m.block<1, 3>(1, 0) = u.transpose();
  m.block<1, 3>(2, 0) = -f.transpose();
  m(0, 3) = -s.dot(eye);
  m(1, 3) = -u.dot(eye);
  m(2, 3) = f.dot(eye);
  return m;
}

Eigen::Matrix4f projection_matrix(const Camera& camera, float aspect) {
  // Near and far planes scale with the eye-target distance: the scene stays in the well-resolved depth range.
  const float distance = static_cast<float>((camera.target - camera.eye).norm());
  const float z_near = 0.02f * distance;
  const float z_far = 20.0f * distance;
  const float t = 1.0f / std::tan(0.5f * static_cast<float>(camera.fov_deg) * kPi / 180.0f);
  Eigen::Matrix4f p = Eigen::Matrix4f::Zero();
  p(0, 0) = t / aspect;
  p(1, 1) = t;
  p(2, 2) = (z_far + z_near) / (z_near - z_far);
  p(2, 3) = 2.0f * z_far * z_near / (z_near - z_far);
  p(3, 2) = -1.0f;
  return p;
}

Eigen::Vector2f project_to_pixel(const Camera& camera, int width, int height, const Eigen::Vector3f& world) {
  const Eigen::Vector4f clip = projection_matrix(camera, static_cast<float>(width) / static_cast<float>(height)) *
                               view_matrix(camera) * world.homogeneous();
  const float x_ndc = clip.x() / clip.w();
  const float y_ndc = clip.y() / clip.w();
  return {0.5f * (x_ndc + 1.0f) * static_cast<float>(width), 0.5f * (1.0f - y_ndc) * static_cast<float>(height)};
}

}  // namespace surgsim
