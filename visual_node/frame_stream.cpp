#include "frame_stream.h"

#include <turbojpeg.h>

#include <chrono>
#include <cstring>
#include <nlohmann/json.hpp>

#include "core/clock.h"

using namespace surgsim::core;

namespace surgsim {

JpegCodec::JpegCodec() : compressor_(tjInitCompress()), decompressor_(tjInitDecompress()) {}

JpegCodec::~JpegCodec() {
  if (compressor_ != nullptr) tjDestroy(static_cast<tjhandle>(compressor_));
  if (decompressor_ != nullptr) tjDestroy(static_cast<tjhandle>(decompressor_));
}

std::size_t JpegCodec::max_jpeg_bytes(int width, int height) {
  return static_cast<std::size_t>(tjBufSize(width, height, TJSAMP_420));
}

bool JpegCodec::encode(const Image& image, int quality, std::vector<std::uint8_t>& out) {
  if (compressor_ == nullptr || image.empty()) {
    error_ = compressor_ == nullptr ? "libturbojpeg compressor not initialised" : "empty image";
    return false;
  }
  // Compress into the caller's buffer (no reallocation inside libturbojpeg: TJFLAG_NOREALLOC with the worst case).
  out.resize(max_jpeg_bytes(image.width, image.height));
  unsigned char* dst = out.data();
  unsigned long size = out.size();  // NOLINT(google-runtime-int): libturbojpeg's type
  if (tjCompress2(static_cast<tjhandle>(compressor_), image.rgb.data(), image.width, 0, image.height, TJPF_RGB, &dst,
                  &size, TJSAMP_420, quality, TJFLAG_NOREALLOC | TJFLAG_FASTDCT) != 0) {
    error_ = tjGetErrorStr2(static_cast<tjhandle>(compressor_));
    out.clear();
    return false;
  }
  out.resize(size);
  return true;
}

bool JpegCodec::decode(const std::uint8_t* data, std::size_t size, Image& out) {
  int w = 0, h = 0, subsampling = 0, colorspace = 0;
  auto* d = static_cast<tjhandle>(decompressor_);
  auto* src = const_cast<unsigned char*>(data);  // libturbojpeg's API is not const-correct; it does not write
  if (d == nullptr || tjDecompressHeader3(d, src, size, &w, &h, &subsampling, &colorspace) != 0) {
    error_ = d == nullptr ? "libturbojpeg decompressor not initialised" : tjGetErrorStr2(d);
    return false;
  }
  out.resize(w, h);
  if (tjDecompress2(d, src, size, out.rgb.data(), w, 0, h, TJPF_RGB, TJFLAG_ACCURATEDCT) != 0) {
    error_ = tjGetErrorStr2(d);
    return false;
  }
  return true;
}

FrameStream::FrameStream(const FrameStreamOptions& options, Sink sink) : options_(options), sink_(std::move(sink)) {
  // --- init: every buffer at its final size, then the thread ---
  slot_.resize(options_.width, options_.height);
  jpeg_.reserve(JpegCodec::max_jpeg_bytes(options_.width, options_.height));
  frame_.jpeg().reserve(options_.max_bytes);
  frame_.quality(static_cast<std::uint32_t>(options_.quality));
  thread_ = std::thread([this] { run(); });
}

FrameStream::~FrameStream() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

Image* FrameStream::acquire() {
  offered_.fetch_add(1, std::memory_order_relaxed);
  int expected = kFree;
  if (!state_.compare_exchange_strong(expected, kFilling, std::memory_order_acquire)) {
    dropped_busy_.fetch_add(1, std::memory_order_relaxed);
    return nullptr;
  }
  return &slot_;
}

void FrameStream::submit(const FrameStamp& stamp) {
  stamp_ = stamp;
  {
    std::lock_guard<std::mutex> lock(mutex_);  // held for a store: the encoder holds it only to check and wait
    state_.store(kReady, std::memory_order_release);
  }
  wake_.notify_one();
}

void FrameStream::wait_idle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [this] { return state_.load() == kFree; });
}

void FrameStream::run() {
  for (;;) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || state_.load(std::memory_order_acquire) == kReady; });
      if (state_.load() != kReady) return;  // stopped with nothing to encode
    }
    const std::uint64_t t0 = monotonic_ns();
    const bool ok = codec_.encode(slot_, options_.quality, jpeg_);
    const FrameStamp stamp = stamp_;
    const int width = slot_.width, height = slot_.height;
    {
      // The slot is free again as soon as the picture is compressed: the render loop may fill the next one.
      std::lock_guard<std::mutex> lock(mutex_);
      state_.store(kFree, std::memory_order_release);
    }
    idle_.notify_all();
    const double us = static_cast<double>(monotonic_ns() - t0) * 1e-3;
    if (!ok) {
      encode_errors_.fetch_add(1, std::memory_order_relaxed);
      continue;
    }
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      encode_us_.add(us);
      bytes_.add(static_cast<double>(jpeg_.size()));
    }
    if (jpeg_.size() > options_.max_bytes) {
      dropped_oversize_.fetch_add(1, std::memory_order_relaxed);  // never cut: a truncated JPEG is not a picture
      continue;
    }
    frame_.frame_number(stamp.frame_number);
    frame_.render_stamp_ns(stamp.render_stamp_ns);
    frame_.haptic_stamp_ns(stamp.haptic_stamp_ns);
    frame_.haptic_seq(stamp.haptic_seq);
    frame_.width(static_cast<std::uint32_t>(width));
    frame_.height(static_cast<std::uint32_t>(height));
    frame_.jpeg().assign(jpeg_.begin(), jpeg_.end());  // within the reserved capacity
    sink_(frame_);
    sent_.fetch_add(1, std::memory_order_relaxed);
  }
}

Percentiles FrameStream::encode_us() {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return encode_us_.summary();
}

Percentiles FrameStream::jpeg_bytes() {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return bytes_.summary();
}

void FrameStream::add_stats(nlohmann::json& j, double fps) {
  j["stream"] = {{"fps", fps},
                 {"quality", options_.quality},
                 {"width", options_.width},
                 {"height", options_.height},
                 {"max_bytes", options_.max_bytes},
                 {"offered", offered()},
                 {"sent", sent()},
                 {"dropped_busy", dropped_busy()},
                 {"dropped_oversize", dropped_oversize()},
                 {"encode_errors", encode_errors()},
                 {"encode_us", to_json(encode_us())},
                 {"bytes", to_json(jpeg_bytes())}};
}

}  // namespace surgsim
