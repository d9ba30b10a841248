// The live view's frame stream: rendered pictures JPEG-compressed (libturbojpeg) and handed to a sink (the
// DDS writer of surgsim/frame) on a thread of their own, so the render loop never waits for an encode or a write.
//
// One preallocated slot sits between the two threads. The render loop asks for it (acquire): when the encoder is still
// busy with the previous picture it gets nothing and that picture is dropped (counted), never waited for; otherwise it
// reads the picture straight into the slot's image and submits it with its stamps. The encoder compresses into a
// buffer sized for the worst case at start-up, and a JPEG larger than the topic's bound (kMaxFrameBytes) is dropped and
// counted, never cut. After the first frame nothing allocates.
#pragma once
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <nlohmann/json_fwd.hpp>
#include <thread>
#include <vector>

#include "core/stats.h"
#include "render/image.h"
#include "surgsim_types.h"

namespace surgsim {

inline constexpr const char* kFrameTopic = "surgsim/frame";
// Endpoint profiles of the frame topic in config/dds/profiles.xml (best effort, keep last 1, asynchronous writes).
inline constexpr const char* kFrameWriterProfile = "surgsim_frame_writer";
inline constexpr const char* kFrameReaderProfile = "surgsim_frame_reader";

/// JPEG compression and decompression of RGB images with libturbojpeg (4:2:0 subsampling, baseline).
class JpegCodec {
 public:
  JpegCodec();
  ~JpegCodec();
  JpegCodec(const JpegCodec&) = delete;
  JpegCodec& operator=(const JpegCodec&) = delete;

  /// Compresses `image` at `quality` (1..100) into `out` (resized to the JPEG's size; its capacity is kept, so a
  /// reused buffer reserved with max_jpeg_bytes() never allocates). False on a libturbojpeg error (error() says it).
  bool encode(const Image& image, int quality, std::vector<std::uint8_t>& out);
  /// Decompresses a JPEG into RGB. False when it is not a JPEG libturbojpeg reads (error() says why).
  bool decode(const std::uint8_t* data, std::size_t size, Image& out);
  const char* error() const { return error_; }
  /// The largest JPEG libturbojpeg can make of a width x height picture (4:2:0), bytes.
  static std::size_t max_jpeg_bytes(int width, int height);

 private:
  void* compressor_ = nullptr;    // tjhandle
  void* decompressor_ = nullptr;  // tjhandle
  const char* error_ = "";
};

/// Where a picture came from.
struct FrameStamp {
  std::uint64_t frame_number = 0;     // the visual node's rendered-frame count
  std::uint64_t render_stamp_ns = 0;  // end of the render, this host's CLOCK_MONOTONIC
  std::uint64_t haptic_stamp_ns = 0;  // the contact frame drawn (0: none)
  std::uint64_t haptic_seq = 0;
};

struct FrameStreamOptions {
  int width = 640;                    // pixels: the slot and the encode buffer are sized for this
  int height = 480;
  int quality = 75;                   // 1..100
  std::size_t max_bytes = 524288;     // the topic's bound (msg::kMaxFrameBytes); larger JPEGs are dropped
};

class FrameStream {
 public:
  using Sink = std::function<void(const msg::Frame&)>;  // called on the encoder thread

  /// Init: preallocates the slot, the JPEG buffer and the message, and starts the encoder thread.
  FrameStream(const FrameStreamOptions& options, Sink sink);
  /// Stops and joins the encoder (a picture being encoded is finished first).
  ~FrameStream();
  FrameStream(const FrameStream&) = delete;
  FrameStream& operator=(const FrameStream&) = delete;

  /// Render loop: the slot's image when the encoder is idle (fill it, then submit()), else nullptr: the encoder is
  /// still busy with the previous picture and this one is dropped (counted in dropped_busy). Never blocks.
  Image* acquire();
  /// Hands the acquired image to the encoder with its stamps.
  void submit(const FrameStamp& stamp);
  /// Waits until the encoder is idle (tests and benchmarks only; the render loop never calls it).
  void wait_idle();

  std::uint64_t offered() const { return offered_.load(); }             // acquire() calls
  std::uint64_t dropped_busy() const { return dropped_busy_.load(); }   // encoder busy: not encoded
  std::uint64_t dropped_oversize() const { return dropped_oversize_.load(); }  // JPEG above max_bytes: not sent
  std::uint64_t encode_errors() const { return encode_errors_.load(); }
  std::uint64_t sent() const { return sent_.load(); }
  /// Encode time (us) and JPEG size (bytes) of the pictures encoded so far.
  core::Percentiles encode_us();
  core::Percentiles jpeg_bytes();
  /// Adds "stream": {fps, quality, offered, sent, dropped_busy, dropped_oversize, encode_errors, encode_us, bytes}.
  void add_stats(nlohmann::json& j, double fps);

 private:
  void run();

  enum : int { kFree = 0, kFilling = 1, kReady = 2, kStop = 3 };
  FrameStreamOptions options_;
  Sink sink_;
  JpegCodec codec_;
  Image slot_;
  FrameStamp stamp_;
  std::vector<std::uint8_t> jpeg_;
  msg::Frame frame_;
  std::atomic<int> state_{kFree};
  bool stop_ = false;               // guarded by mutex_
  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable idle_;
  std::mutex stats_mutex_;
  core::SampleRecorder encode_us_{1 << 16};
  core::SampleRecorder bytes_{1 << 16};
  std::atomic<std::uint64_t> offered_{0}, dropped_busy_{0}, dropped_oversize_{0}, encode_errors_{0}, sent_{0};
  std::thread thread_;              // last: started once everything above exists
};

}  // namespace surgsim
