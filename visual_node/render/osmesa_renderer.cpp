#include "render/osmesa_renderer.h"

// GL types, enums and function-pointer types come from the core-profile header only. osmesa.h includes the legacy
// <GL/gl.h>, which would clash with glcorearb.h: its include guard is set so that only the OSMesa API is declared.
#include <GL/glcorearb.h>
#define __gl_h_
#ifndef GLAPIENTRY
#define GLAPIENTRY
#endif
#include <GL/osmesa.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <cstring>
#include <initializer_list>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::fem;
using namespace surgsim::scene;

namespace surgsim {
namespace {

// The GL entry points this backend uses, loaded with OSMesaGetProcAddress (no GLEW).
#define SURGSIM_GL_FUNCTIONS(X)                                    \
  X(PFNGLGETSTRINGPROC, GetString)                                 \
  X(PFNGLGETERRORPROC, GetError)                                   \
  X(PFNGLVIEWPORTPROC, Viewport)                                   \
  X(PFNGLSCISSORPROC, Scissor)                                     \
  X(PFNGLCLEARCOLORPROC, ClearColor)                               \
  X(PFNGLCLEARPROC, Clear)                                         \
  X(PFNGLENABLEPROC, Enable)                                       \
  X(PFNGLDISABLEPROC, Disable)                                     \
  X(PFNGLDEPTHFUNCPROC, DepthFunc)                                 \
  X(PFNGLFINISHPROC, Finish)                                       \
  X(PFNGLREADBUFFERPROC, ReadBuffer)                               \
  X(PFNGLREADPIXELSPROC, ReadPixels)                               \
  X(PFNGLPIXELSTOREIPROC, PixelStorei)                             \
  X(PFNGLCREATESHADERPROC, CreateShader)                           \
  X(PFNGLSHADERSOURCEPROC, ShaderSource)                           \
  X(PFNGLCOMPILESHADERPROC, CompileShader)                         \
  X(PFNGLGETSHADERIVPROC, GetShaderiv)                             \
  X(PFNGLGETSHADERINFOLOGPROC, GetShaderInfoLog)                   \
  X(PFNGLDELETESHADERPROC, DeleteShader)                           \
  X(PFNGLCREATEPROGRAMPROC, CreateProgram)                         \
  X(PFNGLATTACHSHADERPROC, AttachShader)                           \
  X(PFNGLBINDATTRIBLOCATIONPROC, BindAttribLocation)               \
  X(PFNGLLINKPROGRAMPROC, LinkProgram)                             \
  X(PFNGLGETPROGRAMIVPROC, GetProgramiv)                           \
  X(PFNGLGETPROGRAMINFOLOGPROC, GetProgramInfoLog)                 \
  X(PFNGLUSEPROGRAMPROC, UseProgram)                               \
  X(PFNGLGETUNIFORMLOCATIONPROC, GetUniformLocation)               \
  X(PFNGLUNIFORMMATRIX4FVPROC, UniformMatrix4fv)                   \
  X(PFNGLUNIFORMMATRIX3FVPROC, UniformMatrix3fv)                   \
  X(PFNGLUNIFORM3FVPROC, Uniform3fv)                               \
  X(PFNGLUNIFORM1FPROC, Uniform1f)                                 \
  X(PFNGLGENVERTEXARRAYSPROC, GenVertexArrays)                     \
  X(PFNGLBINDVERTEXARRAYPROC, BindVertexArray)                     \
  X(PFNGLGENBUFFERSPROC, GenBuffers)                               \
  X(PFNGLBINDBUFFERPROC, BindBuffer)                               \
  X(PFNGLBUFFERDATAPROC, BufferData)                               \
  X(PFNGLBUFFERSUBDATAPROC, BufferSubData)                         \
  X(PFNGLENABLEVERTEXATTRIBARRAYPROC, EnableVertexAttribArray)     \
  X(PFNGLVERTEXATTRIBPOINTERPROC, VertexAttribPointer)             \
  X(PFNGLDRAWELEMENTSPROC, DrawElements)                           \
  X(PFNGLDELETEBUFFERSPROC, DeleteBuffers)                         \
  X(PFNGLGENTEXTURESPROC, GenTextures)                             \
  X(PFNGLBINDTEXTUREPROC, BindTexture)                             \
  X(PFNGLACTIVETEXTUREPROC, ActiveTexture)                         \
  X(PFNGLTEXBUFFERPROC, TexBuffer)                                 \
  X(PFNGLUNIFORM1IPROC, Uniform1i)                                 \
  X(PFNGLDRAWELEMENTSINSTANCEDPROC, DrawElementsInstanced)         \
  X(PFNGLDRAWARRAYSINSTANCEDPROC, DrawArraysInstanced)             \
  X(PFNGLTRANSFORMFEEDBACKVARYINGSPROC, TransformFeedbackVaryings) \
  X(PFNGLBINDBUFFERBASEPROC, BindBufferBase)                       \
  X(PFNGLBEGINTRANSFORMFEEDBACKPROC, BeginTransformFeedback)       \
  X(PFNGLENDTRANSFORMFEEDBACKPROC, EndTransformFeedback)           \
  X(PFNGLGETBUFFERSUBDATAPROC, GetBufferSubData)                   \
  X(PFNGLBLENDFUNCPROC, BlendFunc)                                 \
  X(PFNGLDEPTHMASKPROC, DepthMask)                                 \
  X(PFNGLUNIFORM4FVPROC, Uniform4fv)

struct GlApi {
#define SURGSIM_GL_DECLARE(type, name) type name = nullptr;
  SURGSIM_GL_FUNCTIONS(SURGSIM_GL_DECLARE)
#undef SURGSIM_GL_DECLARE

