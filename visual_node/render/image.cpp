#include "render/image.h"

#include <png.h>

#include <cstring>

#include "core/error.h"

using namespace surgsim::core;

namespace surgsim {

void Image::resize(int w, int h) {
  width = w;
  height = h;
  rgb.resize(static_cast<std::size_t>(w > 0 ? w : 0) * (h > 0 ? h : 0) * 3);
}

namespace {
/// Where destination index i samples a source of `from` pixels scaled to `to`: the lower source index and the
/// weight of the one above it.
struct Tap {
  int i0;
  int i1;
  float w;
};
Tap tap(int i, int from, float ratio) {
  float s = (static_cast<float>(i) + 0.5f) * ratio - 0.5f;
  if (s < 0.0f) s = 0.0f;
  const float last = static_cast<float>(from - 1);
  if (s > last) s = last;
  const int i0 = static_cast<int>(s);
  const int i1 = i0 + 1 < from ? i0 + 1 : i0;
  return {i0, i1, s - static_cast<float>(i0)};
}
}  // namespace

void resize_bilinear(const Image& src, int width, int height, Image& dst) {
  if (src.empty() || width <= 0 || height <= 0) {
    dst.resize(0, 0);
    return;
  }
  dst.resize(width, height);
  if (src.width == width && src.height == height) {
    std::memcpy(dst.rgb.data(), src.rgb.data(), src.rgb.size());
    return;
  }
  const float rx = static_cast<float>(src.width) / static_cast<float>(width);
  const float ry = static_cast<float>(src.height) / static_cast<float>(height);
  for (int y = 0; y < height; ++y) {
    const Tap ty = tap(y, src.height, ry);
    std::uint8_t* out = dst.at(0, y);
    for (int x = 0; x < width; ++x, out += 3) {
      const Tap tx = tap(x, src.width, rx);
      const std::uint8_t* a = src.at(tx.i0, ty.i0);
      const std::uint8_t* b = src.at(tx.i1, ty.i0);
      const std::uint8_t* c = src.at(tx.i0, ty.i1);
      const std::uint8_t* d = src.at(tx.i1, ty.i1);
      for (int k = 0; k < 3; ++k) {
        const float top = static_cast<float>(a[k]) + tx.w * static_cast<float>(b[k] - a[k]);
        const float bottom = static_cast<float>(c[k]) + tx.w * static_cast<float>(d[k] - c[k]);
        out[k] = static_cast<std::uint8_t>(top + ty.w * (bottom - top) + 0.5f);
      }
    }
  }
}

void write_png(const std::string& path, const Image& image) {
  if (image.empty() || image.rgb.size() != static_cast<std::size_t>(image.width) * image.height * 3) {
    throw_error(path, ": cannot write PNG: image is ", image.width, "x", image.height, " with ", image.rgb.size(),
                " bytes (expected width * height * 3 > 0)");
  }
  // libpng's simplified API: no setjmp in our code, errors come back in png.message.
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  png.width = static_cast<png_uint_32>(image.width);
  png.height = static_cast<png_uint_32>(image.height);
  png.format = PNG_FORMAT_RGB;
  png.flags = PNG_IMAGE_FLAG_FAST;  // frames are written while running: speed over file size
  const png_int_32 row_stride = image.width * 3;
  if (!png_image_write_to_file(&png, path.c_str(), 0, image.rgb.data(), row_stride, nullptr)) {
    const std::string why = png.message[0] ? png.message : "unknown libpng error";
    png_image_free(&png);
    throw_error(path, ": cannot write PNG: ", why, " (check that the folder exists and is writable)");
  }
}

Image read_png(const std::string& path) {
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&png, path.c_str())) {
    throw_error(path, ": cannot read PNG: ", png.message);
  }
  png.format = PNG_FORMAT_RGB;
  Image out;
  out.resize(static_cast<int>(png.width), static_cast<int>(png.height));
  if (!png_image_finish_read(&png, nullptr, out.rgb.data(), static_cast<png_int_32>(png.width) * 3, nullptr)) {
    const std::string why = png.message;
    png_image_free(&png);
    throw_error(path, ": cannot read PNG: ", why);
  }
  return out;
}

}  // namespace surgsim
