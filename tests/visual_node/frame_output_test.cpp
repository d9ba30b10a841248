// FrameOutput without a renderer: PNGs of given images, the frames.csv index, VTK beside each PNG through the organ,
// failures counted without stopping, nothing at all when headless.
#include "frame_output.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <iterator>
#include <thread>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/error.h"
#include "organ_view.h"

using namespace surgsim::core;
using namespace surgsim::mesh;

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
    out.flush();
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
  out.flush();
  EXPECT_EQ(out.png_errors(), 2u);
  EXPECT_EQ(out.pngs_written(), 0u);
  out.write(small_image(), 3, 3, 0.0, organ, 1);
  out.flush();
  EXPECT_EQ(out.pngs_written(), 1u);
  EXPECT_EQ(read_text(o.out + "/frames.csv"),
            "png,seq,sim_time,contacts,max_displacement_m,instruments\nframe_000003.png,3,0.000000,3,0.004,1\n");
  nlohmann::json j;
  out.add_stats(j);
  EXPECT_EQ(j["first_png"], o.out + "/frame_000003.png");
  fs::remove_all(o.out);
}

// Every frame written to a fresh folder whose first PNG path is a FIFO nobody reads yet: writing it blocks until the
// test opens the other end (a disk that does not answer).
FrameOutputOptions blocked_disk(const std::string& name) {
  FrameOutputOptions o;
  o.out = fresh_dir(name);
  o.png_every = 1;
  std::filesystem::create_directories(o.out);
  EXPECT_EQ(::mkfifo((o.out + "/frame_000001.png").c_str(), 0600), 0);
  return o;
}

// Reads the FIFO to its end (unblocking the writer): the bytes written through it.
std::string read_fifo(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The render loop hands a PNG over and goes on drawing while the disk is slow: here the PNG's path is a FIFO nobody
// reads yet, so writing it blocks until the test opens the other end. write() must return before that (it wrote the
// PNG on the render thread before: a 640 x 480 PNG took about one frame period of the intestine's 30 Hz display).
TEST(FrameOutput, WriteReturnsWhileTheDiskIsBlockedAndNothingIsLost) {
  const FrameOutputOptions o = blocked_disk("fifo");
  FrameOutput out(o);
  const Image image = small_image();
  const FakeOrgan organ(false);
  std::promise<void> returned;
  std::future<void> done = returned.get_future();
  std::thread render([&] {
    out.write(image, 1, 7, 0.25, organ, 1);
    returned.set_value();
  });
  // Generous: the call only copies 384 bytes; before the fix it could not return until the FIFO is read below.
  const bool returned_while_blocked = done.wait_for(std::chrono::seconds(20)) == std::future_status::ready;
  EXPECT_TRUE(returned_while_blocked) << "write() waited for the disk";
  const std::string bytes = read_fifo(o.out + "/frame_000001.png");  // the PNG written through it
  render.join();
  out.write(image, 2, 8, 0.5, organ, 1);  // and the next frame after it, in order
  out.flush();
  EXPECT_EQ(out.pngs_written(), 2u);
  EXPECT_EQ(out.png_errors(), 0u);
  EXPECT_EQ(out.png_waits(), 0u);
  EXPECT_EQ(bytes.substr(1, 3), "PNG");
  EXPECT_EQ(read_png(o.out + "/frame_000002.png").rgb, image.rgb);
  EXPECT_EQ(read_text(o.out + "/frames.csv"),
            "png,seq,sim_time,contacts,max_displacement_m,instruments\n"
            "frame_000001.png,7,0.250000,3,0.004,1\nframe_000002.png,8,0.500000,3,0.004,1\n");
  fs::remove_all(o.out);
}

// More PNGs than slots while the disk is blocked: write() waits for a slot (counted), none is dropped.
TEST(FrameOutput, AFullQueueWaitsForTheDiskInsteadOfDroppingFrames) {
  const FrameOutputOptions o = blocked_disk("full");
  FrameOutput out(o);
  const Image image = small_image();
  const FakeOrgan organ(false);
  const int frames = FrameOutput::kSlots + 2;
  std::atomic<int> handed{0};
  std::thread render([&] {
    for (int f = 1; f <= frames; ++f) {
      out.write(image, static_cast<std::uint64_t>(f), static_cast<std::uint64_t>(f), 0.0, organ, 1);
      handed.fetch_add(1);
    }
  });
  // The writer is stuck on frame 1, so at most kSlots frames can be handed over until the FIFO is read.
  while (handed.load() < FrameOutput::kSlots) std::this_thread::yield();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(handed.load(), FrameOutput::kSlots);
  read_fifo(o.out + "/frame_000001.png");
  render.join();
  out.flush();
  EXPECT_EQ(out.pngs_written(), static_cast<std::uint64_t>(frames));
  EXPECT_GE(out.png_waits(), 1u);
  for (int f = 2; f <= frames; ++f) {
    char name[64];
    std::snprintf(name, sizeof name, "/frame_%06d.png", f);
    EXPECT_EQ(read_png(o.out + name).rgb, image.rgb) << name;
  }
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
