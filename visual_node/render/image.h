// RGB images read back from a renderer, and PNG files (libpng).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace surgsim {

/// An 8-bit RGB image, rows stored top to bottom (row 0 is the top of the picture), 3 bytes per pixel.
struct Image {
  int width = 0;                   // pixels
  int height = 0;                  // pixels
  std::vector<std::uint8_t> rgb;   // width * height * 3, row-major, row 0 = top

  /// Sizes the buffer (keeps its capacity, so a reused image stops allocating after the first frame).
  void resize(int w, int h);
  bool empty() const { return width <= 0 || height <= 0; }
  /// Pointer to the 3 bytes of pixel (x, y); y = 0 is the top row. No bounds check.
  const std::uint8_t* at(int x, int y) const { return rgb.data() + (static_cast<std::size_t>(y) * width + x) * 3; }
  std::uint8_t* at(int x, int y) { return rgb.data() + (static_cast<std::size_t>(y) * width + x) * 3; }
};

/// Scales `src` to width x height into `dst` (resized; its capacity is reused) by bilinear interpolation between
/// pixel centres: destination pixel (x, y) samples the source at ((x + 0.5) sw / width - 0.5, (y + 0.5) sh / height -
/// 0.5), clamped to the outer pixel centres, rounded to the nearest byte. The same size copies. Empty `src`: `dst`
/// empty.
void resize_bilinear(const Image& src, int width, int height, Image& dst);

/// Writes `image` as an 8-bit RGB PNG, compressed for speed rather than size (frames are written while running).
/// Throws surgsim::core::Error naming `path` when the file cannot be written or the image is malformed.
void write_png(const std::string& path, const Image& image);

/// Reads any PNG libpng understands, converted to 8-bit RGB (alpha dropped over black, grey expanded).
/// Throws surgsim::core::Error naming `path` on failure.
Image read_png(const std::string& path);

}  // namespace surgsim
