// The visual node's renderer behind an interface (docs/DESIGN.md, section 'Layout'): an OSMesa backend that draws
// off-screen and a null backend that only counts calls (--headless, and tests of the visual logic without a GL
// context).
//
// A frame is: begin_frame(camera), any number of draw_* calls, end_frame(), then optionally read_image().
// Construction may throw (no GL context, shader compile failure); the per-frame calls never throw: input they
// cannot draw (out-of-range indices, non-finite coordinates) is skipped and counted in counts().rejected.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "render/image.h"
#include "scene/scene.h"
#include "tool/tool.h"
#include "intestine/tube_geometry.h"

namespace surgsim {

/// Default colours, linear RGB in [0, 1].
inline const Eigen::Vector3f kLiverRgb(0.50f, 0.16f, 0.12f);        // dark red-brown liver
inline const Eigen::Vector3f kGallbladderRgb(0.36f, 0.42f, 0.20f);  // the gallbladder, greenish, seen through its wall
inline const Eigen::Vector3f kMarkerRgb(0.95f, 0.85f, 0.20f);   // contact-point markers
/// Instruments (several tools told apart in a picture), by index in the scene's tools list: 0 metallic
/// grey (the one-tool colour), 1 blue, 2 green, 3 violet. instrument_rgb() cycles beyond them.
inline const std::array<Eigen::Vector3f, 4> kInstrumentRgb = {
    Eigen::Vector3f(0.66f, 0.68f, 0.71f), Eigen::Vector3f(0.22f, 0.42f, 0.86f), Eigen::Vector3f(0.22f, 0.70f, 0.36f),
    Eigen::Vector3f(0.62f, 0.34f, 0.80f)};
inline const Eigen::Vector3f& instrument_rgb(int instrument) {
  return kInstrumentRgb[static_cast<std::size_t>(instrument < 0 ? 0 : instrument) % kInstrumentRgb.size()];
}
/// Background, as stored in the image (a dark neutral, not black, so a test can tell foreground apart).
constexpr std::uint8_t kBackgroundRgb[3] = {40, 42, 48};

/// How a lit surface reflects (draw_surface, draw_skinned_tube): its colour and a grey specular highlight. The
/// default is a matte organ; wet mucosa (the intestine tube) is glossier.
struct SurfaceLook {
  Eigen::Vector3f rgb = Eigen::Vector3f::Constant(0.8f);  // display colour
  float specular = 0.22f;                                   // linear, of the key light
  float shininess = 40.0f;                                  // Blinn-Phong exponent
};

/// What a membrane looks like (draw_membrane): fat over a web of vessels, translucent, lit on both sides with some
/// of the light coming through from behind.
struct MembraneLook {
  Eigen::Vector3f rgb = Eigen::Vector3f(0.95f, 0.80f, 0.62f);        // display colour of the fat
  Eigen::Vector3f vessel_rgb = Eigen::Vector3f(0.55f, 0.13f, 0.14f); // of the vessels
  float alpha = 0.88f;      // opacity, blended over what was drawn before it
  float vessels = 1.0f;     // 0: no vessels; 1: the root vessel along v = 1, branches and arcades to v = 0
  float specular = 0.30f;   // linear
  float shininess = 30.0f;
};

/// The lights of a picture (set_lighting; kept across frames). The studio rig: a key light raking from the upper left
/// and a fill from the right, fixed in view space. The scope: one light at the eye (a laparoscope's tip), falling off
/// with distance as 1 / (a + b d + c d^2); with it the surfaces look wet, a sharp highlight over a broad one.
struct Lighting {
  bool scope = false;
  Eigen::Vector3f falloff = Eigen::Vector3f(0.3f, 0.0f, 60.0f);  // scope: a, b, c (d in m)
  float wet = 1.0f;                                              // scope: the speculars' scale, 0 = matte
};
/// The lighting a scene's visual.render asks for.
Lighting lighting_of(const scene::RenderSpec& render);

/// What a renderer was asked to do (both backends count the same way).
struct RenderCounts {
  std::uint64_t frames = 0;     // end_frame calls
  std::uint64_t surfaces = 0;   // draw_surface, draw_skinned_tube and draw_membrane calls drawn
  std::uint64_t tools = 0;      // draw_tool calls drawn
  std::uint64_t points = 0;     // markers drawn (sum of rows passed to draw_points)
  std::uint64_t rejected = 0;   // draw calls skipped because of bad input
  std::uint64_t gl_errors = 0;  // frames that ended with a GL error flag (OSMesa only)
};

class Renderer {
 public:
  virtual ~Renderer() = default;

  /// Starts a frame: clears to the background and sets view and projection from `camera` (vertical field of view;
  /// near and far planes follow the eye-target distance).
  virtual void begin_frame(const scene::Camera& camera) = 0;

