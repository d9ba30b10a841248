// Reading a PNG frame written by the visual node as plain RGB (integration tests).
#pragma once
#include <png.h>

#include <string>
#include <vector>

namespace surgsim::testing {

struct Rgb {
  int width = 0, height = 0;
  std::vector<unsigned char> data;  // rgb, row 0 = top; empty when the file could not be read
};

inline Rgb read_png_rgb(const std::string& path) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  Rgb out;
  if (!png_image_begin_read_from_file(&img, path.c_str())) return out;
  img.format = PNG_FORMAT_RGB;
  out.width = static_cast<int>(img.width);
  out.height = static_cast<int>(img.height);
  out.data.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.data.data(), 0, nullptr)) out.data.clear();
  return out;
}

}  // namespace surgsim::testing
