#include "render/renderer.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <map>
#include <utility>
#include <vector>

#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::tool;
using namespace surgsim::intestine;
using namespace surgsim::scene;

namespace surgsim {
namespace {

constexpr int kWidth = 320;
constexpr int kHeight = 240;

struct Surface {
  Eigen::MatrixX3f positions;  // #V x 3
  Eigen::MatrixX3i tris;       // #F x 3, outward
};

/// Icosphere with shared vertices (so that smooth normals and dents behave as on an organ surface).
Surface icosphere(int subdivisions, float radius) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Eigen::Vector3f> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& v : p) v.normalize();
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoints;
    auto mid = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      const auto it = midpoints.find(key);
      if (it != midpoints.end()) return it->second;
      p.push_back((p[a] + p[b]).normalized());
      const int id = static_cast<int>(p.size()) - 1;
      midpoints.emplace(key, id);
      return id;
    };
    std::vector<Eigen::Vector3i> next;
    for (const auto& tri : f) {
      const int ab = mid(tri[0], tri[1]), bc = mid(tri[1], tri[2]), ca = mid(tri[2], tri[0]);
      next.push_back({tri[0], ab, ca});
      next.push_back({tri[1], bc, ab});
      next.push_back({tri[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    f.swap(next);
  }
  Surface s;
  s.positions.resize(static_cast<Eigen::Index>(p.size()), 3);
  for (std::size_t i = 0; i < p.size(); ++i) s.positions.row(static_cast<Eigen::Index>(i)) = radius * p[i].transpose();
  s.tris.resize(static_cast<Eigen::Index>(f.size()), 3);
  for (std::size_t i = 0; i < f.size(); ++i) s.tris.row(static_cast<Eigen::Index>(i)) = f[i].transpose();
  return s;
}

/// Looking at the origin from -y, z up, 4 m away: a unit sphere fills a good part of the picture.
Camera front_camera() {
  Camera c;
  c.eye = {0, -4, 0};
  c.target = {0, 0, 0};
  c.up = {0, 0, 1};
  c.fov_deg = 35.0;
  return c;
}

bool is_background(const Image& image, int x, int y) {
  const std::uint8_t* p = image.at(x, y);
  return p[0] == kBackgroundRgb[0] && p[1] == kBackgroundRgb[1] && p[2] == kBackgroundRgb[2];
}

double foreground_fraction(const Image& image) {
  int n = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) n += is_background(image, x, y) ? 0 : 1;
  }
  return static_cast<double>(n) / (image.width * image.height);
}

Image render_surface(Renderer& renderer, const Surface& surface, const Camera& camera = front_camera()) {
  renderer.begin_frame(camera);
  renderer.draw_surface(surface.positions, surface.tris, kLiverRgb);
  renderer.end_frame();
  Image image;
  EXPECT_TRUE(renderer.read_image(image));
  return image;
}

std::string temp_path(const std::string& name) { return ::testing::TempDir() + name; }

TEST(OsMesaRenderer, CoreProfileContext) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  std::printf("renderer: %s\n", renderer->info().c_str());
  // The core profile is what we ask for; "osmesa-compat" would mean Mesa refused it (still usable).
  EXPECT_STREQ(renderer->name(), "osmesa");
  EXPECT_EQ(renderer->width(), kWidth);
  EXPECT_EQ(renderer->height(), kHeight);
}

TEST(OsMesaRenderer, SphereIsVisibleRedAndFramed) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const Image image = render_surface(*renderer, icosphere(3, 1.0f));
  ASSERT_EQ(image.width, kWidth);
  ASSERT_EQ(image.height, kHeight);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  EXPECT_EQ(renderer->counts().surfaces, 1u);

  // A unit sphere 4 m away with a 35 degree field of view covers about a third of the picture.
  const double fraction = foreground_fraction(image);
  EXPECT_GT(fraction, 0.2);
  EXPECT_LT(fraction, 0.6);
  const std::uint8_t* centre = image.at(kWidth / 2, kHeight / 2);
  EXPECT_GT(centre[0], centre[1] + 40) << "centre should be the organ's red-brown";
  EXPECT_GT(centre[0], centre[2] + 40);
  for (const auto& [x, y] : {std::pair{0, 0}, {kWidth - 1, 0}, {0, kHeight - 1}, {kWidth - 1, kHeight - 1}}) {
    EXPECT_TRUE(is_background(image, x, y)) << "corner " << x << "," << y;
  }
  // The sphere is centred: its projected centre is the image centre.
  const Eigen::Vector2f c = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f::Zero());
  EXPECT_NEAR(c.x(), kWidth / 2.0f, 1e-3f);
  EXPECT_NEAR(c.y(), kHeight / 2.0f, 1e-3f);

  // Written as a PNG that reads back to the same pixels.
  const std::string path = temp_path("surgsim_renderer_sphere.png");
  write_png(path, image);
  const Image back = read_png(path);
  EXPECT_EQ(back.width, kWidth);
  EXPECT_EQ(back.height, kHeight);
  EXPECT_TRUE(back.rgb == image.rgb);
}

