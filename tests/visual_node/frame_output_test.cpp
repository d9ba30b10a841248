// FrameOutput without a renderer: PNGs of given images, the frames.csv index, VTK beside each PNG through the organ,
// failures counted without stopping, nothing at all when headless.
#include "frame_output.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/error.h"
#include "organ_view.h"

namespace surgsim {
namespace {

namespace fs = std::filesystem;

// An organ that reports fixed numbers and writes a small file as its VTK (or has no surface).
class FakeOrgan : public OrganView {
 public:
  explicit FakeOrgan(bool has_surface) : has_surface_(has_surface) {}
  double update(const msg::ContactFrame*, bool) noexcept override { return -1; }
  void draw(Renderer&) const override {}
  int contacts_shown() const override { return 3; }
  double max_displacement() const override { return 0.004; }
  bool write_vtk(const std::string& path) const override {
    if (!has_surface_) return false;
    std::ofstream(path) << "# vtk DataFile Version 3.0\n";
    return true;
  }
  void add_stats(nlohmann::json& j) const override { j["model_built"] = "fake"; }

 private:
  bool has_surface_;
};

std::string fresh_dir(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("surgsim_frame_output_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(p);
  return p.string();
}

Image small_image() {
  Image im;
  im.resize(16, 8);
  for (std::size_t i = 0; i < im.rgb.size(); ++i) im.rgb[i] = static_cast<std::uint8_t>(i % 251);
  return im;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(FrameOutput, HeadlessWritesNothingAndMakesNoFolder) {
  FrameOutputOptions o;
  o.out = fresh_dir("headless");
  o.png_every = 1;
  o.enabled = false;
  FrameOutput out(o);
  EXPECT_FALSE(out.due(1));
  EXPECT_FALSE(fs::exists(o.out));
  out.finish();
  EXPECT_EQ(out.video(), "");
}

TEST(FrameOutput, PngEveryZeroWritesNothing) {
  FrameOutputOptions o;
  o.out = fresh_dir("none");
  o.png_every = 0;
  FrameOutput out(o);
  EXPECT_FALSE(out.due(5));
  EXPECT_FALSE(fs::exists(o.out));
}

TEST(FrameOutput, WritesEveryNthFrameWithItsIndexRowAndVtk) {
  FrameOutputOptions o;
  o.out = fresh_dir("written");
  o.png_every = 2;
  o.vtk = true;
  FrameOutput out(o);
  ASSERT_TRUE(fs::exists(o.out + "/frames.csv"));
  EXPECT_FALSE(out.due(1));
  EXPECT_TRUE(out.due(2));
  EXPECT_FALSE(out.due(3));
  EXPECT_TRUE(out.due(4));

  const FakeOrgan organ(true);
  const Image image = small_image();
  out.write(image, 2, 17, 0.5, organ, 2);  // two instruments drawn
  out.write(image, 4, 18, -1.0, organ, 0);  // before the first frame: none
  out.flush();

  const Image back = read_png(o.out + "/frame_000002.png");
  EXPECT_EQ(back.width, 16);
  EXPECT_EQ(back.height, 8);
  EXPECT_EQ(back.rgb, image.rgb);
  EXPECT_TRUE(fs::exists(o.out + "/frame_000002.vtk"));
  EXPECT_TRUE(fs::exists(o.out + "/frame_000004.vtk"));
  EXPECT_EQ(read_text(o.out + "/frames.csv"),
            "png,seq,sim_time,contacts,max_displacement_m,instruments\n"
            "frame_000002.png,17,0.500000,3,0.004,2\n"
            "frame_000004.png,18,-1.000000,3,0.004,0\n");
  EXPECT_EQ(out.pngs_written(), 2u);
  EXPECT_EQ(out.vtk_written(), 2u);
  EXPECT_EQ(out.png_errors(), 0u);

  nlohmann::json j;
  out.add_stats(j);
  EXPECT_EQ(j["pngs_written"].get<int>(), 2);
  EXPECT_EQ(j["png_errors"].get<int>(), 0);
  EXPECT_EQ(j["vtk_written"].get<int>(), 2);
  EXPECT_EQ(j["video"], "");
  EXPECT_EQ(j["out"], o.out);
  EXPECT_EQ(j["first_png"], o.out + "/frame_000002.png");
  EXPECT_EQ(j["last_png"], o.out + "/frame_000004.png");
  fs::remove_all(o.out);
}

TEST(FrameOutput, NoVtkWhenTheSceneDoesNotAskOrTheOrganHasNoSurface) {
  FrameOutputOptions o;
  o.out = fresh_dir("novtk");
  o.png_every = 1;
  o.vtk = true;
  {
    FrameOutput out(o);
    out.write(small_image(), 1, 1, 0.0, FakeOrgan(false), 1);  // the organ has no surface (e.g. the intestine)
    EXPECT_EQ(out.pngs_written(), 1u);
    EXPECT_EQ(out.vtk_written(), 0u);
  }
  o.vtk = false;
  {
    FrameOutput out(o);
    out.write(small_image(), 1, 1, 0.0, FakeOrgan(true), 1);
    EXPECT_EQ(out.vtk_written(), 0u);
  }
  EXPECT_FALSE(fs::exists(o.out + "/frame_000001.vtk"));
  fs::remove_all(o.out);
}

TEST(FrameOutput, AFailedWriteIsCountedAndTheNextOneStillWrites) {
  FrameOutputOptions o;
  o.out = fresh_dir("failing");
  o.png_every = 1;
  FrameOutput out(o);
  // A folder where the PNG should go: the write fails like on a full disk.
  fs::create_directories(o.out + "/frame_000001.png");
  fs::create_directories(o.out + "/frame_000002.png");
  const FakeOrgan organ(true);
  EXPECT_NO_THROW(out.write(small_image(), 1, 1, 0.0, organ, 1));
  EXPECT_NO_THROW(out.write(small_image(), 2, 2, 0.0, organ, 1));
  EXPECT_EQ(out.png_errors(), 2u);
  EXPECT_EQ(out.pngs_written(), 0u);
  out.write(small_image(), 3, 3, 0.0, organ, 1);
  EXPECT_EQ(out.pngs_written(), 1u);
  out.flush();
  EXPECT_EQ(read_text(o.out + "/frames.csv"),
            "png,seq,sim_time,contacts,max_displacement_m,instruments\nframe_000003.png,3,0.000000,3,0.004,1\n");
  nlohmann::json j;
  out.add_stats(j);
  EXPECT_EQ(j["first_png"], o.out + "/frame_000003.png");
  fs::remove_all(o.out);
}

TEST(FrameOutput, AnUncreatableFolderIsAnError) {
  const std::string file = fresh_dir("blocker");
  std::ofstream(file) << "not a folder\n";
  FrameOutputOptions o;
  o.out = file + "/frames";
  o.png_every = 1;
  EXPECT_THROW(FrameOutput out(o), Error);
  fs::remove(file);
}

TEST(FrameOutput, NoVideoFromFewerThanTwoPngs) {
  FrameOutputOptions o;
  o.out = fresh_dir("video");
  o.png_every = 1;
  o.video = true;
  o.quiet = true;
  FrameOutput out(o);
  out.write(small_image(), 1, 1, 0.0, FakeOrgan(false), 1);
  out.finish();
  EXPECT_EQ(out.video(), "");
  EXPECT_FALSE(fs::exists(o.out + "/video.mp4"));
  fs::remove_all(o.out);
}

}  // namespace
}  // namespace surgsim