  /// Fills every pointer; throws naming the first entry point OSMesa does not have.
  void load() {
#define SURGSIM_GL_LOAD(type, name)                                           \
  name = reinterpret_cast<type>(OSMesaGetProcAddress("gl" #name));            \
  if (name == nullptr) throw_error("renderer (osmesa): GL entry point gl" #name " not found");
    SURGSIM_GL_FUNCTIONS(SURGSIM_GL_LOAD)
#undef SURGSIM_GL_LOAD
  }
};

// Blinn-Phong with a key and a fill light fixed in view space (the studio rig), or one light at the eye with distance
// falloff (the scope: a laparoscope's light at its tip); see Lighting. Colours are display (sRGB) values: shading is
// done in linear light and encoded back, with gamma 2 for sRGB (square on the CPU, sqrt per fragment: pow is the costly
// part of a fragment on llvmpipe).
constexpr const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec3 a_position;  // model space
layout(location = 1) in vec3 a_normal;    // model space
layout(location = 2) in vec3 a_tint;      // the vertex's colour as a factor of the surface's (display)
uniform mat4 u_mvp;
uniform mat4 u_model_view;
uniform mat3 u_normal_matrix;  // inverse transpose of the model-view's 3x3 block
out vec3 v_position;           // view space
out vec3 v_normal;             // view space
out vec3 v_tint;               // linear factor
void main() {
  v_position = (u_model_view * vec4(a_position, 1.0)).xyz;
  v_normal = u_normal_matrix * a_normal;
  v_tint = a_tint * a_tint;
  gl_Position = u_mvp * vec4(a_position, 1.0);
}
)";

// Fragment shaders are the version line, the lights (kLightsGlsl) and their own main.
constexpr const char* kFragmentVersion = "#version 330 core\n";

// The lights (set from Lighting every draw). Studio: the key rakes from the upper left, the fill from the right; the
// key is kept well away from the usual surface normals (a camera looking down on an organ at about 45 degrees) so that
// a dent changes the shading at first order; a light along the normal hides shallow dents. Scope: the key is a point
// at the eye with falloff 1 / (a + b d + c d^2) and no fill; the speculars are wet. The fill is diffuse only; the
// highlight is one pow per fragment: a broad lobe (exponent / 8) and its 8th power, the sharp one (three squarings).
constexpr const char* kLightsGlsl = R"(
uniform vec4 u_key;      // view space: towards the key light (w = 0), or its position (w = 1)
uniform vec3 u_falloff;  // the key's 1 / (a + b d + c d^2), d its distance (1, 0, 0 for a direction)
uniform vec4 u_light;    // key, fill, ambient, the broad highlight's share
const vec3 kFillDir = normalize(vec3(0.75, -0.25, 0.65));
// Linear colour at a view-space position of a surface with unit normal n (facing the viewer's side), diffuse
// `albedo`, highlight `specular` with exponent `shininess`; `through`: the key light reaching its back.
vec3 lit(vec3 n, vec3 position, vec3 albedo, vec3 specular, float shininess, out float through) {
  vec3 v = normalize(-position);
  vec3 to_key = u_key.xyz - u_key.w * position;
  float d = length(to_key);
  vec3 l = to_key / d;
  float key = u_light.x / (u_falloff.x + d * (u_falloff.y + d * u_falloff.z));
  float diffuse = max(dot(n, l), 0.0);
  float fill = max(dot(n, kFillDir), 0.0);
  float broad = diffuse > 0.0 ? pow(max(dot(n, normalize(l + v)), 0.0), 0.125 * shininess) : 0.0;
  float sharp = broad * broad;
  sharp *= sharp;
  sharp *= sharp;
  through = key * max(-dot(n, l), 0.0);
  return (u_light.z + key * diffuse + u_light.y * fill) * albedo + key * (sharp + u_light.w * broad) * specular;
}
)";

constexpr const char* kFragmentShader = R"(
in vec3 v_position;
in vec3 v_normal;
in vec3 v_tint;
uniform vec3 u_albedo;     // linear: the display colour squared
uniform vec3 u_specular;   // linear
uniform float u_shininess;
out vec4 frag_color;
void main() {
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) n = -n;  // both sides lit (open or cut surfaces)
  float through;
  vec3 c = lit(n, v_position, u_albedo * v_tint, u_specular, u_shininess, through);
  frag_color = vec4(sqrt(clamp(c, 0.0, 1.0)), 1.0);
}
)";

// Object-id pictures (Renderer::set_id_colour): the colour as given, nothing else.
constexpr const char* kIdFragmentShader = R"(
uniform vec3 u_id;
out vec4 frag_color;
void main() { frag_color = vec4(u_id, 1.0); }
)";

// Two-matrix skinning of the tube primitive (tube_geometry.h, docs/DESIGN.md, section 'Intestine rendering'): instance
// k of a draw skins the primitive with interval u_first_interval + k. A vertex (x, y, t, z) becomes
//   (1 - w(t)) (A (x, y, t, 1) + z r_a T_a) + w(t) (B (x, y, t, 1) + z r_b T_b),  w(t) = 3 t^2 - 2 t^3,
// the normal the same blend of x N + y B + z T; r, N, B, T are read from the matrices' columns. v_world and
// v_world_normal are what capture_skinned_tube reads back by transform feedback.
constexpr const char* kSkinVertexShader = R"(#version 330 core
layout(location = 0) in vec4 a_prim;  // x, y, t, z
uniform samplerBuffer u_skin;         // RGBA32F, 6 texels per interval: the rows of A_k, then of B_k
uniform int u_first_interval;
uniform mat4 u_mvp;
uniform mat4 u_model_view;
uniform mat3 u_normal_matrix;
out vec3 v_position;      // view space
out vec3 v_normal;        // view space
out vec3 v_world;         // m
out vec3 v_world_normal;  // unit
out vec3 v_tint;          // linear factor: the serosa's mottling, from the interval and the angle around the tube
// One end's matrix (rows at texel `base`) applied to the vertex: the point and the direction x N + y B + z T.
void skin_end(int base, out vec3 point, out vec3 direction, out vec3 tangent) {
  vec4 r0 = texelFetch(u_skin, base), r1 = texelFetch(u_skin, base + 1), r2 = texelFetch(u_skin, base + 2);
  vec3 n = vec3(r0.x, r1.x, r2.x), b = vec3(r0.y, r1.y, r2.y);
  tangent = normalize(vec3(r0.z, r1.z, r2.z));
  float radius = length(n);
  vec4 v = vec4(a_prim.xyz, 1.0);
  point = vec3(dot(r0, v), dot(r1, v), dot(r2, v)) + (a_prim.w * radius) * tangent;
  direction = a_prim.x * (n / radius) + a_prim.y * normalize(b) + a_prim.w * tangent;
}
void main() {
  int base = 6 * (u_first_interval + gl_InstanceID);
  float t = a_prim.z;
  float w = t * t * (3.0 - 2.0 * t);
  vec3 pa, da, ta, pb, db, tb;
  skin_end(base, pa, da, ta);
  skin_end(base + 3, pb, db, tb);
  v_world = mix(pa, pb, w);
  vec3 n = mix(da, db, w);
  v_world_normal = dot(n, n) > 1e-24 ? normalize(n) : ta;
  v_position = (u_model_view * vec4(v_world, 1.0)).xyz;
  v_normal = u_normal_matrix * v_world_normal;
  float u = float(u_first_interval + gl_InstanceID) + t;
  float mottle = sin(2.3 * u + 2.0 * a_prim.x) * sin(1.7 * u - 3.0 * a_prim.y) + 0.5 * sin(5.1 * u + 4.0 * a_prim.y);
  v_tint = vec3(1.0 + 0.10 * mottle, 1.0 + 0.14 * mottle, 1.0 + 0.12 * mottle);
  gl_Position = u_mvp * vec4(v_world, 1.0);
}
)";

// The membrane (draw_membrane: the mesentery): the surface's own normals and its coordinates (u along the intestine in
// grid columns, s across from the bowel, 0, to the root on the vessel, 1).
constexpr const char* kMembraneVertexShader = R"(#version 330 core
layout(location = 0) in vec3 a_position;  // model space
layout(location = 1) in vec3 a_normal;    // model space, unit
layout(location = 2) in vec2 a_coord;     // u, s
uniform mat4 u_mvp;
uniform mat4 u_model_view;
uniform mat3 u_normal_matrix;
out vec3 v_position;
out vec3 v_normal;
out vec2 v_coord;
out vec3 v_vessels;  // the branches' sideways wiggle (columns), the arcades' height (s), the vasa recta's shift
void main() {
  v_position = (u_model_view * vec4(a_position, 1.0)).xyz;
  v_normal = u_normal_matrix * a_normal;
  v_coord = a_coord;
  float u = a_coord.x, s = a_coord.y;
  v_vessels = vec3(0.3 * sin(4.0 * s + 0.57 * u) + 0.25 * sin(0.23 * u),
                   0.27 + 0.12 * (1.0 - abs(sin(1.0471976 * u))) + 0.05 * sin(0.37 * u + 1.0),
                   0.25 * sin(1.3 * u));
  gl_Position = u_mvp * vec4(a_position, 1.0);
}
)";