TEST(OsMesaRenderer, ShadingFollowsTheKeyLight) {
  // The key light comes from the viewer's upper left: that side of the sphere is brighter than the lower right.
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const Image image = render_surface(*renderer, icosphere(3, 1.0f));
  const Eigen::Vector2f c = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f::Zero());
  const Eigen::Vector2f edge = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f(0, 0, 1));
  const float r_px = c.y() - edge.y();  // projected radius, about
  auto brightness = [&](float dx, float dy) {
    const std::uint8_t* p = image.at(static_cast<int>(c.x() + dx * r_px), static_cast<int>(c.y() + dy * r_px));
    return static_cast<int>(p[0]) + p[1] + p[2];
  };
  const int upper_left = brightness(-0.4f, -0.5f);
  const int lower_right = brightness(0.5f, 0.5f);
  EXPECT_GT(upper_left, lower_right + 60) << "upper left " << upper_left << ", lower right " << lower_right;

  // Not a flat silhouette: the red channel spans a wide range over the sphere.
  int lo = 255, hi = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      if (is_background(image, x, y)) continue;
      lo = std::min<int>(lo, image.at(x, y)[0]);
      hi = std::max<int>(hi, image.at(x, y)[0]);
    }
  }
  EXPECT_GT(hi - lo, 80);
}

TEST(OsMesaRenderer, DentChangesPixelsNearItOnly) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  Surface sphere = icosphere(3, 1.0f);
  const Image before = render_surface(*renderer, sphere);

  // Push a cap of vertices (within 20 degrees of a direction on the visible side) inwards.
  const Eigen::Vector3f dent_dir = Eigen::Vector3f(0.45f, -1.0f, 0.4f).normalized();
  int moved = 0;
  for (Eigen::Index v = 0; v < sphere.positions.rows(); ++v) {
    const Eigen::Vector3f p = sphere.positions.row(v).transpose();
    const float cos_angle = p.normalized().dot(dent_dir);
    if (cos_angle > std::cos(20.0f * 3.14159265f / 180.0f)) {
      sphere.positions.row(v) *= 0.75f;
      ++moved;
    }
  }
  ASSERT_GT(moved, 3);
  const Image after = render_surface(*renderer, sphere);

  const Eigen::Vector2f dent_px = project_to_pixel(front_camera(), kWidth, kHeight, dent_dir);
  const Eigen::Vector2f c = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f::Zero());
  const Eigen::Vector2f edge = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f(0, 0, 1));
  const float r_px = c.y() - edge.y();
  int changed_near = 0, changed_far = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const bool changed = !std::equal(before.at(x, y), before.at(x, y) + 3, after.at(x, y));
      const float d = (Eigen::Vector2f(x + 0.5f, y + 0.5f) - dent_px).norm();
      if (d < 0.2f * r_px) changed_near += changed ? 1 : 0;
      // The cap plus one ring of neighbours (whose normals change) spans well under one sphere radius.
      if (d > r_px) changed_far += changed ? 1 : 0;
    }
  }
  EXPECT_GT(changed_near, 50);
  EXPECT_EQ(changed_far, 0);
}

TEST(OsMesaRenderer, ToolShaftAndJawsAreDrawn) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  ToolGeometry tool{};
  tool.trocar = {-1.2, 0.0, 1.0};
  tool.tip = {0.3, 0.0, -0.2};
  tool.direction = (tool.tip - tool.trocar).normalized();
  tool.jaw_normal = {0, -1, 0};
  const Eigen::Vector3d side = tool.direction.cross(tool.jaw_normal).normalized();
  tool.jaw_tips[0] = tool.tip + 0.25 * (tool.direction + 0.5 * side).normalized();
  tool.jaw_tips[1] = tool.tip + 0.25 * (tool.direction - 0.5 * side).normalized();

  const Camera camera = front_camera();
  renderer->begin_frame(camera);
  renderer->draw_tool(tool, 0.05f);
  renderer->end_frame();
  Image image;
  ASSERT_TRUE(renderer->read_image(image));
  EXPECT_EQ(renderer->counts().tools, 1u);

  const Eigen::Vector2f a = project_to_pixel(camera, kWidth, kHeight, tool.trocar.cast<float>());
  const Eigen::Vector2f b = project_to_pixel(camera, kWidth, kHeight, tool.tip.cast<float>());
  const Eigen::Vector2f normal = Eigen::Vector2f(-(b - a).y(), (b - a).x()).normalized();
  for (float s = 0.1f; s < 0.95f; s += 0.1f) {
    const Eigen::Vector2f q = a + s * (b - a);
    const int x = static_cast<int>(q.x()), y = static_cast<int>(q.y());
    ASSERT_TRUE(x >= 0 && x < kWidth && y >= 0 && y < kHeight);
    EXPECT_FALSE(is_background(image, x, y)) << "shaft at s = " << s;
    const std::uint8_t* p = image.at(x, y);
    EXPECT_LT(std::abs(p[0] - p[2]), 40) << "shaft should be grey at s = " << s;
    const Eigen::Vector2f off = q + 25.0f * normal;  // well beside the shaft (about 10 px wide)
    EXPECT_TRUE(is_background(image, static_cast<int>(off.x()), static_cast<int>(off.y()))) << "beside, s = " << s;
  }
  // Each jaw, halfway along.
  for (const auto& jaw : tool.jaw_tips) {
    const Eigen::Vector2f q = project_to_pixel(camera, kWidth, kHeight, (0.5 * (tool.tip + jaw)).cast<float>());
    EXPECT_FALSE(is_background(image, static_cast<int>(q.x()), static_cast<int>(q.y())));
  }
}

