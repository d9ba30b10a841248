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