// Fat over vessels, lit like the other surfaces (same lights) on both sides, plus the key light coming through the
// membrane from behind, reddened by the tissue; blended with u_alpha. The vessels are drawn from the coordinates,
// anti-aliased by their screen derivatives: the root vessel along s = 1, a wavy branch every 3 columns from the root
// down to the arcades, the arcades arching towards the bowel between branches, and thin straight vessels (vasa
// recta) every half column from the arcades to the bowel. The curves' sines are evaluated per vertex (v_vessels):
// the fragments only measure distances.
constexpr const char* kMembraneFragmentShader = R"(
in vec3 v_position;
in vec3 v_normal;
in vec2 v_coord;
in vec3 v_vessels;
uniform vec3 u_albedo;     // linear
uniform vec3 u_vessel;     // linear
uniform vec3 u_specular;   // linear
uniform float u_shininess;
uniform float u_alpha;
uniform float u_vessels;
out vec4 frag_color;
const float kThrough = 0.35;
const vec3 kThroughTint = vec3(1.0, 0.62, 0.48);
// Coverage of a line of half-width w at distance d (same units), anti-aliased over fw, the distance's change per pixel.
float line(float d, float w, float fw) { return 1.0 - smoothstep(w - fw, w + fw, d); }
void main() {
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) n = -n;
  float u = v_coord.x, s = v_coord.y;
  float arcade = v_vessels.y;
  float d_branch = 3.0 * abs(fract((u - v_vessels.x) / 3.0 + 0.5) - 0.5);
  float d_arcade = abs(s - arcade);
  float d_recta = 0.5 * abs(fract(2.0 * u + v_vessels.z + 0.5) - 0.5);
  float vessel = line(1.0 - s, 0.04, fwidth(s));
  vessel = max(vessel, 0.85 * line(d_branch, 0.06, fwidth(d_branch)) * step(arcade, s));
  vessel = max(vessel, 0.75 * line(d_arcade, 0.011, fwidth(d_arcade)));
  vessel = max(vessel, 0.35 * line(d_recta, 0.03, fwidth(d_recta)) * step(s, arcade) * smoothstep(0.0, 0.12, s));
  vec3 albedo = mix(u_albedo, u_vessel, 0.8 * u_vessels * vessel);
  float through;
  vec3 c = lit(n, v_position, albedo, u_specular, u_shininess, through);
  c += kThrough * through * albedo * kThroughTint;
  frag_color = vec4(sqrt(clamp(c, 0.0, 1.0)), u_alpha);
}
)";

// The backdrop (draw_backdrop): a kBackdropColumns x kBackdropRows grid over the viewport at the far plane, its
// vertices made from gl_VertexID (two triangles a cell), coloured in the vertex shader (a vignette with faint folds)
// and interpolated: the fragment shader only writes the colour, the cheapest full-screen pass on llvmpipe.
constexpr int kBackdropColumns = 16;
constexpr int kBackdropRows = 12;
constexpr const char* kBackdropVertexShader = R"(#version 330 core
uniform vec3 u_centre;  // display colours
uniform vec3 u_edge;
uniform float u_aspect;
out vec3 v_colour;
const int kColumns = 16, kRows = 12;
void main() {
  int cell = gl_VertexID / 6, corner = gl_VertexID % 6;
  int dx = (corner == 1 || corner == 2 || corner == 4) ? 1 : 0;
  int dy = (corner == 2 || corner == 4 || corner == 5) ? 1 : 0;
  vec2 p = vec2(float(cell % kColumns + dx) / float(kColumns), float(cell / kColumns + dy) / float(kRows)) * 2.0 - 1.0;
  vec2 q = p * vec2(u_aspect, 1.0);
  float r = length(q) / length(vec2(u_aspect, 1.0));
  float folds = 0.5 + 0.5 * sin(7.0 * q.x + 3.0 * sin(2.3 * q.y + 1.3 * q.x));
  v_colour = mix(u_centre, u_edge, smoothstep(0.0, 0.95, r)) * (0.82 + 0.18 * folds * (1.0 - r));
  gl_Position = vec4(p, 0.99999, 1.0);
}
)";

constexpr const char* kBackdropFragmentShader = R"(
in vec3 v_colour;
out vec4 frag_color;
void main() { frag_color = vec4(v_colour, 1.0); }
)";

constexpr float kPi = 3.14159265358979323846f;
// The lights (Lighting). Studio: towards the key light, view space (w = 0: a direction). Scope: its ambient (the
// cavity's light scattered back), the broad highlight's share and the scale of the surfaces' specular at wet 1.
const Eigen::Vector4f kStudioKey = [] {
  const Eigen::Vector3f d = Eigen::Vector3f(-0.75f, 0.45f, 0.5f).normalized();
  return Eigen::Vector4f(d.x(), d.y(), d.z(), 0.0f);
}();
constexpr float kScopeAmbient = 0.05f;
constexpr float kBroadShare = 0.2f;
constexpr float kWetSpecular = 1.6f;
constexpr int kCylinderSegments = 24;
constexpr int kSphereSubdivisions = 2;  // 320 triangles
constexpr float kJawRadiusRatio = 0.55f;  // jaw radius / shaft radius

struct Material {
  Eigen::Vector3f rgb;
  Eigen::Vector3f specular;
  float shininess;
};

/// Floats per vertex of a GpuMesh: position, normal, tint.
constexpr int kVertexFloats = 9;

/// A vertex array with interleaved position + normal + tint (kVertexFloats) and 32-bit indices. Capacities only grow.
struct GpuMesh {
  GLuint vao = 0, vbo = 0, ebo = 0;
  GLsizei vertex_capacity = 0;  // vertices
  GLsizei index_capacity = 0;   // indices
  GLsizei index_count = 0;      // indices drawn
};

/// One per draw_surface call in a frame; keeps the indices last uploaded so that they are sent only on change.
struct SurfaceSlot {
  GpuMesh mesh;
  std::vector<std::uint32_t> indices;
};

/// A linked program and the locations of the uniforms draw() sets.
struct Program {
  GLuint id = 0;
  GLint mvp = -1, model_view = -1, normal_matrix = -1, albedo = -1, specular = -1, shininess = -1;
  GLint skin = -1, first_interval = -1;  // skinning programs only
  GLint vessel = -1, alpha = -1, vessels = -1;  // membrane only
  GLint centre = -1, edge = -1, aspect = -1;    // backdrop only
  GLint key = -1, falloff = -1, light = -1;     // the lights (every program with the lit() shaders)
  GLint id_colour = -1;                         // id programs only
};

/// The membrane's buffers: interleaved position, normal, coordinates (8 floats) and the triangles last sent.
struct MembraneMesh {
  GLuint vao = 0, vbo = 0, ebo = 0;
  GLsizei vertex_capacity = 0;
  GLsizei index_capacity = 0;
  GLsizei index_count = 0;
  std::vector<std::uint32_t> indices;
};

/// A tube primitive of one LOD on the GPU: static vertices (x, y, t, z) and indices, uploaded once.
struct PrimitiveMesh {
  GLuint vao = 0, vbo = 0, ebo = 0;
  GLsizei vertex_count = 0;      // body and both caps
  GLsizei body_index_count = 0;  // then the first ring's cap, then the last ring's
  GLsizei cap_index_count = 0;
};

struct CpuMesh {
  std::vector<float> vertices;  // x y z nx ny nz 1 1 1 per vertex (no tint)
  std::vector<std::uint32_t> indices;
};

/// Closed unit cylinder along +z from z = 0 to z = 1, radius 1, with flat caps.
CpuMesh make_unit_cylinder() {
  CpuMesh m;
  auto vertex = [&m](float x, float y, float z, float nx, float ny, float nz) {
    m.vertices.insert(m.vertices.end(), {x, y, z, nx, ny, nz, 1.0f, 1.0f, 1.0f});
    return static_cast<std::uint32_t>(m.vertices.size() / kVertexFloats - 1);
  };
  // Side: two rings with radial normals.
  for (int i = 0; i < kCylinderSegments; ++i) {
    const float a = 2.0f * kPi * static_cast<float>(i) / kCylinderSegments;
    const float c = std::cos(a), s = std::sin(a);
    vertex(c, s, 0.0f, c, s, 0.0f);
    vertex(c, s, 1.0f, c, s, 0.0f);
  }
  for (int i = 0; i < kCylinderSegments; ++i) {
    const std::uint32_t j = (i + 1) % kCylinderSegments;
    const std::uint32_t b0 = 2 * i, t0 = 2 * i + 1, b1 = 2 * j, t1 = 2 * j + 1;
    m.indices.insert(m.indices.end(), {b0, b1, t1, b0, t1, t0});
  }
  // Caps: a fan each, normals along the axis.
  for (int cap = 0; cap < 2; ++cap) {
    const float z = static_cast<float>(cap);
    const float nz = cap == 0 ? -1.0f : 1.0f;
    const std::uint32_t centre = vertex(0.0f, 0.0f, z, 0.0f, 0.0f, nz);
    for (int i = 0; i < kCylinderSegments; ++i) {
      const float a = 2.0f * kPi * static_cast<float>(i) / kCylinderSegments;
      vertex(std::cos(a), std::sin(a), z, 0.0f, 0.0f, nz);
    }
    for (int i = 0; i < kCylinderSegments; ++i) {
      const std::uint32_t a = centre + 1 + i, b = centre + 1 + (i + 1) % kCylinderSegments;
      if (cap == 0) {
        m.indices.insert(m.indices.end(), {centre, b, a});
      } else {
        m.indices.insert(m.indices.end(), {centre, a, b});
      }
    }
  }
  return m;
}