// Several instruments are told apart by colour: two tools side by side, one in instrument 0's colour
// (grey), one in instrument 1's (blue).
TEST(OsMesaRenderer, InstrumentColoursTellToolsApart) {
  // The palette: distinct colours, cycling beyond the fourth instrument.
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) EXPECT_GT((instrument_rgb(i) - instrument_rgb(j)).norm(), 0.2f) << i << " " << j;
    EXPECT_EQ(instrument_rgb(i + 4), instrument_rgb(i));
  }
  EXPECT_EQ(instrument_rgb(-1), instrument_rgb(0));

  const auto tool_at = [](double x) {
    ToolGeometry t{};
    t.trocar = {x, 0.0, 1.2};
    t.tip = {x, 0.0, -0.4};
    t.direction = {0, 0, -1};
    t.jaw_normal = {0, -1, 0};
    t.jaw_tips = {t.tip + Eigen::Vector3d(0.1, 0, -0.2), t.tip + Eigen::Vector3d(-0.1, 0, -0.2)};
    return t;
  };
  const ToolGeometry left = tool_at(-0.6), right = tool_at(0.6);
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  renderer->begin_frame(front_camera());
  renderer->draw_tool(left, 0.06f, instrument_rgb(0));
  renderer->draw_tool(right, 0.06f, instrument_rgb(1));
  renderer->end_frame();
  Image image;
  ASSERT_TRUE(renderer->read_image(image));
  EXPECT_EQ(renderer->counts().tools, 2u);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  // Across each shaft, halfway along it: how many pixels are drawn, and how many of them are grey or blue.
  const auto across = [&](const ToolGeometry& t, int& drawn, int& grey, int& blue) {
    drawn = grey = blue = 0;
    const Eigen::Vector3f middle = (0.5 * (t.trocar + t.tip)).cast<float>();
    const Eigen::Vector2f c = project_to_pixel(front_camera(), kWidth, kHeight, middle);
    for (int dx = -12; dx <= 12; ++dx) {
      const int x = static_cast<int>(c.x()) + dx, y = static_cast<int>(c.y());
      if (is_background(image, x, y)) continue;
      const std::uint8_t* p = image.at(x, y);
      ++drawn;
      grey += std::abs(p[0] - p[2]) < 40 ? 1 : 0;
      blue += p[2] > p[0] + 60 ? 1 : 0;
    }
  };
  int drawn = 0, grey = 0, blue = 0;
  across(left, drawn, grey, blue);
  EXPECT_GT(drawn, 4) << "instrument 0's shaft";
  EXPECT_EQ(grey, drawn) << "instrument 0 is grey";
  across(right, drawn, grey, blue);
  EXPECT_GT(drawn, 4) << "instrument 1's shaft";
  EXPECT_GE(blue, drawn - 1) << "instrument 1 is blue (" << blue << " of " << drawn << " pixels)";
}

TEST(OsMesaRenderer, PointsAreDrawnAsMarkers) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  Eigen::MatrixX3f points(2, 3);
  points << -0.8f, 0.0f, 0.3f, 0.7f, 0.0f, -0.5f;
  renderer->begin_frame(front_camera());
  renderer->draw_points(points, 0.06f, kMarkerRgb);
  renderer->end_frame();
  Image image;
  ASSERT_TRUE(renderer->read_image(image));
  EXPECT_EQ(renderer->counts().points, 2u);
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector2f q = project_to_pixel(front_camera(), kWidth, kHeight, points.row(i).transpose());
    const std::uint8_t* p = image.at(static_cast<int>(q.x()), static_cast<int>(q.y()));
    EXPECT_GT(p[0], p[2] + 60) << "marker " << i << " should be yellow";
    EXPECT_GT(p[1], p[2] + 60) << "marker " << i << " should be yellow";
  }
  EXPECT_LT(foreground_fraction(image), 0.05);
}

TEST(OsMesaRenderer, DeterministicAcrossFramesAndInstances) {
  const Surface sphere = icosphere(3, 1.0f);
  auto first = make_renderer("osmesa", kWidth, kHeight);
  auto second = make_renderer("osmesa", kWidth, kHeight);
  // Interleaved use: each renderer makes its own context current.
  const Image a1 = render_surface(*first, sphere);
  const Image b1 = render_surface(*second, sphere);
  const Image a2 = render_surface(*first, sphere);
  // The pictures show the organ (two empty pictures would be identical too): the sphere covers a good part of each,
  // and the centre is its red-brown.
  for (const Image* image : {&a1, &b1, &a2}) {
    ASSERT_EQ(image->width, kWidth);
    ASSERT_EQ(image->height, kHeight);
    ASSERT_GT(foreground_fraction(*image), 0.2);
    const std::uint8_t* centre = image->at(kWidth / 2, kHeight / 2);
    ASSERT_GT(centre[0], centre[1] + 40) << "centre should be the organ's red-brown";
  }
  EXPECT_TRUE(a1.rgb == a2.rgb);
  EXPECT_TRUE(a1.rgb == b1.rgb);
}