  /// A triangle surface. positions: #V x 3, m; tris: #F x 3 indices into positions, counter-clockwise seen from
  /// outside. Smooth normals (area-weighted per vertex) are recomputed from the positions on every call; both
  /// sides are lit. GPU buffers are allocated for the largest size seen and then only updated.
  /// `tint` (#V x 3, or null): each vertex's colour as a factor of look.rgb (procedural detail,
  /// render/surface_detail.h); rejected when its rows are not the positions'.
  virtual void draw_surface(const Eigen::Ref<const Eigen::MatrixX3f>& positions,
                            const Eigen::Ref<const Eigen::MatrixX3i>& tris, const SurfaceLook& look,
                            const Eigen::MatrixX3f* tint) = 0;
  /// The same in the look's colour alone.
  void draw_surface(const Eigen::Ref<const Eigen::MatrixX3f>& positions, const Eigen::Ref<const Eigen::MatrixX3i>& tris,
                    const SurfaceLook& look) {
    draw_surface(positions, tris, look, nullptr);
  }
  /// The same, matte, in `rgb`.
  void draw_surface(const Eigen::Ref<const Eigen::MatrixX3f>& positions, const Eigen::Ref<const Eigen::MatrixX3i>& tris,
                    const Eigen::Vector3f& rgb) {
    draw_surface(positions, tris, SurfaceLook{rgb});
  }

  /// A membrane given with its own per-vertex unit normals (intestine::MesenterySurface: the smooth mesentery) and
  /// surface coordinates (u along, v across from 0 to 1) from which the fragment shader draws its vessels. Drawn
  /// translucent (look.alpha) over what was drawn before it, so draw it after the opaque surfaces it may cover; it
  /// writes depth, so what is drawn after it behind it is hidden. Both sides lit, plus the light through it. GPU
  /// buffers as draw_surface's; the triangles are sent again only when they change. Rejected (counts().rejected)
  /// when the surface's arrays do not match its counts, an index is out of range or a value is not finite.
  virtual void draw_membrane(const intestine::MesenterySurface& surface, const MembraneLook& look) = 0;

  /// A backdrop behind everything drawn in this frame, before or after it (it lies at the far plane and writes no
  /// depth): a vignette from `centre_rgb` in the middle of the image to `edge_rgb` in its corners, with faint
  /// folds, like an abdominal cavity seen through a laparoscope. Drawn after the opaque surfaces it costs only the
  /// pixels they leave (early depth test); a translucent surface drawn before it blends over the clear colour
  /// instead. Not counted as a surface.
  virtual void draw_backdrop(const Eigen::Vector3f& centre_rgb, const Eigen::Vector3f& edge_rgb) = 0;

  /// A tool in metallic `rgb` (instrument_rgb(i) for instrument i): the shaft as a cylinder of `radius` (m) from
  /// tool.trocar to tool.tip, and the two jaws as thinner cylinders from the tip to jaw_tips[0] and jaw_tips[1].
  virtual void draw_tool(const tool::ToolGeometry& tool, float radius, const Eigen::Vector3f& rgb) = 0;
  /// The same in the first instrument's grey.
  void draw_tool(const tool::ToolGeometry& tool, float radius) { draw_tool(tool, radius, instrument_rgb(0)); }

  /// Small spheres of `radius` (m) at each row of `points` (#P x 3, m), e.g. contact points.
  virtual void draw_points(const Eigen::Ref<const Eigen::MatrixX3f>& points, float radius,
                           const Eigen::Vector3f& rgb) = 0;

  /// A tube skinned on the GPU (docs/DESIGN.md, section 'Intestine rendering', tube_geometry.h): `primitive` (one
  /// interval of a level of detail and the two end caps; uploaded on its first use and kept, one buffer per LOD)
  /// deformed in the vertex shader by the per-interval matrices `skin` (24 floats per interval: A_k then B_k, 3 x 4
  /// row-major, as TubeMesh::skin), one instance per interval, the first ring's cap with interval 0 and the last
  /// ring's with interval intervals - 1.
  /// Only the matrices are sent per call. Lit like draw_surface. Rejected (counts().rejected) when the backend has no
  /// GPU skinning (gpu_skinning() false), for intervals < 1 or a non-finite matrix.
  virtual void draw_skinned_tube(const intestine::TubePrimitive& primitive, const float* skin, int intervals,
                                 const SurfaceLook& look) = 0;
  /// The same, matte, in `rgb`.
  void draw_skinned_tube(const intestine::TubePrimitive& primitive, const float* skin, int intervals,
                         const Eigen::Vector3f& rgb) {
    draw_skinned_tube(primitive, skin, intervals, SurfaceLook{rgb});
  }
  /// Whether draw_skinned_tube draws (the null backend counts it; OSMesa needs a core context with texture buffers).
  virtual bool gpu_skinning() const = 0;

  /// Debug path for tests: runs the skinning vertex shader of draw_skinned_tube over every primitive vertex of every
  /// interval (instance k writes primitive vertex i at k * #vertices + i) and reads the results back by transform
  /// feedback: world positions (m) and unit normals, 3 floats each per vertex (resized). Allocates; not for frames.
  /// False when the backend has no GPU skinning.
  virtual bool capture_skinned_tube(const intestine::TubePrimitive& primitive, const float* skin, int intervals,
                                    std::vector<float>& positions, std::vector<float>& normals) = 0;