/// Unit icosphere (normals = positions), refined `subdivisions` times.
CpuMesh make_unit_sphere(int subdivisions) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Eigen::Vector3f> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& v : p) v.normalize();
  std::vector<std::uint32_t> f = {0, 11, 5, 0, 5,  1, 0, 1, 7, 0, 7,  10, 0, 10, 11, 1, 5, 9, 5, 11,
                                  4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3, 9,  4, 3,  4,  2, 3, 2, 6, 3,
                                  6, 8,  3, 8, 9,  4, 9, 5, 2, 4, 11, 6, 2, 10, 8,  6, 7, 9, 8, 1};
  for (int s = 0; s < subdivisions; ++s) {
    std::vector<std::uint32_t> next;
    // Split each edge once per face (duplicate midpoints are harmless for a handful of markers).
    for (std::size_t i = 0; i < f.size(); i += 3) {
      const std::uint32_t a = f[i], b = f[i + 1], c = f[i + 2];
      const auto mid = [&p](std::uint32_t u, std::uint32_t v) {
        p.push_back((p[u] + p[v]).normalized());
        return static_cast<std::uint32_t>(p.size() - 1);
      };
      const std::uint32_t ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
      next.insert(next.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
    }
    f.swap(next);
  }
  CpuMesh m;
  for (const auto& v : p) {
    m.vertices.insert(m.vertices.end(), {v.x(), v.y(), v.z(), v.x(), v.y(), v.z(), 1.0f, 1.0f, 1.0f});
  }
  m.indices = std::move(f);
  return m;
}

class OsMesaRenderer final : public Renderer {
 public:
  OsMesaRenderer(int width, int height) : Renderer(width, height) {
    // --- init: context, buffers, entry points, shaders, static meshes. May throw. ---
    keep_freed_heap();
    create_context();
    gl_.load();
    info_ = std::string(name()) + ": " + gl_string(GL_VERSION) + ", " + gl_string(GL_RENDERER);
    program_ = build_program(kVertexShader, kFragmentShader, false);
    membrane_program_ = build_program(kMembraneVertexShader, kMembraneFragmentShader, false);
    backdrop_program_ = build_program(kBackdropVertexShader, kBackdropFragmentShader, false);
    id_program_ = build_program(kVertexShader, kIdFragmentShader, false);
    membrane_id_program_ = build_program(kMembraneVertexShader, kIdFragmentShader, false);
    gl_.GenVertexArrays(1, &backdrop_vao_);  // the core profile draws only with a vertex array bound
    init_skinning();
    upload_static(make_unit_cylinder(), cylinder_);
    upload_static(make_unit_sphere(kSphereSubdivisions), sphere_);
    readback_.resize(static_cast<std::size_t>(width_) * height_ * 4);
    scaled_.rgb.reserve(static_cast<std::size_t>(width_) * height_ * 3);
    vertex_staging_.reserve(6 * 4096);
    index_staging_.reserve(3 * 8192);

    set_viewport(width_, height_);
    gl_.Enable(GL_DEPTH_TEST);
    gl_.DepthFunc(GL_LESS);
    gl_.Disable(GL_CULL_FACE);  // both sides are drawn and lit
    gl_.ClearColor(kBackgroundRgb[0] / 255.0f, kBackgroundRgb[1] / 255.0f, kBackgroundRgb[2] / 255.0f, 1.0f);
    gl_.PixelStorei(GL_PACK_ALIGNMENT, 1);
    const GLenum err = gl_.GetError();
    if (err != GL_NO_ERROR) throw_error("renderer (osmesa): GL error 0x", std::hex, err, " while initialising");
  }

  OsMesaRenderer(const OsMesaRenderer&) = delete;
  OsMesaRenderer& operator=(const OsMesaRenderer&) = delete;

  // --- run: per-frame calls. No allocation once buffers have reached their sizes; no exceptions. ---

  void begin_frame(const Camera& camera) override {
    make_current();
    next_surface_slot_ = 0;
    view_ = view_matrix(camera);
    projection_ = projection_matrix(camera, static_cast<float>(width_) / static_cast<float>(height_));
    set_viewport(render_width(), render_height());
    gl_.Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    gl_.UseProgram(program_.id);
  }

  using Renderer::draw_skinned_tube;
  using Renderer::draw_surface;

  void draw_surface(const Eigen::Ref<const Eigen::MatrixX3f>& positions, const Eigen::Ref<const Eigen::MatrixX3i>& tris,
                    const SurfaceLook& look, const Eigen::MatrixX3f* tint) override {
    const Eigen::Vector3f& rgb = look.rgb;
    // Indices to row-major 32-bit, checking the range on the way.
    const Eigen::Index nv = positions.rows();
    const Eigen::Index nt = tris.rows();
    index_staging_.resize(static_cast<std::size_t>(3 * nt));
    bool ok = positions.allFinite() && rgb.allFinite() &&
              (tint == nullptr || (tint->rows() == positions.rows() && tint->allFinite()));
    for (Eigen::Index f = 0; f < nt && ok; ++f) {
      for (int k = 0; k < 3; ++k) {
        const int i = tris(f, k);
        ok = ok && i >= 0 && i < nv;
        index_staging_[3 * f + k] = static_cast<std::uint32_t>(i);
      }
    }
    if (!ok) {
      ++counts_.rejected;
      return;
    }
    ++counts_.surfaces;
    if (nt == 0) return;

    // Positions, this frame's smooth normals and the tint, interleaved (x y z nx ny nz r g b), written in place.
    vertex_staging_.resize(static_cast<std::size_t>(kVertexFloats * nv));
    using Interleaved = Eigen::Map<Eigen::MatrixX3f, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
    const Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic> every_vertex(1, kVertexFloats);  // (outer, inner)
    Interleaved(vertex_staging_.data(), nv, 3, every_vertex) = positions;
    vertex_normals(positions, tris, Interleaved(vertex_staging_.data() + 3, nv, 3, every_vertex));
    if (tint != nullptr) {
      Interleaved(vertex_staging_.data() + 6, nv, 3, every_vertex) = *tint;
    } else {
      Interleaved(vertex_staging_.data() + 6, nv, 3, every_vertex).setOnes();
    }

    // Upload into this call's slot: vertices every frame, indices only when they changed.
    if (next_surface_slot_ == surface_slots_.size()) surface_slots_.emplace_back();  // first frames only
    SurfaceSlot& slot = surface_slots_[next_surface_slot_++];
    upload_vertices(slot.mesh, vertex_staging_);
    if (slot.indices != index_staging_) {
      upload_indices(slot.mesh, index_staging_);
      slot.indices = index_staging_;
    }
    draw(slot.mesh, Eigen::Matrix4f::Identity(), material(look));
  }