TEST(OsMesaRenderer, MeshSizeChangesReuseBuffers) {
  // Small -> large -> small through the same surface slot: buffers grow once, then are updated in place.
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const Surface coarse = icosphere(1, 1.0f);
  const Surface fine = icosphere(3, 1.0f);
  const Image c1 = render_surface(*renderer, coarse);
  const Image f1 = render_surface(*renderer, fine);
  const Image c2 = render_surface(*renderer, coarse);
  EXPECT_FALSE(c1.rgb == f1.rgb);
  EXPECT_TRUE(c1.rgb == c2.rgb);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);

  // Two surfaces in one frame use two slots: a second sphere beside the first.
  Surface small = icosphere(2, 0.3f);
  small.positions.col(0).array() += 1.4f;
  renderer->begin_frame(front_camera());
  renderer->draw_surface(fine.positions, fine.tris, kLiverRgb);
  renderer->draw_surface(small.positions, small.tris, Eigen::Vector3f(0.3f, 0.5f, 0.8f));
  renderer->end_frame();
  Image two;
  ASSERT_TRUE(renderer->read_image(two));
  const Eigen::Vector2f q = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f(1.4f, -0.3f, 0.0f));
  const std::uint8_t* p = two.at(static_cast<int>(q.x()), static_cast<int>(q.y()));
  EXPECT_GT(p[2], p[0]) << "the second surface is blue";
  EXPECT_EQ(renderer->counts().surfaces, 5u);
}

TEST(OsMesaRenderer, BadInputIsSkippedAndCounted) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  Surface sphere = icosphere(1, 1.0f);
  Surface bad_index = sphere;
  bad_index.tris(3, 1) = static_cast<int>(sphere.positions.rows());
  Surface bad_position = sphere;
  bad_position.positions(0, 2) = std::nanf("");
  ToolGeometry bad_tool{};
  bad_tool.trocar = {0, 0, 1};
  bad_tool.tip = {0, 0, std::nan("")};
  bad_tool.jaw_tips = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};

  renderer->begin_frame(front_camera());
  renderer->draw_surface(bad_index.positions, bad_index.tris, kLiverRgb);
  renderer->draw_surface(bad_position.positions, bad_position.tris, kLiverRgb);
  renderer->draw_tool(bad_tool, 0.05f);
  renderer->end_frame();
  Image image;
  ASSERT_TRUE(renderer->read_image(image));
  EXPECT_EQ(renderer->counts().rejected, 3u);
  EXPECT_EQ(renderer->counts().surfaces, 0u);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  EXPECT_EQ(foreground_fraction(image), 0.0);
}

// A curved membrane for draw_membrane: a coarse rows x cols grid on a cylinder about z (radius 1, facing the front
// camera at -y, u around it over 2.4 rad, v down it), refined and given normals by intestine::MesenterySurface as the
// intestine view does with the mass-spring grid.
intestine::MesenterySurface curved_membrane(int rows = 4, int cols = 8) {
  std::vector<double> grid;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const double phi = -1.2 + 2.4 * c / (cols - 1);
      grid.insert(grid.end(), {std::sin(phi), -std::cos(phi), 0.6 - 1.2 * r / (rows - 1)});
    }
  }
  intestine::MesenterySurface s = intestine::make_mesentery_surface(rows, cols, 3, 4);
  EXPECT_TRUE(intestine::mesentery_surface(grid.data(), s));
  return s;
}

int grey(const Image& image, int x, int y) {
  const std::uint8_t* p = image.at(x, y);
  return static_cast<int>(p[0]) + p[1] + p[2];
}

Image render_membrane(Renderer& renderer, const intestine::MesenterySurface& s, const MembraneLook& look,
                      const Camera& camera = front_camera()) {
  renderer.begin_frame(camera);
  renderer.draw_membrane(s, look);
  renderer.end_frame();
  Image image;
  EXPECT_TRUE(renderer.read_image(image));
  return image;
}

// The mesentery is shaded, not one flat colour: across a curved sheet seen from the front its intensity changes a
// lot from one side to the other, and smoothly (no step between adjacent pixels as between facets of the coarse
// grid, whose intervals turn the normal by 0.34 rad); seen from behind it is lit too.
TEST(OsMesaRenderer, MembraneIsShadedSmoothlyOnBothSides) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const intestine::MesenterySurface sheet = curved_membrane();
  MembraneLook look;
  look.vessels = 0.0f;  // the shading alone
  look.alpha = 1.0f;
  const Image front = render_membrane(*renderer, sheet, look);
  EXPECT_EQ(renderer->counts().surfaces, 1u);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  EXPECT_GT(foreground_fraction(front), 0.15);
  // Along the middle row, from the sheet's left edge to its right edge (a few pixels in from the silhouette).
  const int y = kHeight / 2;
  int x0 = 0, x1 = kWidth - 1;
  while (x0 < kWidth && is_background(front, x0, y)) ++x0;
  while (x1 > 0 && is_background(front, x1, y)) --x1;
  ASSERT_GT(x1 - x0, kWidth / 3);
  int lo = 765, hi = 0, step = 0;
  for (int x = x0 + 3; x <= x1 - 3; ++x) {
    lo = std::min(lo, grey(front, x, y));
    hi = std::max(hi, grey(front, x, y));
    if (x > x0 + 3) step = std::max(step, std::abs(grey(front, x, y) - grey(front, x - 1, y)));
  }
  std::printf("membrane across the middle row: grey %d..%d, largest step between adjacent pixels %d\n", lo, hi, step);
  EXPECT_GT(hi - lo, 90) << "lit by the key light: bright on one side, darker on the other";
  EXPECT_LE(step, 12) << "smooth: no facet edge between adjacent pixels (range " << lo << ".." << hi << ")";
  // The inside of the sheet, from behind: lit as well (both sides), not black.
  Camera back = front_camera();
  back.eye = {0, 4, 0};
  const Image behind = render_membrane(*renderer, sheet, look, back);
  double sum = 0;
  int n = 0;
  for (int x = 0; x < kWidth; ++x) {
    if (is_background(behind, x, y)) continue;
    sum += grey(behind, x, y);
    ++n;
  }
  ASSERT_GT(n, kWidth / 3);
  EXPECT_GT(sum / n, 150.0) << "the far side is lit too";
}

