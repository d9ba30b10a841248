// The web view's frame stream: the JPEG round trip, the topic's size bound (a JPEG above it is dropped and
// counted, never cut), a busy encoder drops the picture instead of making the render loop wait, the stamps carried,
// and the scene keys that turn it on (validated, outside the scene hash).
#include "frame_stream.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>
#include <vector>

#include "core/error.h"
#include "scene/scene.h"

using namespace surgsim::core;
using namespace surgsim::scene;

namespace surgsim {
namespace {

// A smooth picture (gradients and a disc), as a rendered organ is.
Image smooth_image(int w, int h) {
  Image im;
  im.resize(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      std::uint8_t* p = im.at(x, y);
      const double dx = x - w / 2.0, dy = y - h / 2.0;
      const bool disc = dx * dx + dy * dy < (h / 3.0) * (h / 3.0);
      p[0] = static_cast<std::uint8_t>(disc ? 200 : 255 * x / w);
      p[1] = static_cast<std::uint8_t>(disc ? 90 : 255 * y / h);
      p[2] = static_cast<std::uint8_t>(disc ? 80 : 128);
    }
  }
  return im;
}

// White noise: the worst case for JPEG (a large file).
Image noise_image(int w, int h, unsigned seed) {
  Image im;
  im.resize(w, h);
  std::mt19937 rng(seed);
  for (auto& b : im.rgb) b = static_cast<std::uint8_t>(rng());
  return im;
}

double mean_abs_error(const Image& a, const Image& b) {
  double sum = 0;
  for (std::size_t i = 0; i < a.rgb.size(); ++i) sum += std::abs(static_cast<int>(a.rgb[i]) - b.rgb[i]);
  return sum / static_cast<double>(a.rgb.size());
}

TEST(JpegCodec, RoundTripKeepsSizeAndPicture) {
  JpegCodec codec;
  const Image in = smooth_image(320, 240);
  std::vector<std::uint8_t> jpeg;
  ASSERT_TRUE(codec.encode(in, 90, jpeg)) << codec.error();
  ASSERT_GT(jpeg.size(), 100u);
  EXPECT_EQ(jpeg[0], 0xFF);  // SOI marker
  EXPECT_EQ(jpeg[1], 0xD8);
  EXPECT_LT(jpeg.size(), in.rgb.size() / 10);  // a smooth picture compresses well
  Image out;
  ASSERT_TRUE(codec.decode(jpeg.data(), jpeg.size(), out)) << codec.error();
  EXPECT_EQ(out.width, 320);
  EXPECT_EQ(out.height, 240);
  EXPECT_LT(mean_abs_error(in, out), 3.0);
}

TEST(JpegCodec, LowerQualityIsSmaller) {
  JpegCodec codec;
  const Image in = noise_image(160, 120, 3);
  std::vector<std::uint8_t> q50, q90;
  ASSERT_TRUE(codec.encode(in, 50, q50));
  ASSERT_TRUE(codec.encode(in, 90, q90));
  EXPECT_LT(q50.size(), q90.size());
}

TEST(JpegCodec, GarbageIsRefusedWithAReason) {
  JpegCodec codec;
  const std::vector<std::uint8_t> junk = {1, 2, 3, 4, 5, 6, 7, 8};
  Image out;
  EXPECT_FALSE(codec.decode(junk.data(), junk.size(), out));
  EXPECT_STRNE(codec.error(), "");
}

// Collects what the stream sends.
struct Collector {
  std::mutex m;
  std::vector<msg::Frame> frames;
  FrameStream::Sink sink() {
    return [this](const msg::Frame& f) {
      std::lock_guard<std::mutex> lock(m);
      frames.push_back(f);
    };
  }
};

TEST(FrameStream, SendsTheJpegWithItsStamps) {
  Collector c;
  FrameStreamOptions o;
  o.width = 320;
  o.height = 240;
  o.quality = 80;
  FrameStream stream(o, c.sink());
  Image* slot = stream.acquire();
  ASSERT_NE(slot, nullptr);
  *slot = smooth_image(320, 240);
  stream.submit(FrameStamp{7, 123456789, 111, 42});
  stream.wait_idle();
  // The sink runs after the slot is free: wait for it too (the destructor joins the thread).
  for (int i = 0; i < 500 && stream.sent() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  ASSERT_EQ(stream.sent(), 1u);
  std::lock_guard<std::mutex> lock(c.m);
  const msg::Frame& f = c.frames.at(0);
  EXPECT_EQ(f.frame_number(), 7u);
  EXPECT_EQ(f.render_stamp_ns(), 123456789u);
  EXPECT_EQ(f.haptic_stamp_ns(), 111u);
  EXPECT_EQ(f.haptic_seq(), 42u);
  EXPECT_EQ(f.width(), 320u);
  EXPECT_EQ(f.height(), 240u);
  EXPECT_EQ(f.quality(), 80u);
  JpegCodec codec;
  Image out;
  ASSERT_TRUE(codec.decode(f.jpeg().data(), f.jpeg().size(), out));
  EXPECT_LT(mean_abs_error(smooth_image(320, 240), out), 3.0);
}

TEST(FrameStream, AJpegAboveTheBoundIsDroppedAndCountedNotCut) {
  Collector c;
  FrameStreamOptions o;
  o.width = 640;
  o.height = 480;
  o.quality = 95;
  o.max_bytes = 65536;  // noise at q95 is several hundred KiB
  FrameStream stream(o, c.sink());
  Image* slot = stream.acquire();
  ASSERT_NE(slot, nullptr);
  *slot = noise_image(640, 480, 1);
  stream.submit(FrameStamp{1, 1, 0, 0});
  stream.wait_idle();
  for (int i = 0; i < 500 && stream.dropped_oversize() == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  EXPECT_EQ(stream.dropped_oversize(), 1u);
  EXPECT_EQ(stream.sent(), 0u);
  // A picture within the bound still goes through afterwards.
  slot = stream.acquire();
  ASSERT_NE(slot, nullptr);
  *slot = smooth_image(640, 480);
  stream.submit(FrameStamp{2, 2, 0, 0});
  for (int i = 0; i < 500 && stream.sent() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  EXPECT_EQ(stream.sent(), 1u);
  std::lock_guard<std::mutex> lock(c.m);
  ASSERT_EQ(c.frames.size(), 1u);
  EXPECT_LE(c.frames[0].jpeg().size(), 65536u);
  EXPECT_EQ(c.frames[0].frame_number(), 2u);
}

TEST(FrameStream, ABusyEncoderDropsThePictureInsteadOfWaiting) {
  std::atomic<bool> release{false};
  FrameStreamOptions o;
  o.width = 64;
  o.height = 48;
  // The sink blocks until told: the encoder thread is busy with picture 1 meanwhile.
  FrameStream stream(o, [&](const msg::Frame&) {
    while (!release.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  });
  struct Releaser {  // declared after the stream: runs first, so its destructor never joins a blocked sink
    std::atomic<bool>& flag;
    ~Releaser() { flag = true; }
  } releaser{release};
  Image* slot = stream.acquire();
  ASSERT_NE(slot, nullptr);
  *slot = smooth_image(64, 48);
  stream.submit(FrameStamp{1, 1, 0, 0});
  stream.wait_idle();  // picture 1 compressed; its sink is blocked
  // The slot is free again (the compressed copy is the encoder's): picture 2 is taken...
  slot = stream.acquire();
  ASSERT_NE(slot, nullptr);
  *slot = smooth_image(64, 48);
  stream.submit(FrameStamp{2, 2, 0, 0});
  // ...and while it waits for the busy encoder, picture 3 finds no slot: dropped at once, counted.
  EXPECT_EQ(stream.acquire(), nullptr);
  EXPECT_EQ(stream.dropped_busy(), 1u);
  EXPECT_EQ(stream.offered(), 3u);
}

TEST(FrameStream, StatsNameTheCounters) {
  FrameStream stream(FrameStreamOptions{}, [](const msg::Frame&) {});
  nlohmann::json j;
  stream.add_stats(j, 20);
  for (const char* k : {"offered", "sent", "dropped_busy", "dropped_oversize", "encode_errors", "encode_us", "bytes"}) {
    EXPECT_TRUE(j["stream"].contains(k)) << k;
  }
  EXPECT_EQ(j["stream"]["fps"], 20);
}

// visual.stream_fps / stream_quality: validated with the key named, and outside the scene hash.
TEST(FrameStreamScene, KeysAreValidatedAndDoNotChangeTheHash) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(::testing::TempDir()) / "frame_stream_scene";
  fs::create_directories(dir);
  auto write = [&](const char* name, const std::string& visual) {
    const fs::path p = dir / name;
    std::ofstream(p) << "name: mini\nmesh: {generate: liver}\nvisual:\n" << visual;
    return p.string();
  };
  const Scene off = load_scene(write("off.yaml", "  rate_hz: 50\n"));
  EXPECT_EQ(off.visual.stream_fps, 0);
  EXPECT_EQ(off.visual.stream_quality, 75);
  const Scene on = load_scene(write("on.yaml", "  stream_fps: 25\n  stream_quality: 60\n"));
  EXPECT_EQ(on.visual.stream_fps, 25);
  EXPECT_EQ(on.visual.stream_quality, 60);
  EXPECT_EQ(on.hash(), off.hash());
  for (const char* bad : {"  stream_quality: 0\n", "  stream_quality: 101\n", "  stream_fps: -1\n",
                          "  stream_fps: 500\n"}) {
    try {
      load_scene(write("bad.yaml", bad));
      ADD_FAILURE() << "accepted " << bad;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("stream_"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace surgsim