  void draw_membrane(const intestine::MesenterySurface& surface, const MembraneLook& look) override {
    if (!membrane_drawable(surface, look)) {
      ++counts_.rejected;
      return;
    }
    ++counts_.surfaces;
    const int nv = surface.vertex_count;
    if (nv == 0 || surface.indices.empty()) return;
    // Position, normal, coordinates interleaved (8 floats a vertex).
    vertex_staging_.resize(static_cast<std::size_t>(8 * nv));
    for (std::size_t v = 0; v < static_cast<std::size_t>(nv); ++v) {
      float* out = vertex_staging_.data() + 8 * v;
      std::memcpy(out, surface.positions.data() + 3 * v, 3 * sizeof(float));
      std::memcpy(out + 3, surface.normals.data() + 3 * v, 3 * sizeof(float));
      std::memcpy(out + 6, surface.coords.data() + 2 * v, 2 * sizeof(float));
    }
    MembraneMesh& m = membrane_;
    if (m.vao == 0) {
      gl_.GenVertexArrays(1, &m.vao);
      gl_.GenBuffers(1, &m.vbo);
      gl_.GenBuffers(1, &m.ebo);
      gl_.BindVertexArray(m.vao);
      gl_.BindBuffer(GL_ARRAY_BUFFER, m.vbo);
      const auto stride = static_cast<GLsizei>(8 * sizeof(float));
      for (GLuint a = 0; a < 3; ++a) {
        gl_.EnableVertexAttribArray(a);
        gl_.VertexAttribPointer(a, a == 2 ? 2 : 3, GL_FLOAT, GL_FALSE, stride,
                                reinterpret_cast<const void*>(3 * a * sizeof(float)));
      }
      gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ebo);
      gl_.BindVertexArray(0);
    }
    gl_.BindBuffer(GL_ARRAY_BUFFER, m.vbo);
    send(GL_ARRAY_BUFFER, vertex_staging_, nv, m.vertex_capacity);
    if (m.indices != surface.indices) {  // the same triangles every frame: sent once
      m.index_count = static_cast<GLsizei>(surface.indices.size());
      gl_.BindVertexArray(m.vao);  // the element buffer binding belongs to the VAO
      send(GL_ELEMENT_ARRAY_BUFFER, surface.indices, m.index_count, m.index_capacity);
      gl_.BindVertexArray(0);
      m.indices = surface.indices;
    }
    const Program& program = id_mode_ ? membrane_id_program_ : membrane_program_;
    gl_.UseProgram(program.id);
    set_uniforms(program, Eigen::Matrix4f::Identity(),
                 {look.rgb, Eigen::Vector3f::Constant(look.specular), look.shininess});
    const Eigen::Vector3f vessel = look.vessel_rgb.cwiseProduct(look.vessel_rgb);  // display -> linear
    gl_.Uniform3fv(program.vessel, 1, vessel.data());
    gl_.Uniform1f(program.alpha, std::clamp(look.alpha, 0.0f, 1.0f));
    gl_.Uniform1f(program.vessels, look.vessels);
    const bool blend = look.alpha < 1.0f && !id_mode_;
    if (blend) {
      gl_.Enable(GL_BLEND);
      gl_.BlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    }
    gl_.BindVertexArray(m.vao);
    gl_.DrawElements(GL_TRIANGLES, m.index_count, GL_UNSIGNED_INT, nullptr);
    gl_.BindVertexArray(0);
    if (blend) gl_.Disable(GL_BLEND);
    gl_.UseProgram(program_.id);
  }

  void draw_backdrop(const Eigen::Vector3f& centre_rgb, const Eigen::Vector3f& edge_rgb) override {
    if (!(centre_rgb.allFinite() && edge_rgb.allFinite())) {
      ++counts_.rejected;
      return;
    }
    if (id_mode_) return;  // an id picture has only the surfaces
    gl_.UseProgram(backdrop_program_.id);
    gl_.Uniform3fv(backdrop_program_.centre, 1, centre_rgb.data());
    gl_.Uniform3fv(backdrop_program_.edge, 1, edge_rgb.data());
    gl_.Uniform1f(backdrop_program_.aspect, static_cast<float>(width_) / static_cast<float>(height_));
    gl_.DepthMask(GL_FALSE);
    gl_.BindVertexArray(backdrop_vao_);
    gl_.DrawArraysInstanced(GL_TRIANGLES, 0, 6 * kBackdropColumns * kBackdropRows, 1);
    gl_.BindVertexArray(0);
    gl_.DepthMask(GL_TRUE);
    gl_.UseProgram(program_.id);
  }

  void draw_tool(const ToolGeometry& tool, float radius, const Eigen::Vector3f& rgb) override {
    if (!(tool.trocar.allFinite() && tool.tip.allFinite() && tool.jaw_tips[0].allFinite() &&
          tool.jaw_tips[1].allFinite() && std::isfinite(radius) && radius > 0.0f && rgb.allFinite())) {
      ++counts_.rejected;
      return;
    }
    ++counts_.tools;
    const Material metal{rgb, Eigen::Vector3f::Constant(0.75f), 60.0f};
    const Eigen::Vector3f tip = tool.tip.cast<float>();
    draw_cylinder(tool.trocar.cast<float>(), tip, radius, metal);
    for (const auto& jaw : tool.jaw_tips) draw_cylinder(tip, jaw.cast<float>(), kJawRadiusRatio * radius, metal);
  }

  void draw_points(const Eigen::Ref<const Eigen::MatrixX3f>& points, float radius, const Eigen::Vector3f& rgb) override {
    if (!(points.allFinite() && std::isfinite(radius) && radius > 0.0f && rgb.allFinite())) {
      ++counts_.rejected;
      return;
    }
    const Material marker{rgb, Eigen::Vector3f::Constant(0.3f), 32.0f};
    for (Eigen::Index i = 0; i < points.rows(); ++i) {
      Eigen::Matrix4f model = Eigen::Matrix4f::Identity();
      model.topLeftCorner<3, 3>() *= radius;
      model.block<3, 1>(0, 3) = points.row(i).transpose();
      draw(sphere_, model, marker);
    }
    counts_.points += static_cast<std::uint64_t>(points.rows());
  }

  void draw_skinned_tube(const intestine::TubePrimitive& primitive, const float* skin, int intervals,
                         const SurfaceLook& look) override {
    const PrimitiveMesh* mesh = look.rgb.allFinite() ? skinning_input(primitive, skin, intervals) : nullptr;
    if (mesh == nullptr) {
      ++counts_.rejected;
      return;
    }
    ++counts_.surfaces;
    // The tube: one instance per interval; then each cap once, with the first and the last interval's matrices.
    const Program& program = id_mode_ ? skin_id_program_ : skin_program_;
    gl_.UseProgram(program.id);
    set_uniforms(program, Eigen::Matrix4f::Identity(), material(look));
    gl_.BindVertexArray(mesh->vao);
    const auto offset = [](GLsizei indices) { return reinterpret_cast<const void*>(indices * sizeof(std::uint32_t)); };
    gl_.Uniform1i(program.first_interval, 0);
    gl_.DrawElementsInstanced(GL_TRIANGLES, mesh->body_index_count, GL_UNSIGNED_INT, nullptr, intervals);
    gl_.DrawElementsInstanced(GL_TRIANGLES, mesh->cap_index_count, GL_UNSIGNED_INT, offset(mesh->body_index_count), 1);
    gl_.Uniform1i(program.first_interval, intervals - 1);
    gl_.DrawElementsInstanced(GL_TRIANGLES, mesh->cap_index_count, GL_UNSIGNED_INT,
                              offset(mesh->body_index_count + mesh->cap_index_count), 1);
    gl_.BindVertexArray(0);
    gl_.UseProgram(program_.id);
  }

  bool gpu_skinning() const override { return skin_program_.id != 0; }

  bool capture_skinned_tube(const intestine::TubePrimitive& primitive, const float* skin, int intervals,
                            std::vector<float>& positions, std::vector<float>& normals) override {
    make_current();
    const PrimitiveMesh* mesh = skinning_input(primitive, skin, intervals);
    if (mesh == nullptr) return false;
    // Every primitive vertex of every instance as a point, rasterizer off, into a transform feedback buffer.
    const auto count = static_cast<std::size_t>(mesh->vertex_count) * static_cast<std::size_t>(intervals);
    std::vector<float> captured(6 * count);
    const auto bytes = static_cast<GLsizeiptr>(captured.size() * sizeof(float));
    GLuint buffer = 0;
    gl_.GenBuffers(1, &buffer);
    gl_.BindBuffer(GL_TRANSFORM_FEEDBACK_BUFFER, buffer);
    gl_.BufferData(GL_TRANSFORM_FEEDBACK_BUFFER, bytes, nullptr, GL_STATIC_READ);
    gl_.UseProgram(capture_program_.id);
    gl_.Uniform1i(capture_program_.first_interval, 0);
    gl_.Enable(GL_RASTERIZER_DISCARD);
    gl_.BindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, buffer);
    gl_.BindVertexArray(mesh->vao);
    gl_.BeginTransformFeedback(GL_POINTS);
    gl_.DrawArraysInstanced(GL_POINTS, 0, mesh->vertex_count, intervals);
    gl_.EndTransformFeedback();
    gl_.BindVertexArray(0);
    gl_.Disable(GL_RASTERIZER_DISCARD);
    gl_.GetBufferSubData(GL_TRANSFORM_FEEDBACK_BUFFER, 0, bytes, captured.data());
    gl_.BindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, 0);
    gl_.DeleteBuffers(1, &buffer);
    gl_.UseProgram(program_.id);
    if (gl_.GetError() != GL_NO_ERROR) return false;
    // Interleaved (v_world, v_world_normal) per vertex.
    positions.resize(3 * count);
    normals.resize(3 * count);
    for (std::size_t v = 0; v < count; ++v) {
      for (std::size_t c = 0; c < 3; ++c) {
        positions[3 * v + c] = captured[6 * v + c];
        normals[3 * v + c] = captured[6 * v + 3 + c];
      }
    }
    return true;
  }

  void end_frame() override {
    gl_.Finish();
    bool error = false;
    while (gl_.GetError() != GL_NO_ERROR) error = true;  // drain every flag
    if (error) ++counts_.gl_errors;
    ++counts_.frames;
  }

  bool read_image(Image& out) override {
    const bool full = viewport_width_ == width_ && viewport_height_ == height_;
    if (!read_drawn_image(full ? out : scaled_)) return false;
    if (!full) resize_bilinear(scaled_, width_, height_, out);
    return true;
  }

  bool read_drawn_image(Image& flipped) override {
    if (counts_.frames == 0) return false;
    make_current();
    const int w = viewport_width_;
    const int h = viewport_height_;
    gl_.ReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, readback_.data());
    // GL's row 0 is the bottom: flip while dropping alpha.
    flipped.resize(w, h);
    for (int y = 0; y < h; ++y) {
      const std::uint8_t* src = readback_.data() + static_cast<std::size_t>(h - 1 - y) * w * 4;
      std::uint8_t* dst = flipped.at(0, y);
      for (int x = 0; x < w; ++x, src += 4, dst += 3) {
        dst[0] = src[0];
        dst[1] = src[1];
        dst[2] = src[2];
      }
    }
    return true;
  }

  const char* name() const override { return core_ ? "osmesa" : "osmesa-compat"; }
  std::string info() const override { return info_; }

 private:
  /// The frame's viewport (set_render_scale): the lower-left w x h pixels, the clear limited to them by the scissor.
  void set_viewport(int w, int h) {
    if (w == viewport_width_ && h == viewport_height_) return;
    viewport_width_ = w;
    viewport_height_ = h;
    gl_.Viewport(0, 0, w, h);
    gl_.Scissor(0, 0, w, h);
    if (w < width_ || h < height_) {
      gl_.Enable(GL_SCISSOR_TEST);
    } else {
      gl_.Disable(GL_SCISSOR_TEST);
    }
  }

  // --- init helpers ---

  /// llvmpipe allocates and frees its binning memory every frame. With glibc's default trim threshold the freed
  /// top of the heap goes back to the OS and is faulted in again on the next frame: measured 11.6 ms instead of
  /// 7.8 ms of CPU per 640x480 frame. Keeping up to 256 MiB of freed heap avoids that (process-wide setting; the
  /// visual node holds no other large transient allocations).
  static void keep_freed_heap() {
#if defined(__GLIBC__)
    static const bool once = (mallopt(M_TRIM_THRESHOLD, 256 << 20), true);
    (void)once;
#endif
  }

  void create_context() {
    const int core_attribs[] = {OSMESA_FORMAT, OSMESA_RGBA, OSMESA_DEPTH_BITS, 24, OSMESA_STENCIL_BITS, 0,
                                OSMESA_ACCUM_BITS, 0, OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                                OSMESA_CONTEXT_MAJOR_VERSION, 3, OSMESA_CONTEXT_MINOR_VERSION, 3, 0};
    context_.reset(OSMesaCreateContextAttribs(core_attribs, nullptr));
    core_ = context_ != nullptr;
    if (!context_) context_.reset(OSMesaCreateContextExt(OSMESA_RGBA, 24, 0, 0, nullptr));  // see name()
    if (!context_) throw_error("renderer (osmesa): cannot create an OSMesa context (core 3.3 nor compatibility)");
    color_buffer_.resize(static_cast<std::size_t>(width_) * height_ * 4);
    if (!OSMesaMakeCurrent(context_.get(), color_buffer_.data(), GL_UNSIGNED_BYTE, width_, height_)) {
      throw_error("renderer (osmesa): cannot make the context current at ", width_, "x", height_);
    }
  }

  std::string gl_string(GLenum what) const {
    const GLubyte* s = gl_.GetString(what);
    return s ? reinterpret_cast<const char*>(s) : "?";
  }

  /// A shader from the concatenation of `sources` (the first begins with the version line).
  GLuint compile(GLenum type, std::initializer_list<const char*> sources) {
    const GLuint shader = gl_.CreateShader(type);
    gl_.ShaderSource(shader, static_cast<GLsizei>(sources.size()), sources.begin(), nullptr);
    gl_.CompileShader(shader);
    GLint ok = GL_FALSE;
    gl_.GetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (ok != GL_TRUE) {
      GLint length = 0;
      gl_.GetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
      std::string log(static_cast<std::size_t>(length > 1 ? length : 1), '\0');
      gl_.GetShaderInfoLog(shader, static_cast<GLsizei>(log.size()), nullptr, &log[0]);
      gl_.DeleteShader(shader);
      throw_error("renderer (osmesa): ", type == GL_VERTEX_SHADER ? "vertex" : "fragment",
                  " shader does not compile: ", log.c_str());
    }
    return shader;
  }

  /// Links `vertex_source` with the fragment shader of `fragment_main` (after the version line and the lights);
  /// `capture` records v_world and v_world_normal by transform feedback (interleaved).
  Program build_program(const char* vertex_source, const char* fragment_main, bool capture) {
    const GLuint vs = compile(GL_VERTEX_SHADER, {vertex_source});
    const GLuint fs = compile(GL_FRAGMENT_SHADER, {kFragmentVersion, kLightsGlsl, fragment_main});
    const GLuint program = gl_.CreateProgram();
    gl_.AttachShader(program, vs);
    gl_.AttachShader(program, fs);
    if (capture) {
      const char* varyings[] = {"v_world", "v_world_normal"};
      gl_.TransformFeedbackVaryings(program, 2, varyings, GL_INTERLEAVED_ATTRIBS);
    }
    gl_.LinkProgram(program);
    gl_.DeleteShader(vs);  // flagged; freed with the program
    gl_.DeleteShader(fs);
    GLint ok = GL_FALSE;
    gl_.GetProgramiv(program, GL_LINK_STATUS, &ok);
    if (ok != GL_TRUE) {
      GLint length = 0;
      gl_.GetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
      std::string log(static_cast<std::size_t>(length > 1 ? length : 1), '\0');
      gl_.GetProgramInfoLog(program, static_cast<GLsizei>(log.size()), nullptr, &log[0]);
      throw_error("renderer (osmesa): shader program does not link: ", log.c_str());
    }
    Program p;
    p.id = program;
    p.mvp = gl_.GetUniformLocation(program, "u_mvp");
    p.model_view = gl_.GetUniformLocation(program, "u_model_view");
    p.normal_matrix = gl_.GetUniformLocation(program, "u_normal_matrix");
    p.albedo = gl_.GetUniformLocation(program, "u_albedo");
    p.specular = gl_.GetUniformLocation(program, "u_specular");
    p.shininess = gl_.GetUniformLocation(program, "u_shininess");
    p.skin = gl_.GetUniformLocation(program, "u_skin");
    p.first_interval = gl_.GetUniformLocation(program, "u_first_interval");
    p.vessel = gl_.GetUniformLocation(program, "u_vessel");
    p.alpha = gl_.GetUniformLocation(program, "u_alpha");
    p.vessels = gl_.GetUniformLocation(program, "u_vessels");
    p.centre = gl_.GetUniformLocation(program, "u_centre");
    p.edge = gl_.GetUniformLocation(program, "u_edge");
    p.aspect = gl_.GetUniformLocation(program, "u_aspect");
    p.key = gl_.GetUniformLocation(program, "u_key");
    p.falloff = gl_.GetUniformLocation(program, "u_falloff");
    p.light = gl_.GetUniformLocation(program, "u_light");
    p.id_colour = gl_.GetUniformLocation(program, "u_id");
    return p;
  }

  /// The tube skinning programs (drawing and capture) and the texture buffer of the matrices. A context that cannot
  /// have them (compatibility fallback without texture buffers) keeps the renderer usable: gpu_skinning() is false
  /// and info() says why.
  void init_skinning() {
    try {
      skin_program_ = build_program(kSkinVertexShader, kFragmentShader, false);
      capture_program_ = build_program(kSkinVertexShader, kFragmentShader, true);
      skin_id_program_ = build_program(kSkinVertexShader, kIdFragmentShader, false);
    } catch (const Error& e) {
      skin_program_ = capture_program_ = skin_id_program_ = Program{};
      info_ += std::string("; no GPU tube skinning (") + e.what() + ")";
      while (gl_.GetError() != GL_NO_ERROR) {
      }
      return;
    }
    gl_.GenBuffers(1, &skin_buffer_);
    gl_.GenTextures(1, &skin_texture_);
    gl_.BindBuffer(GL_TEXTURE_BUFFER, skin_buffer_);
    gl_.BufferData(GL_TEXTURE_BUFFER, 24 * sizeof(float), nullptr, GL_DYNAMIC_DRAW);  // grown on use
    skin_capacity_ = 1;
    gl_.BindTexture(GL_TEXTURE_BUFFER, skin_texture_);
    gl_.TexBuffer(GL_TEXTURE_BUFFER, GL_RGBA32F, skin_buffer_);
    for (const Program* p : {&skin_program_, &capture_program_, &skin_id_program_}) {
      gl_.UseProgram(p->id);
      gl_.Uniform1i(p->skin, 0);  // texture unit 0
    }
    gl_.UseProgram(0);
  }

  /// Checks a skinning call's input, uploads the primitive of its LOD on first use and this call's matrices; the
  /// primitive's buffers, or null (nothing done) when the input cannot be drawn.
  const PrimitiveMesh* skinning_input(const intestine::TubePrimitive& primitive, const float* skin, int intervals) {
    if (skin_program_.id == 0 || skin == nullptr || intervals < 1) return nullptr;
    int lod = -1;
    for (int l = 0; l <= intestine::kTubeMaxLod && lod < 0; ++l) {
      const intestine::TubeLod t = intestine::tube_lod(l);
      if (t.sides == primitive.lod.sides && t.rings == primitive.lod.rings && t.cap_rings == primitive.lod.cap_rings) lod = l;
    }
    const int vertices = primitive.body_vertex_count + 2 * primitive.cap_vertex_count;
    if (lod < 0 || primitive.vertices.size() != 4 * static_cast<std::size_t>(vertices) ||
        primitive.indices.size() != static_cast<std::size_t>(primitive.body_index_count + 2 * primitive.cap_index_count)) {
      return nullptr;
    }
    for (int i = 0; i < 24 * intervals; ++i) {
      if (!std::isfinite(skin[i])) return nullptr;
    }
    PrimitiveMesh& mesh = primitives_[static_cast<std::size_t>(lod)];
    if (mesh.vao == 0) upload_primitive(primitive, mesh);
    // The matrices: 6 RGBA32F texels per interval, the buffer grown (reallocated) only for more intervals.
    const auto bytes = static_cast<GLsizeiptr>(24 * sizeof(float) * static_cast<std::size_t>(intervals));
    gl_.BindBuffer(GL_TEXTURE_BUFFER, skin_buffer_);
    if (intervals > skin_capacity_) {
      gl_.BufferData(GL_TEXTURE_BUFFER, bytes, skin, GL_DYNAMIC_DRAW);
      skin_capacity_ = intervals;
    } else {
      gl_.BufferSubData(GL_TEXTURE_BUFFER, 0, bytes, skin);
    }
    gl_.ActiveTexture(GL_TEXTURE0);
    gl_.BindTexture(GL_TEXTURE_BUFFER, skin_texture_);
    return &mesh;
  }

  void upload_primitive(const intestine::TubePrimitive& primitive, PrimitiveMesh& mesh) {
    gl_.GenVertexArrays(1, &mesh.vao);
    gl_.GenBuffers(1, &mesh.vbo);
    gl_.GenBuffers(1, &mesh.ebo);
    gl_.BindVertexArray(mesh.vao);
    gl_.BindBuffer(GL_ARRAY_BUFFER, mesh.vbo);
    gl_.BufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(primitive.vertices.size() * sizeof(float)),
                   primitive.vertices.data(), GL_STATIC_DRAW);
    gl_.EnableVertexAttribArray(0);
    gl_.VertexAttribPointer(0, 4, GL_FLOAT, GL_FALSE, 4 * sizeof(float), nullptr);
    gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, mesh.ebo);
    gl_.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(primitive.indices.size() * sizeof(std::uint32_t)),
                   primitive.indices.data(), GL_STATIC_DRAW);
    gl_.BindVertexArray(0);
    mesh.vertex_count = static_cast<GLsizei>(primitive.vertices.size() / 4);
    mesh.body_index_count = primitive.body_index_count;
    mesh.cap_index_count = primitive.cap_index_count;
  }

  void upload_static(const CpuMesh& cpu, GpuMesh& mesh) {
    upload_vertices(mesh, cpu.vertices);
    upload_indices(mesh, cpu.indices);
  }

  // --- GPU buffers: created on first use, reallocated only when a larger size is needed ---

  void ensure_buffers(GpuMesh& mesh) {
    if (mesh.vao != 0) return;
    gl_.GenVertexArrays(1, &mesh.vao);
    gl_.GenBuffers(1, &mesh.vbo);
    gl_.GenBuffers(1, &mesh.ebo);
    gl_.BindVertexArray(mesh.vao);
    gl_.BindBuffer(GL_ARRAY_BUFFER, mesh.vbo);
    gl_.EnableVertexAttribArray(0);
    const auto stride = static_cast<GLsizei>(kVertexFloats * sizeof(float));
    for (GLuint a = 0; a < 3; ++a) {  // position, normal, tint
      gl_.EnableVertexAttribArray(a);
      gl_.VertexAttribPointer(a, 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(3 * a * sizeof(float)));
    }
    gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, mesh.ebo);  // recorded in the VAO
    gl_.BindVertexArray(0);
  }

  /// Sends `data` (`count` elements: vertices or indices) into the buffer bound to `target`, reallocating it only
  /// when `count` exceeds `capacity` (then raised).
  template <typename T>
  void send(GLenum target, const std::vector<T>& data, GLsizei count, GLsizei& capacity) {
    const auto bytes = static_cast<GLsizeiptr>(data.size() * sizeof(T));
    if (count > capacity) {
      gl_.BufferData(target, bytes, data.data(), GL_DYNAMIC_DRAW);
      capacity = count;
    } else {
      gl_.BufferSubData(target, 0, bytes, data.data());
    }
  }

  void upload_vertices(GpuMesh& mesh, const std::vector<float>& data) {
    ensure_buffers(mesh);
    gl_.BindBuffer(GL_ARRAY_BUFFER, mesh.vbo);
    send(GL_ARRAY_BUFFER, data, static_cast<GLsizei>(data.size() / kVertexFloats), mesh.vertex_capacity);
  }

  void upload_indices(GpuMesh& mesh, const std::vector<std::uint32_t>& data) {
    ensure_buffers(mesh);
    mesh.index_count = static_cast<GLsizei>(data.size());
    gl_.BindVertexArray(mesh.vao);  // the element buffer binding belongs to the VAO
    send(GL_ELEMENT_ARRAY_BUFFER, data, mesh.index_count, mesh.index_capacity);
    gl_.BindVertexArray(0);
  }

  // --- drawing ---

  static Material material(const SurfaceLook& look) {
    return {look.rgb, Eigen::Vector3f::Constant(look.specular), look.shininess};
  }

  /// Transforms, lights and material of the program in use (and the id colour of an id program).
  void set_uniforms(const Program& program, const Eigen::Matrix4f& model, const Material& material) {
    const bool scope = lighting_.scope;
    const Eigen::Vector4f key = scope ? Eigen::Vector4f(0.0f, 0.0f, 0.0f, 1.0f) : kStudioKey;
    const Eigen::Vector3f falloff = scope ? lighting_.falloff : Eigen::Vector3f(1.0f, 0.0f, 0.0f);
    const Eigen::Vector4f light = scope ? Eigen::Vector4f(1.0f, 0.0f, kScopeAmbient, kBroadShare * lighting_.wet)
                                        : Eigen::Vector4f(0.9f, 0.3f, 0.08f, 0.0f);
    const float specular_scale = scope ? kWetSpecular * lighting_.wet : 1.0f;
    gl_.Uniform4fv(program.key, 1, key.data());
    gl_.Uniform3fv(program.falloff, 1, falloff.data());
    gl_.Uniform4fv(program.light, 1, light.data());
    if (program.id_colour >= 0) gl_.Uniform3fv(program.id_colour, 1, id_rgb_.data());
    const Eigen::Matrix4f model_view = view_ * model;
    const Eigen::Matrix4f mvp = projection_ * model_view;
    const Eigen::Matrix3f normal_matrix = model_view.topLeftCorner<3, 3>().inverse().transpose();
    gl_.UniformMatrix4fv(program.mvp, 1, GL_FALSE, mvp.data());  // Eigen is column-major, like GL
    gl_.UniformMatrix4fv(program.model_view, 1, GL_FALSE, model_view.data());
    gl_.UniformMatrix3fv(program.normal_matrix, 1, GL_FALSE, normal_matrix.data());
    const Eigen::Vector3f albedo = material.rgb.cwiseProduct(material.rgb);  // display -> linear (gamma 2)
    gl_.Uniform3fv(program.albedo, 1, albedo.data());
    const Eigen::Vector3f specular = specular_scale * material.specular;
    gl_.Uniform3fv(program.specular, 1, specular.data());
    gl_.Uniform1f(program.shininess, material.shininess);
  }

  void draw(const GpuMesh& mesh, const Eigen::Matrix4f& model, const Material& material) {
    if (id_mode_) gl_.UseProgram(id_program_.id);
    set_uniforms(id_mode_ ? id_program_ : program_, model, material);
    gl_.BindVertexArray(mesh.vao);
    gl_.DrawElements(GL_TRIANGLES, mesh.index_count, GL_UNSIGNED_INT, nullptr);
    gl_.BindVertexArray(0);
    if (id_mode_) gl_.UseProgram(program_.id);
  }

  /// The unit cylinder scaled to `radius` and stretched from a to b. Skipped when a and b (nearly) coincide.
  void draw_cylinder(const Eigen::Vector3f& a, const Eigen::Vector3f& b, float radius, const Material& material) {
    const Eigen::Vector3f axis = b - a;
    const float length = axis.norm();
    if (!(length > 1e-6f)) return;
    Eigen::Matrix4f model = Eigen::Matrix4f::Identity();
    const Eigen::Matrix3f rotation =
        Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitZ(), axis / length).toRotationMatrix();
    model.topLeftCorner<3, 3>() = rotation * Eigen::Vector3f(radius, radius, length).asDiagonal();
    model.block<3, 1>(0, 3) = a;
    draw(cylinder_, model, material);
  }

  void make_current() {
    if (OSMesaGetCurrentContext() != context_.get()) {
      OSMesaMakeCurrent(context_.get(), color_buffer_.data(), GL_UNSIGNED_BYTE, width_, height_);
    }
  }

  /// Destroys the context (and with it every GL object), unbinding it first if it is current on this thread.
  struct ContextDeleter {
    void operator()(osmesa_context* context) const {
      if (OSMesaGetCurrentContext() == context) OSMesaMakeCurrent(nullptr, nullptr, 0, 0, 0);
      OSMesaDestroyContext(context);
    }
  };

  // The buffer outlives the context (declared first), which is destroyed after every other member, also on a throw.
  std::vector<std::uint8_t> color_buffer_;  // RGBA, width x height, the context's draw buffer
  std::unique_ptr<osmesa_context, ContextDeleter> context_;
  bool core_ = false;
  GlApi gl_;
  std::string info_;

  Program program_;          // surfaces, tool, markers
  Program skin_program_;     // tube skinning (id 0: not available)
  Program capture_program_;  // the same with transform feedback, for capture_skinned_tube
  Program membrane_program_;  // draw_membrane
  Program id_program_;        // the id pictures (set_id_colour): surfaces, tool, markers
  Program skin_id_program_;   // the tube's
  Program membrane_id_program_;  // the membrane's
  Program backdrop_program_;  // draw_backdrop
  GLuint backdrop_vao_ = 0;   // empty: the backdrop's vertices come from gl_VertexID
  MembraneMesh membrane_;
  GLuint skin_buffer_ = 0, skin_texture_ = 0;  // the matrices, a texture buffer
  int skin_capacity_ = 0;                      // intervals
  std::array<PrimitiveMesh, intestine::kTubeMaxLod + 1> primitives_{};  // uploaded on first use

  GpuMesh cylinder_;
  GpuMesh sphere_;
  std::vector<SurfaceSlot> surface_slots_;
  std::size_t next_surface_slot_ = 0;

  // Per-frame state and scratch space (sized on first use, then reused).
  Eigen::Matrix4f view_ = Eigen::Matrix4f::Identity();
  Eigen::Matrix4f projection_ = Eigen::Matrix4f::Identity();
  std::vector<float> vertex_staging_;
  std::vector<std::uint32_t> index_staging_;
  std::vector<std::uint8_t> readback_;  // RGBA, bottom row first
  Image scaled_;                        // a frame drawn at a render scale below 1, before it is scaled up
  int viewport_width_ = 0;              // the viewport of the frames drawn since the last change (set_viewport)
  int viewport_height_ = 0;
};

}  // namespace

std::unique_ptr<Renderer> make_osmesa_renderer(int width, int height) {
  return std::make_unique<OsMesaRenderer>(width, height);
}

}  // namespace surgsim