// With its vessels the membrane has dark red lines over the fat (the root vessel along v = 1, the bottom edge here);
// translucent, it lets a surface behind it show through; the backdrop is a vignette behind everything.
TEST(OsMesaRenderer, MembraneVesselsTranslucencyAndBackdrop) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const intestine::MesenterySurface sheet = curved_membrane();
  MembraneLook look;
  look.alpha = 1.0f;
  look.vessels = 0.0f;
  const Image plain = render_membrane(*renderer, sheet, look);
  look.vessels = 1.0f;
  const Image veined = render_membrane(*renderer, sheet, look);
  // The root vessel: just above the sheet's bottom edge at the centre column, redder than the fat there.
  const Eigen::Vector2f root = project_to_pixel(front_camera(), kWidth, kHeight, Eigen::Vector3f(0.0f, -1.0f, -0.58f));
  const std::uint8_t* v = veined.at(static_cast<int>(root.x()), static_cast<int>(root.y()));
  const std::uint8_t* f = plain.at(static_cast<int>(root.x()), static_cast<int>(root.y()));
  std::printf("root vessel pixel %d %d %d, fat there %d %d %d\n", v[0], v[1], v[2], f[0], f[1], f[2]);
  EXPECT_GT(f[1], v[1] + 40) << "the vessel is darker in green than the fat";
  EXPECT_GT(v[0], v[1] + 40) << "and red";
  int changed = 0;
  for (std::size_t i = 0; i < plain.rgb.size(); i += 3) changed += plain.rgb[i + 1] != veined.rgb[i + 1] ? 1 : 0;
  EXPECT_GT(changed, static_cast<int>(plain.rgb.size() / 3) / 50) << "branches and arcades over the sheet";

  // An opaque blue sphere behind the sheet's middle: seen through the translucent membrane, not through an opaque one.
  Surface ball = icosphere(2, 0.3f);
  ball.positions.col(1).array() += 0.2f;  // behind the sheet (which bulges towards -y, the camera)
  const auto with_ball = [&](float alpha) {
    renderer->begin_frame(front_camera());
    renderer->draw_surface(ball.positions, ball.tris, Eigen::Vector3f(0.2f, 0.3f, 0.9f));
    MembraneLook l;
    l.vessels = 0.0f;
    l.alpha = alpha;
    renderer->draw_membrane(sheet, l);
    renderer->end_frame();
    Image image;
    EXPECT_TRUE(renderer->read_image(image));
    return image;
  };
  const Image opaque = with_ball(1.0f), translucent = with_ball(0.8f);
  const std::uint8_t* o = opaque.at(kWidth / 2, kHeight / 2);
  const std::uint8_t* t = translucent.at(kWidth / 2, kHeight / 2);
  std::printf("behind an opaque membrane %d %d %d, a translucent one %d %d %d\n", o[0], o[1], o[2], t[0], t[1], t[2]);
  EXPECT_GT(static_cast<int>(t[2]) - t[0], static_cast<int>(o[2]) - o[0] + 20) << "bluer where the ball shows through";

  // The backdrop: brighter and redder in the middle than in the corners, drawn wherever nothing else is.
  renderer->begin_frame(front_camera());
  renderer->draw_backdrop(Eigen::Vector3f(0.30f, 0.13f, 0.11f), Eigen::Vector3f(0.05f, 0.025f, 0.025f));
  renderer->end_frame();
  Image backdrop;
  ASSERT_TRUE(renderer->read_image(backdrop));
  EXPECT_DOUBLE_EQ(foreground_fraction(backdrop), 1.0);
  const std::uint8_t* mid = backdrop.at(kWidth / 2, kHeight / 2);
  EXPECT_GT(mid[0], mid[2] + 20);
  EXPECT_GT(grey(backdrop, kWidth / 2, kHeight / 2), grey(backdrop, 0, 0) + 60);
  EXPECT_EQ(renderer->counts().rejected, 0u);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
}

// The scope's light is at the eye and falls off with distance: the same sphere nearer is brighter in the middle; its
// wet highlight is where the normal faces the eye (the centre), not where the studio key puts it.
TEST(OsMesaRenderer, ScopeLightFallsOffWithDistanceAndHighlightsTheCentre) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  Lighting scope;
  scope.scope = true;
  scope.falloff = Eigen::Vector3f(0.2f, 0.0f, 0.1f);  // d in m: 1/0.3 at 1 m, 1/1.8 at 4 m
  renderer->set_lighting(scope);
  const Surface sphere = icosphere(3, 1.0f);
  Camera near = front_camera();
  near.eye = {0, -2, 0};
  const Image far_image = render_surface(*renderer, sphere);
  const Image near_image = render_surface(*renderer, sphere, near);
  const int far_centre = grey(far_image, kWidth / 2, kHeight / 2),
            near_centre = grey(near_image, kWidth / 2, kHeight / 2);
  std::printf("scope light: centre grey %d at 3 m from the surface, %d at 1 m\n", far_centre, near_centre);
  EXPECT_GT(near_centre, far_centre + 60);
  // The highlight: the centre (normal towards the eye) is the brightest point of the far sphere.
  int brightest = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x)
      brightest = std::max(brightest, is_background(far_image, x, y) ? 0 : grey(far_image, x, y));
  }
  EXPECT_GE(far_centre + 6, brightest);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
}