  /// Finishes the frame (waits for the rasterizer, so the time of begin..end is the render time).
  virtual void end_frame() = 0;

  /// Copies the last finished frame into `out` (resized to width x height; row 0 = top; reuses its capacity).
  /// False when the backend has no image (null) or no frame has been finished yet.
  virtual bool read_image(Image& out) = 0;
  /// The same without the scale-up: the last frame's render_width() x render_height() pixels as drawn (at a render
  /// scale of 1, what read_image gives).
  virtual bool read_drawn_image(Image& out) = 0;

  /// "osmesa" (core profile), "osmesa-compat" (core profile unavailable) or "null".
  virtual const char* name() const = 0;
  /// One line for logs, e.g. the GL version and renderer string.
  virtual std::string info() const = 0;

  /// The lights of the frames from now on (studio by default).
  void set_lighting(const Lighting& lighting) { lighting_ = lighting; }
  const Lighting& lighting() const { return lighting_; }

  /// Object-id pictures (tests, picking): with a colour set, every draw call draws its surface flat in `id_rgb` (no
  /// lighting, tint, vessels or blending; the backdrop is not drawn), so that each pixel tells which call drew it.
  /// Each channel is stored exactly when it is a multiple of 1/255. clear_id_colour() goes back to shading.
  void set_id_colour(const Eigen::Vector3f& id_rgb) {
    id_mode_ = true;
    id_rgb_ = id_rgb;
  }
  void clear_id_colour() { id_mode_ = false; }

  /// Dynamic resolution: the frames from the next begin_frame on are drawn into the lower-left render_width() x
  /// render_height() pixels (the picture's width and height times `scale`, rounded to a multiple of 8 pixels, at
  /// least 16 each), and read_image scales that back up to width() x height() (bilinear), so a PNG still gets a
  /// full-size picture; read_drawn_image gives the pixels drawn (the web stream: the page scales them up). The
  /// fragment work falls with the square of the scale. `scale` is clamped to [kMinRenderScale, 1]; a non-finite one is
  /// ignored. 1 (the default) draws at full size, exactly as without it.
  void set_render_scale(float scale) {
    if (!std::isfinite(scale)) return;
    render_scale_ = scale < kMinRenderScale ? kMinRenderScale : (scale > 1.0f ? 1.0f : scale);
  }
  float render_scale() const { return render_scale_; }
  int render_width() const { return scaled(width_); }
  int render_height() const { return scaled(height_); }
  static constexpr float kMinRenderScale = 0.25f;

  int width() const { return width_; }
  int height() const { return height_; }
  const RenderCounts& counts() const { return counts_; }

 protected:
  Renderer(int width, int height) : width_(width), height_(height) {}
  int width_;
  int height_;
  RenderCounts counts_;
  Lighting lighting_;
  bool id_mode_ = false;
  Eigen::Vector3f id_rgb_ = Eigen::Vector3f::Zero();
  float render_scale_ = 1.0f;

 private:
  int scaled(int size) const {
    if (render_scale_ >= 1.0f) return size;
    const int s = 8 * static_cast<int>(std::lround(static_cast<float>(size) * render_scale_ / 8.0f));
    if (s >= size) return size;
    return s < 16 ? (size < 16 ? size : 16) : s;
  }
};

/// Creates a renderer: backend "osmesa" or "null"; width and height in pixels (16..8192).
/// Throws surgsim::core::Error on an unknown backend, a bad size, or when the GL context or shaders cannot be created.
std::unique_ptr<Renderer> make_renderer(const std::string& backend, int width, int height);

// Geometry shared by the backends and by tests (pure; no GL).

/// Any #V x 3 float view: a plain MatrixX3f, or a strided Map into an interleaved vertex buffer.
using MatrixX3fView = Eigen::Ref<Eigen::MatrixX3f, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

/// Area-weighted vertex normals: each vertex gets the normalized sum of the cross products of its faces.
/// `normals` must already be #V x 3 (nothing is allocated); a vertex without faces (or with a degenerate fan)
/// gets (0, 0, 1). Indices must be in range (not checked here).
void vertex_normals(const Eigen::Ref<const Eigen::MatrixX3f>& positions, const Eigen::Ref<const Eigen::MatrixX3i>& tris,
                    MatrixX3fView normals);

/// Whether draw_membrane can draw `surface` with `look`: arrays as long as its counts, indices in range, every value
/// finite (both backends reject the same input).
bool membrane_drawable(const intestine::MesenterySurface& surface, const MembraneLook& look) noexcept;

/// World -> view (right-handed, camera looking down -z) for camera.eye/target/up.
Eigen::Matrix4f view_matrix(const scene::Camera& camera);
/// View -> clip (OpenGL conventions) for the camera's vertical field of view and the image aspect (width / height).
Eigen::Matrix4f projection_matrix(const scene::Camera& camera, float aspect);
/// Where a world point lands in a width x height image: x right, y down (row 0 = top), pixel centres at +0.5.
Eigen::Vector2f project_to_pixel(const scene::Camera& camera, int width, int height, const Eigen::Vector3f& world);

}  // namespace surgsim