// A per-vertex tint changes the surface's colour where it is given, and an id picture is one exact flat colour per
// draw call: no lighting, tint, vessels, blending or backdrop.
TEST(OsMesaRenderer, TintColoursVerticesAndIdPicturesAreFlat) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const Surface sphere = icosphere(3, 1.0f);
  Eigen::MatrixX3f tint = Eigen::MatrixX3f::Ones(sphere.positions.rows(), 3);
  for (Eigen::Index v = 0; v < tint.rows(); ++v) {
    if (sphere.positions(v, 0) > 0.0f) tint.row(v) = Eigen::RowVector3f(0.3f, 1.6f, 0.3f);  // the right half green
  }
  renderer->begin_frame(front_camera());
  renderer->draw_surface(sphere.positions, sphere.tris, SurfaceLook{Eigen::Vector3f(0.5f, 0.5f, 0.5f)}, &tint);
  renderer->end_frame();
  Image tinted;
  ASSERT_TRUE(renderer->read_image(tinted));
  const std::uint8_t* left = tinted.at(kWidth / 2 - 30, kHeight / 2);
  const std::uint8_t* right = tinted.at(kWidth / 2 + 30, kHeight / 2);
  EXPECT_LT(std::abs(static_cast<int>(left[0]) - left[1]), 8) << "grey where the tint is 1";
  EXPECT_GT(right[1], right[0] + 60) << "green where it is green";
  Eigen::MatrixX3f short_tint = Eigen::MatrixX3f::Ones(3, 3);
  renderer->draw_surface(sphere.positions, sphere.tris, SurfaceLook{}, &short_tint);
  EXPECT_EQ(renderer->counts().rejected, 1u) << "a tint of another vertex count is refused";

  // Id picture: the sphere, a translucent membrane over it and the backdrop; exactly two colours and the background.
  const Eigen::Vector3f red(200 / 255.0f, 10 / 255.0f, 20 / 255.0f), blue(5 / 255.0f, 30 / 255.0f, 250 / 255.0f);
  renderer->begin_frame(front_camera());
  renderer->set_id_colour(red);
  renderer->draw_surface(sphere.positions, sphere.tris, SurfaceLook{}, &tint);
  renderer->set_id_colour(blue);
  MembraneLook look;
  look.alpha = 0.5f;
  renderer->draw_membrane(curved_membrane(), look);
  renderer->draw_backdrop(Eigen::Vector3f(0.3f, 0.1f, 0.1f), Eigen::Vector3f(0.1f, 0.0f, 0.0f));
  renderer->clear_id_colour();
  renderer->end_frame();
  Image ids;
  ASSERT_TRUE(renderer->read_image(ids));
  int n_red = 0, n_blue = 0, n_background = 0, other = 0;
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const std::uint8_t* p = ids.at(x, y);
      if (p[0] == 200 && p[1] == 10 && p[2] == 20) {
        ++n_red;
      } else if (p[0] == 5 && p[1] == 30 && p[2] == 250) {
        ++n_blue;
      } else if (is_background(ids, x, y)) {
        ++n_background;
      } else {
        ++other;
      }
    }
  }
  std::printf("id picture: %d sphere, %d membrane, %d background, %d other pixels\n", n_red, n_blue, n_background,
              other);
  EXPECT_EQ(other, 0);
  EXPECT_GT(n_red, 1000);
  EXPECT_GT(n_blue, 1000);
  EXPECT_GT(n_background, 1000) << "no backdrop in an id picture";
}

// Dynamic resolution: at half scale the frame is drawn into a quarter of the pixels and read back at full size, the
// same picture at a lower resolution; back at scale 1 the picture is bit for bit the one drawn before any scaling.
TEST(OsMesaRenderer, RenderScaleDrawsFewerPixelsAndReadsBackFullSize) {
  auto renderer = make_renderer("osmesa", kWidth, kHeight);
  const Surface sphere = icosphere(3, 1.0f);
  const Image full = render_surface(*renderer, sphere);

  renderer->set_render_scale(0.5f);
  EXPECT_EQ(renderer->render_width(), kWidth / 2);
  EXPECT_EQ(renderer->render_height(), kHeight / 2);
  const Image half = render_surface(*renderer, sphere);
  ASSERT_EQ(half.width, kWidth);
  ASSERT_EQ(half.height, kHeight);
  EXPECT_EQ(renderer->counts().gl_errors, 0u);
  EXPECT_FALSE(half.rgb == full.rgb) << "drawn at another resolution";
  Image drawn;
  ASSERT_TRUE(renderer->read_drawn_image(drawn));
  EXPECT_EQ(drawn.width, kWidth / 2) << "the pixels drawn, not scaled up";
  EXPECT_EQ(drawn.height, kHeight / 2);
  Image up;
  resize_bilinear(drawn, kWidth, kHeight, up);
  EXPECT_TRUE(up.rgb == half.rgb) << "read_image is the drawn pixels scaled up";
  // The same sphere, centred, the same size: its area and centroid agree within a pixel or two of the half image.
  auto outline = [](const Image& image, double& cx, double& cy) {
    double n = 0, sx = 0, sy = 0;
    for (int y = 0; y < image.height; ++y) {
      for (int x = 0; x < image.width; ++x) {
        if (is_background(image, x, y)) continue;
        n += 1;
        sx += x;
        sy += y;
      }
    }
    cx = sx / n;
    cy = sy / n;
    return n / (image.width * image.height);
  };
  double fx = 0, fy = 0, hx = 0, hy = 0;
  const double f_full = outline(full, fx, fy), f_half = outline(half, hx, hy);
  std::printf("sphere: %.4f of the picture at full size, %.4f at half scale; centroid (%.2f, %.2f) / (%.2f, %.2f)\n",
              f_full, f_half, fx, fy, hx, hy);
  EXPECT_NEAR(f_half, f_full, 0.02);
  EXPECT_NEAR(hx, fx, 1.5);
  EXPECT_NEAR(hy, fy, 1.5);
  long diff = 0;
  for (std::size_t i = 0; i < full.rgb.size(); ++i) diff += std::abs(static_cast<int>(full.rgb[i]) - half.rgb[i]);
  const double mean_diff = static_cast<double>(diff) / static_cast<double>(full.rgb.size());
  std::printf("mean absolute difference: %.2f levels\n", mean_diff);
  EXPECT_LT(mean_diff, 6.0);

  renderer->set_render_scale(1.0f);
  const Image again = render_surface(*renderer, sphere);
  EXPECT_TRUE(again.rgb == full.rgb) << "full size again: the viewport and scissor restored";
  ASSERT_TRUE(renderer->read_drawn_image(drawn));
  EXPECT_TRUE(drawn.rgb == full.rgb) << "at scale 1 the drawn pixels are the picture";
  renderer->set_render_scale(0.6f);
  EXPECT_EQ(renderer->render_width(), 192) << "a multiple of 8 pixels";
  EXPECT_EQ(renderer->render_height(), 144);

  renderer->set_render_scale(0.01f);
  EXPECT_EQ(renderer->render_scale(), Renderer::kMinRenderScale) << "clamped";
  renderer->set_render_scale(std::nanf(""));
  EXPECT_EQ(renderer->render_scale(), Renderer::kMinRenderScale) << "a NaN is ignored";
}

TEST(NullRenderer, CountsAndHasNoImage) {
  auto renderer = make_renderer("null", 640, 480);
  EXPECT_STREQ(renderer->name(), "null");
  Image image;
  EXPECT_FALSE(renderer->read_image(image));
  const Surface sphere = icosphere(1, 1.0f);
  ToolGeometry tool{};
  tool.trocar = {0, 0, 1};
  tool.tip = {0, 0, 0};
  tool.jaw_tips = {Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  Eigen::MatrixX3f points = Eigen::MatrixX3f::Zero(3, 3);
  for (int frame = 0; frame < 2; ++frame) {
    renderer->begin_frame(front_camera());
    renderer->draw_surface(sphere.positions, sphere.tris, kLiverRgb);
    renderer->draw_tool(tool, 0.01f);
    renderer->draw_points(points, 0.01f, kMarkerRgb);
    renderer->end_frame();
  }
  EXPECT_FALSE(renderer->read_image(image));
  EXPECT_EQ(renderer->counts().frames, 2u);
  EXPECT_EQ(renderer->counts().surfaces, 2u);
  EXPECT_EQ(renderer->counts().tools, 2u);
  EXPECT_EQ(renderer->counts().points, 6u);
  EXPECT_EQ(renderer->counts().rejected, 0u);
  // A tool in another instrument's colour counts as a tool; a non-finite colour is rejected.
  renderer->draw_tool(tool, 0.01f, instrument_rgb(1));
  EXPECT_EQ(renderer->counts().tools, 3u);
  renderer->draw_tool(tool, 0.01f, Eigen::Vector3f(std::nanf(""), 0.0f, 0.0f));
  EXPECT_EQ(renderer->counts().tools, 3u);
  EXPECT_EQ(renderer->counts().rejected, 1u);
  // A membrane counts as a surface, the backdrop as nothing; a membrane with a bad index or value is rejected.
  intestine::MesenterySurface sheet = intestine::make_mesentery_surface(3, 4, 2, 2);
  renderer->draw_membrane(sheet, MembraneLook{});
  renderer->draw_backdrop(Eigen::Vector3f::Zero(), Eigen::Vector3f::Ones());
  EXPECT_EQ(renderer->counts().surfaces, 3u);
  sheet.indices[4] = static_cast<std::uint32_t>(sheet.vertex_count);
  renderer->draw_membrane(sheet, MembraneLook{});
  sheet.indices[4] = 0;
  sheet.normals[7] = std::nanf("");
  renderer->draw_membrane(sheet, MembraneLook{});
  EXPECT_EQ(renderer->counts().surfaces, 3u);
  EXPECT_EQ(renderer->counts().rejected, 3u);
}

TEST(MakeRenderer, RefusesUnknownBackendAndBadSize) {
  try {
    make_renderer("vulkan", 64, 64);
    FAIL() << "expected surgsim::core::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("vulkan"), std::string::npos) << e.what();
  }
  EXPECT_THROW(make_renderer("null", 0, 64), Error);
  EXPECT_THROW(make_renderer("osmesa", 64, 100000), Error);
}

TEST(WritePng, UnwritablePathThrowsNamingIt) {
  Image image;
  image.resize(8, 8);
  const std::string path = "/nonexistent-surgsim-dir/frame.png";
  try {
    write_png(path, image);
    FAIL() << "expected surgsim::core::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  Image malformed;
  malformed.width = 4;
  malformed.height = 4;  // no pixels
  EXPECT_THROW(write_png(temp_path("surgsim_malformed.png"), malformed), Error);
}

TEST(WritePng, HeaderAndPixelsReadBack) {
  Image image;
  image.resize(37, 11);  // odd width: rows are not 4-byte aligned
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      std::uint8_t* p = image.at(x, y);
      p[0] = static_cast<std::uint8_t>(7 * x);
      p[1] = static_cast<std::uint8_t>(23 * y);
      p[2] = static_cast<std::uint8_t>(x * y);
    }
  }
  const std::string path = temp_path("surgsim_gradient.png");
  write_png(path, image);

  // The signature, then IHDR with big-endian width and height, 8-bit RGB (colour type 2).
  std::ifstream in(path, std::ios::binary);
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 33u);
  const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  EXPECT_TRUE(std::equal(signature, signature + 8, bytes.begin()));
  EXPECT_EQ(std::string(bytes.begin() + 12, bytes.begin() + 16), "IHDR");
  auto be32 = [&](int at) { return (bytes[at] << 24) | (bytes[at + 1] << 16) | (bytes[at + 2] << 8) | bytes[at + 3]; };
  EXPECT_EQ(be32(16), 37);
  EXPECT_EQ(be32(20), 11);
  EXPECT_EQ(bytes[24], 8);
  EXPECT_EQ(bytes[25], 2);

  const Image back = read_png(path);
  EXPECT_EQ(back.width, 37);
  EXPECT_EQ(back.height, 11);
  EXPECT_TRUE(back.rgb == image.rgb);
  EXPECT_THROW(read_png(temp_path("surgsim_no_such_file.png")), Error);
}

TEST(VertexNormals, SphereNormalsPointOutwards) {
  const Surface sphere = icosphere(2, 2.0f);
  Eigen::MatrixX3f normals(sphere.positions.rows(), 3);
  vertex_normals(sphere.positions, sphere.tris, normals);
  ASSERT_EQ(normals.rows(), sphere.positions.rows());
  for (Eigen::Index v = 0; v < normals.rows(); ++v) {
    EXPECT_NEAR(normals.row(v).norm(), 1.0f, 1e-5f);
    EXPECT_GT(normals.row(v).dot(sphere.positions.row(v).normalized()), 0.99f);
  }
}

TEST(VertexNormals, WritesIntoAnInterleavedBuffer) {
  // The OSMesa backend writes normals straight into its x y z nx ny nz buffer: same values as a plain matrix.
  const Surface sphere = icosphere(1, 1.0f);
  const Eigen::Index nv = sphere.positions.rows();
  Eigen::MatrixX3f plain(nv, 3);
  vertex_normals(sphere.positions, sphere.tris, plain);
  std::vector<float> interleaved(static_cast<std::size_t>(6 * nv), -7.0f);
  using Strided = Eigen::Map<Eigen::MatrixX3f, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;
  vertex_normals(sphere.positions, sphere.tris,
                 Strided(interleaved.data() + 3, nv, 3, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(1, 6)));
  for (Eigen::Index v = 0; v < nv; ++v) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(interleaved[6 * v + 3 + k], plain(v, k));
      EXPECT_EQ(interleaved[6 * v + k], -7.0f) << "positions' slots untouched";
    }
  }
}

TEST(VertexNormals, WeightedByFaceArea) {
  // Vertex 0 is shared by a large face in the xy plane (area 8, normal +z) and a small one in the xz plane
  // (area 0.5, normal -y): its normal is (0, -0.5, 8) normalized. Vertex 5 is in no face.
  Eigen::MatrixX3f p(6, 3);
  p << 0, 0, 0,  4, 0, 0,  0, 4, 0,  1, 0, 0,  0, 0, 1,  9, 9, 9;
  Eigen::MatrixX3i t(2, 3);
  t << 0, 1, 2,  0, 3, 4;
  Eigen::MatrixX3f normals(p.rows(), 3);
  vertex_normals(p, t, normals);
  const Eigen::RowVector3f expected = Eigen::RowVector3f(0.0f, -0.5f, 8.0f).normalized();
  EXPECT_LT((normals.row(0) - expected).norm(), 1e-6f);
  EXPECT_LT((normals.row(1) - Eigen::RowVector3f(0, 0, 1)).norm(), 1e-6f);
  EXPECT_LT((normals.row(3) - Eigen::RowVector3f(0, -1, 0)).norm(), 1e-6f);
  EXPECT_LT((normals.row(5) - Eigen::RowVector3f(0, 0, 1)).norm(), 1e-6f);
}

}  // namespace
}  // namespace surgsim
