#include "imaging/volume_io.h"

#include <png.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <vector>

#include "core/error.h"
#include "core/text.h"

using namespace surgsim::core;

namespace surgsim::imaging {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------------------------
// PNG (libpng's classic API: the simplified one converts 16-bit and palette images through colour spaces, which
// would change label values).

struct PngPixels {
  int width = 0, height = 0;
  std::vector<std::int32_t> values;  // width * height, row-major from the top row
};

// libpng reports errors through this handler; it keeps the message and jumps back to read_png's setjmp.
void png_error_handler(png_structp png, png_const_charp message) {
  auto* buffer = static_cast<char*>(png_get_error_ptr(png));
  std::snprintf(buffer, 256, "%s", message);
  png_longjmp(png, 1);
}
void png_warning_handler(png_structp, png_const_charp) {}

// Owns what libpng needs during a read. Held through a pointer made before setjmp and never reassigned, so that a
// longjmp back leaves nothing indeterminate; the exception is thrown only after setjmp has returned.
struct PngReadState {
  std::FILE* file = nullptr;
  png_structp png = nullptr;
  png_infop info = nullptr;
  char message[256] = {0};
  std::vector<png_byte> data;
  std::vector<png_bytep> rows;
  long file_bytes = 0;  // size of the file, bounding the samples it can hold
  int width = 0, height = 0, channels = 0, depth = 0, colour = 0;
  ~PngReadState() {
    if (png != nullptr) png_destroy_read_struct(&png, info != nullptr ? &info : nullptr, nullptr);
    if (file != nullptr) std::fclose(file);
  }
};

// The largest expansion of deflate (RFC 1951): a run of 258 bytes costs at least 2 bits.
constexpr double kDeflateMaxRatio = 1032;

// Reads the raw samples (after unpacking sub-byte depths) into state; returns false on a libpng error or a header
// declaring more than the file can hold (then `message` says which).
bool png_read_samples(PngReadState* s) {
  if (setjmp(png_jmpbuf(s->png))) return false;
  png_init_io(s->png, s->file);
  png_read_info(s->png, s->info);
  // Deflate expands at most 1032-fold, so a file declaring more (filtered) rows than that of its own size is
  // truncated or corrupt: refused before the rows are allocated, since a header of a few bytes may declare up to
  // 1e6 x 1e6 pixels.
  const double declared = static_cast<double>(png_get_image_height(s->png, s->info)) *
                          (1.0 + static_cast<double>(png_get_rowbytes(s->png, s->info)));
  if (declared > kDeflateMaxRatio * static_cast<double>(s->file_bytes)) {
    std::snprintf(s->message, sizeof s->message,
                  "declares %u x %u pixels (%.0f bytes of rows), more than its %ld bytes can hold at deflate's best "
                  "ratio (%.0f:1): the file is truncated or corrupt (export the slice again)",
                  png_get_image_width(s->png, s->info), png_get_image_height(s->png, s->info), declared, s->file_bytes,
                  kDeflateMaxRatio);
    return false;
  }
  s->colour = png_get_color_type(s->png, s->info);
  s->depth = png_get_bit_depth(s->png, s->info);
  if (s->depth < 8) png_set_packing(s->png);  // one byte per sample, values kept (not scaled)
  if (s->colour & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(s->png);
  png_set_interlace_handling(s->png);
  png_read_update_info(s->png, s->info);
  s->width = static_cast<int>(png_get_image_width(s->png, s->info));
  s->height = static_cast<int>(png_get_image_height(s->png, s->info));
  s->channels = png_get_channels(s->png, s->info);
  const std::size_t row_bytes = png_get_rowbytes(s->png, s->info);
  s->data.resize(row_bytes * static_cast<std::size_t>(s->height));
  s->rows.resize(static_cast<std::size_t>(s->height));
  for (int y = 0; y < s->height; ++y) s->rows[static_cast<std::size_t>(y)] = s->data.data() + row_bytes * y;
  png_read_image(s->png, s->rows.data());
  png_read_end(s->png, nullptr);
  return true;
}

PngPixels read_png(const std::string& path) {
  auto s = std::make_unique<PngReadState>();
  s->file = std::fopen(path.c_str(), "rb");
  if (s->file == nullptr) throw_error(path, ": cannot open: ", std::strerror(errno));
  if (std::fseek(s->file, 0, SEEK_END) != 0 || (s->file_bytes = std::ftell(s->file)) < 0 ||
      std::fseek(s->file, 0, SEEK_SET) != 0)
    throw_error(path, ": cannot read: ", std::strerror(errno));
  png_byte signature[8] = {0};
  if (std::fread(signature, 1, 8, s->file) != 8 || png_sig_cmp(signature, 0, 8) != 0)
    throw_error(path, ": not a PNG file");
  s->png = png_create_read_struct(PNG_LIBPNG_VER_STRING, s->message, png_error_handler, png_warning_handler);
  if (s->png == nullptr) throw_error(path, ": libpng could not start");
  s->info = png_create_info_struct(s->png);
  if (s->info == nullptr) throw_error(path, ": libpng could not start");
  png_set_sig_bytes(s->png, 8);
  if (!png_read_samples(s.get())) throw_error(path, ": unreadable PNG: ", s->message);

  PngPixels out;
  out.width = s->width;
  out.height = s->height;
  out.values.resize(static_cast<std::size_t>(s->width) * s->height);
  const int bytes = s->depth == 16 ? 2 : 1;
  for (int y = 0; y < s->height; ++y) {
    const png_byte* row = s->rows[static_cast<std::size_t>(y)];
    for (int x = 0; x < s->width; ++x) {
      std::int32_t sample[4] = {0, 0, 0, 0};
      for (int c = 0; c < s->channels && c < 4; ++c) {
        const png_byte* p = row + (static_cast<std::size_t>(x) * s->channels + c) * bytes;
        sample[c] = bytes == 2 ? (p[0] << 8 | p[1]) : p[0];
      }
      if (s->channels >= 3 && (sample[0] != sample[1] || sample[1] != sample[2]))
        throw_error(path, ": colour pixel (", x, ", ", y, ") = (", sample[0], ", ", sample[1], ", ", sample[2],
                    "): labels must be grey values (save the slices as greyscale or palette PNG)");
      out.values[static_cast<std::size_t>(y) * s->width + x] = sample[0];
    }
  }
  return out;
}

// Writes the rows; returns false on a libpng error (kept apart from write_png so that nothing live across the
// setjmp is modified after it).
bool png_write_rows(png_structp png, png_infop info, std::FILE* file, int width, int height, int depth,
                    png_bytep* rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_set_IHDR(png, info, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height), depth, PNG_COLOR_TYPE_GRAY,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  return true;
}

void write_png(const std::string& path, int width, int height, const std::vector<std::uint16_t>& values, int depth) {
  const int bytes = depth == 16 ? 2 : 1;
  std::vector<png_byte> data(static_cast<std::size_t>(width) * height * bytes);
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (bytes == 2) {
      data[2 * i] = static_cast<png_byte>(values[i] >> 8);
      data[2 * i + 1] = static_cast<png_byte>(values[i] & 0xff);
    } else {
      data[i] = static_cast<png_byte>(values[i]);
    }
  }
  std::vector<png_bytep> rows(static_cast<std::size_t>(height));
  for (int y = 0; y < height; ++y) rows[static_cast<std::size_t>(y)] = data.data() + static_cast<std::size_t>(y) * width * bytes;
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) throw_error(path, ": cannot create: ", std::strerror(errno));
  char message[256] = {0};
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, message, png_error_handler, png_warning_handler);
  png_infop info = png != nullptr ? png_create_info_struct(png) : nullptr;
  const bool ok = png != nullptr && info != nullptr && png_write_rows(png, info, file, width, height, depth, rows.data());
  if (png != nullptr) png_destroy_write_struct(&png, info != nullptr ? &info : nullptr);
  const bool closed = std::fclose(file) == 0;
  if (!ok || !closed) throw_error(path, ": PNG write failed", message[0] != 0 ? ": " : "", message);
}

// The last run of digits in a file stem, or -1.
long slice_number(const std::string& stem) {
  const auto end = std::find_if(stem.rbegin(), stem.rend(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); });
  if (end == stem.rend()) return -1;
  const auto begin = std::find_if(end, stem.rend(), [](char c) { return !std::isdigit(static_cast<unsigned char>(c)); });
  const std::string digits(begin.base(), end.base());
  if (digits.size() > 9) return -1;
  return std::stol(digits);
}

// ---------------------------------------------------------------------------------------------------------------
// NRRD (http://teem.sourceforge.net/nrrd/format.html)

std::string trim(const std::string& s) { return std::string(core::text::trim(s)); }
std::string lower(const std::string& s) { return core::text::lower(s); }

struct NrrdType {
  const char* name;  // canonical
  int bytes;
  bool is_signed;
  bool is_float;
};

// Supported types and their NRRD spellings.
const NrrdType* nrrd_type(const std::string& spelling) {
  static const NrrdType kUchar{"uchar", 1, false, false}, kUshort{"ushort", 2, false, false},
      kShort{"short", 2, true, false}, kInt{"int", 4, true, false}, kFloat{"float", 4, true, true};
  static const std::map<std::string, const NrrdType*> kSpellings = {
      {"uchar", &kUchar},           {"unsigned char", &kUchar},      {"uint8", &kUchar},
      {"uint8_t", &kUchar},         {"ushort", &kUshort},            {"unsigned short", &kUshort},
      {"unsigned short int", &kUshort}, {"uint16", &kUshort},        {"uint16_t", &kUshort},
      {"short", &kShort},           {"short int", &kShort},          {"signed short", &kShort},
      {"signed short int", &kShort}, {"int16", &kShort},             {"int16_t", &kShort},
      {"int", &kInt},               {"signed int", &kInt},           {"int32", &kInt},
      {"int32_t", &kInt},           {"float", &kFloat}};
  const auto it = kSpellings.find(lower(spelling));
  return it == kSpellings.end() ? nullptr : it->second;
}

// Parses "(a,b,c)" into v; false on a malformed vector.
bool parse_vector(const std::string& text, Eigen::Vector3d& v) {
  const std::string t = trim(text);
  if (t.size() < 2 || t.front() != '(' || t.back() != ')') return false;
  std::string inner = t.substr(1, t.size() - 2);
  std::replace(inner.begin(), inner.end(), ',', ' ');
  std::istringstream is(inner);
  std::string extra;
  return static_cast<bool>(is >> v.x() >> v.y() >> v.z()) && !(is >> extra) && v.allFinite();
}

// Splits "(..) (..) (..)" into its parenthesized groups.
std::vector<std::string> split_vectors(const std::string& text) {
  std::vector<std::string> out;
  std::size_t i = 0;
  while (i < text.size()) {
    if (std::isspace(static_cast<unsigned char>(text[i]))) {
      ++i;
      continue;
    }
    if (text[i] == '(') {
      const std::size_t close = text.find(')', i);
      if (close == std::string::npos) return {};
      out.push_back(text.substr(i, close - i + 1));
      i = close + 1;
    } else {
      std::size_t end = i;
      while (end < text.size() && !std::isspace(static_cast<unsigned char>(text[end]))) ++end;
      out.push_back(text.substr(i, end - i));  // e.g. "none"
      i = end;
    }
  }
  return out;
}

std::string read_file_bytes(const std::string& path, const char* what) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw_error(path, ": cannot open ", what, ": ", std::strerror(errno));
  std::string bytes;
  char buffer[1 << 16];
  std::size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) bytes.append(buffer, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) throw_error(path, ": read error");
  return bytes;
}

bool host_is_big_endian() {
  const std::uint16_t one = 1;
  unsigned char first = 0;
  std::memcpy(&first, &one, 1);
  return first == 0;
}

}  // namespace

LabelVolume read_png_slices(const std::string& folder, const Eigen::Vector3d& spacing) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw_error(folder, ": not a folder of PNG slices");
  if (!(spacing.minCoeff() > 0.0) || !spacing.allFinite())
    throw_error(folder, ": voxel spacing must be three positive numbers, got ", spacing.transpose());
  std::vector<std::pair<long, std::string>> slices;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (!entry.is_regular_file() || lower(entry.path().extension().string()) != ".png") continue;
    const long number = slice_number(entry.path().stem().string());
    if (number < 0)
      throw_error(entry.path().string(), ": the slice file name has no number (name slices like slice_0001.png)");
    slices.emplace_back(number, entry.path().string());
  }
  if (ec) throw_error(folder, ": cannot list the folder: ", ec.message());
  if (slices.empty()) throw_error(folder, ": no .png slices in the folder");
  std::sort(slices.begin(), slices.end());
  for (std::size_t s = 1; s < slices.size(); ++s) {
    if (slices[s].first == slices[s - 1].first)
      throw_error(slices[s].second, ": same slice number ", slices[s].first, " as ", slices[s - 1].second);
    if (slices[s].first != slices[s - 1].first + 1)
      throw_error(folder, ": missing slice ", slices[s - 1].first + 1,
                  slices[s].first - slices[s - 1].first > 2 ? " (and more)" : "", " between ", slices[s - 1].second,
                  " and ", slices[s].second);
  }

  LabelVolume volume;
  volume.source = folder;
  volume.grid.spacing = spacing;
  for (std::size_t s = 0; s < slices.size(); ++s) {
    const PngPixels image = read_png(slices[s].second);
    if (s == 0) {
      volume.grid.size = Eigen::Vector3i(image.width, image.height, static_cast<int>(slices.size()));
      volume.labels.reserve(static_cast<std::size_t>(volume.grid.voxel_count()));
    } else if (image.width != volume.grid.size.x() || image.height != volume.grid.size.y()) {
      throw_error(slices[s].second, ": slice is ", image.width, " x ", image.height, " pixels but ",
                  slices.front().second, " is ", volume.grid.size.x(), " x ", volume.grid.size.y());
    }
    volume.labels.insert(volume.labels.end(), image.values.begin(), image.values.end());
  }
  return volume;
}

LabelVolume read_nrrd(const std::string& path) {
  const std::string bytes = read_file_bytes(path, "NRRD file");
  // Header: lines up to an empty line (attached data follows) or the end of the file (detached header).
  std::size_t pos = 0;
  int line_number = 0;
  auto next_line = [&](std::string& line) {
    if (pos >= bytes.size()) return false;
    std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) end = bytes.size();
    line = bytes.substr(pos, end - pos);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    pos = std::min(bytes.size(), end + 1);
    ++line_number;
    return true;
  };
  std::string line;
  if (!next_line(line) || line.rfind("NRRD000", 0) != 0)
    throw_error(path, ":1: not an NRRD file (the first line must be NRRD0001 .. NRRD0005)");
  auto fail = [&path](int at, const std::string& what) { throw_error(path, ":", at, ": ", what); };

  const NrrdType* type = nullptr;
  int dimension = 0, endian = 0;  // endian: 0 unset, 1 little, 2 big
  std::vector<long> sizes;
  Eigen::Vector3d spacings = Eigen::Vector3d::Zero(), origin = Eigen::Vector3d::Zero();
  Eigen::Matrix3d directions = Eigen::Matrix3d::Zero();
  bool has_spacings = false, has_directions = false, has_encoding = false;
  double unit = 1e-3;  // m per file unit: millimetres unless `space units` says otherwise
  std::string data_file;
  long line_skip = 0, byte_skip = 0;
  bool attached = false;
  while (next_line(line)) {
    if (line.empty()) {
      attached = true;
      break;
    }
    if (line[0] == '#') continue;
    if (line.find(":=") != std::string::npos) continue;  // key/value pair
    const std::size_t colon = line.find(": ");
    if (colon == std::string::npos) fail(line_number, "expected 'field: value', got '" + line.substr(0, 60) + "'");
    const std::string field = lower(trim(line.substr(0, colon)));
    const std::string value = trim(line.substr(colon + 2));
    const int at = line_number;
    std::istringstream is(value);
    std::string extra;
    if (field == "type") {
      type = nrrd_type(value);
      if (type == nullptr) fail(at, "unknown type '" + value + "' (supported: uchar, ushort, short, int, float)");
    } else if (field == "dimension") {
      if (!(is >> dimension) || (is >> extra)) fail(at, "dimension '" + value + "' is not a number");
      if (dimension != 3) fail(at, "dimension " + value + " not supported (a segmented volume has 3)");
    } else if (field == "sizes") {
      long s = 0;
      while (is >> s) sizes.push_back(s);
      if (!is.eof() || sizes.size() != 3 || *std::min_element(sizes.begin(), sizes.end()) <= 0 ||
          *std::max_element(sizes.begin(), sizes.end()) > 100000)
        fail(at, "sizes '" + value + "': expected three positive voxel counts");
    } else if (field == "encoding") {
      if (lower(value) != "raw")
        fail(at, "unknown or unsupported encoding '" + value + "' (supported: raw; decompress gzip/bzip2 data first)");
      has_encoding = true;
    } else if (field == "endian") {
      const std::string v = lower(value);
      if (v == "little") endian = 1;
      else if (v == "big") endian = 2;
      else fail(at, "unknown endian '" + value + "' (little or big)");
    } else if (field == "spacings") {
      for (int c = 0; c < 3; ++c)
        if (!(is >> spacings[c])) fail(at, "spacings '" + value + "': expected three numbers");
      if ((is >> extra) || !(spacings.minCoeff() > 0.0) || !spacings.allFinite())
        fail(at, "spacings '" + value + "': expected three positive numbers");
      has_spacings = true;
    } else if (field == "space directions") {
      const auto groups = split_vectors(value);
      if (groups.size() != 3) fail(at, "space directions '" + value + "': expected three vectors (x,y,z)");
      for (int c = 0; c < 3; ++c) {
        Eigen::Vector3d d;
        if (!parse_vector(groups[static_cast<std::size_t>(c)], d) || !(d.norm() > 0.0))
          fail(at, "space directions: axis " + std::to_string(c) + " '" + groups[static_cast<std::size_t>(c)] +
                       "' is not a non-zero vector (x,y,z)");
        directions.col(c) = d;
      }
      has_directions = true;
    } else if (field == "space origin") {
      if (!parse_vector(value, origin)) fail(at, "space origin '" + value + "': expected a vector (x,y,z)");
    } else if (field == "space units") {
      std::string u = value;
      u.erase(std::remove(u.begin(), u.end(), '"'), u.end());
      std::istringstream us(u);
      std::string first, w;
      us >> first;
      while (us >> w)
        if (lower(w) != lower(first)) fail(at, "space units '" + value + "': mixed units are not supported");
      const std::string f = lower(first);
      if (f == "mm") unit = 1e-3;
      else if (f == "cm") unit = 1e-2;
      else if (f == "m") unit = 1.0;
      else if (f == "um" || f == "micron" || f == "microns") unit = 1e-6;
      else fail(at, "unknown space units '" + value + "' (supported: mm, cm, m, um)");
    } else if (field == "space") {
      static const char* kSpaces[] = {"right-anterior-superior", "ras", "left-anterior-superior", "las",
                                      "left-posterior-superior", "lps", "scanner-xyz", "3d-right-handed",
                                      "3d-left-handed"};
      if (std::find(std::begin(kSpaces), std::end(kSpaces), lower(value)) == std::end(kSpaces))
        fail(at, "unknown or unsupported space '" + value + "' (a 3D space such as left-posterior-superior)");
    } else if (field == "space dimension") {
      if (value != "3") fail(at, "space dimension " + value + " not supported (3)");
    } else if (field == "data file" || field == "datafile") {
      if (value.find('%') != std::string::npos || lower(value).rfind("list", 0) == 0)
        fail(at, "data file '" + value + "': multi-file data is not supported (one raw file)");
      data_file = value;
    } else if (field == "line skip" || field == "lineskip") {
      if (!(is >> line_skip) || (is >> extra) || line_skip < 0) fail(at, "line skip '" + value + "' must be >= 0");
    } else if (field == "byte skip" || field == "byteskip") {
      if (!(is >> byte_skip) || (is >> extra) || byte_skip < -1) fail(at, "byte skip '" + value + "' must be >= -1");
    } else if (field == "content" || field == "kinds" || field == "centers" || field == "centerings" ||
               field == "labels" || field == "units" || field == "thicknesses" || field == "axis mins" ||
               field == "axismins" || field == "axis maxs" || field == "axismaxs" || field == "min" ||
               field == "max" || field == "old min" || field == "oldmin" || field == "old max" ||
               field == "oldmax" || field == "measurement frame" || field == "sample units" ||
               field == "sampleunits" || field == "number") {
      // informational
    } else {
      fail(at, "unknown field '" + field + "'");
    }
  }
  // Required fields.
  if (type == nullptr) throw_error(path, ": header has no 'type'");
  if (dimension == 0) throw_error(path, ": header has no 'dimension'");
  if (sizes.size() != 3) throw_error(path, ": header has no 'sizes'");
  if (!has_encoding) throw_error(path, ": header has no 'encoding'");
  if (type->bytes > 1 && endian == 0) throw_error(path, ": header has no 'endian' (needed for type ", type->name, ")");
  if (has_spacings && has_directions) throw_error(path, ": header has both 'spacings' and 'space directions'");
  if (!has_spacings && !has_directions)
    throw_error(path, ": header has neither 'spacings' nor 'space directions': the voxel size is unknown");

  constexpr long kMaxVoxels = 1L << 31;
  if (sizes[0] * sizes[1] * sizes[2] > kMaxVoxels)
    throw_error(path, ": ", sizes[0], " x ", sizes[1], " x ", sizes[2], " voxels is more than this reader takes (",
                kMaxVoxels, "); crop the volume around the organ");

  LabelVolume volume;
  volume.source = path;
  VoxelGrid& g = volume.grid;
  g.size = Eigen::Vector3i(static_cast<int>(sizes[0]), static_cast<int>(sizes[1]), static_cast<int>(sizes[2]));
  if (has_spacings) {
    g.spacing = spacings * unit;
  } else {
    // Orthogonal axes only: a rotation (possibly a reflection) times the voxel size.
    for (int c = 0; c < 3; ++c) {
      g.spacing[c] = directions.col(c).norm() * unit;
      g.axes.col(c) = directions.col(c).normalized();
    }
    for (int a = 0; a < 3; ++a)
      for (int b = a + 1; b < 3; ++b)
        if (std::fabs(g.axes.col(a).dot(g.axes.col(b))) > 1e-6)
          throw_error(path, ": space directions are not orthogonal (sheared voxels are not supported)");
  }
  g.origin = origin * unit;

  // Data: attached after the blank line, or in the detached file.
  std::string detached;
  const std::string* data = &bytes;
  std::string data_name = path;
  std::size_t offset = pos;
  if (!data_file.empty()) {
    data_name = (fs::path(path).parent_path() / data_file).string();
    detached = read_file_bytes(data_name, "NRRD data file");
    data = &detached;
    offset = 0;
  } else if (!attached) {
    throw_error(path, ": no data: neither a 'data file' field nor data after a blank line");
  }
  for (long l = 0; l < line_skip; ++l) {
    const std::size_t end = data->find('\n', offset);
    if (end == std::string::npos) throw_error(data_name, ": truncated: fewer lines than 'line skip' ", line_skip);
    offset = end + 1;
  }
  const std::size_t count = static_cast<std::size_t>(g.voxel_count());
  const std::size_t needed = count * static_cast<std::size_t>(type->bytes);
  if (byte_skip == -1) {
    if (data->size() < offset + needed)
      throw_error(data_name, ": truncated: ", needed, " bytes of voxel data expected (", sizes[0], " x ", sizes[1],
                  " x ", sizes[2], " ", type->name, "), ", data->size() - offset, " found");
    offset = data->size() - needed;
  } else {
    offset += static_cast<std::size_t>(byte_skip);
  }
  const std::size_t available = data->size() > offset ? data->size() - offset : 0;
  if (available < needed)
    throw_error(data_name, ": truncated: ", needed, " bytes of voxel data expected (", sizes[0], " x ", sizes[1],
                " x ", sizes[2], " ", type->name, "), ", available, " found");

  const bool swap = type->bytes > 1 && (endian == 2) != host_is_big_endian();
  volume.labels.resize(count);
  const unsigned char* p = reinterpret_cast<const unsigned char*>(data->data()) + offset;
  for (std::size_t v = 0; v < count; ++v, p += type->bytes) {
    unsigned char b[4];
    for (int k = 0; k < type->bytes; ++k) b[k] = swap ? p[type->bytes - 1 - k] : p[k];
    std::int32_t label = 0;
    if (type->is_float) {
      float f = 0.0f;
      std::memcpy(&f, b, 4);
      if (!std::isfinite(f) || f != std::round(f) || std::fabs(f) > 2e9f)
        throw_error(data_name, ": voxel ", v, " holds ", f, ": a float volume must hold whole-number labels");
      label = static_cast<std::int32_t>(f);
    } else if (type->bytes == 1) {
      label = b[0];
    } else if (type->bytes == 2) {
      std::uint16_t u = 0;
      std::memcpy(&u, b, 2);
      label = type->is_signed ? static_cast<std::int32_t>(static_cast<std::int16_t>(u)) : static_cast<std::int32_t>(u);
    } else {
      std::memcpy(&label, b, 4);
    }
    volume.labels[v] = label;
  }
  return volume;
}

void write_png_slices(const LabelVolume& volume, const std::string& folder, const std::string& stem) {
  const VoxelGrid& g = volume.grid;
  if (static_cast<std::int64_t>(volume.labels.size()) != g.voxel_count() || g.voxel_count() == 0)
    throw_error(folder, ": cannot write an empty or inconsistent volume");
  const auto [lo, hi] = std::minmax_element(volume.labels.begin(), volume.labels.end());
  if (*lo < 0 || *hi > 65535) throw_error(folder, ": labels ", *lo, "..", *hi, " do not fit a 16-bit PNG");
  const int depth = *hi > 255 ? 16 : 8;
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) throw_error(folder, ": cannot create the folder: ", ec.message());
  std::vector<std::uint16_t> values(static_cast<std::size_t>(g.size.x()) * g.size.y());
  for (int k = 0; k < g.size.z(); ++k) {
    for (int j = 0; j < g.size.y(); ++j)
      for (int i = 0; i < g.size.x(); ++i)
        values[static_cast<std::size_t>(j) * g.size.x() + i] =
            static_cast<std::uint16_t>(volume.labels[static_cast<std::size_t>(g.index(i, j, k))]);
    char name[32];
    std::snprintf(name, sizeof name, "_%04d.png", k);
    write_png((fs::path(folder) / (stem + name)).string(), g.size.x(), g.size.y(), values, depth);
  }
}

void write_nrrd(const LabelVolume& volume, const std::string& path, const NrrdWriteOptions& options) {
  const VoxelGrid& g = volume.grid;
  const NrrdType* type = nrrd_type(options.type);
  if (type == nullptr) throw_error(path, ": unknown NRRD type '", options.type, "'");
  if (static_cast<std::int64_t>(volume.labels.size()) != g.voxel_count() || g.voxel_count() == 0)
    throw_error(path, ": cannot write an empty or inconsistent volume");
  std::ostringstream h;
  h.precision(17);
  h << "NRRD0004\n# written by surgsim (segmented volume)\n"
    << "type: " << type->name << "\ndimension: 3\n"
    << "sizes: " << g.size.x() << " " << g.size.y() << " " << g.size.z() << "\n";
  if (options.space_directions) {
    h << "space: 3D-right-handed\nspace directions:";
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d d = g.axes.col(c) * g.spacing[c] * 1e3;
      h << " (" << d.x() << "," << d.y() << "," << d.z() << ")";
    }
    const Eigen::Vector3d o = g.origin * 1e3;
    h << "\nspace origin: (" << o.x() << "," << o.y() << "," << o.z() << ")\nspace units: \"mm\" \"mm\" \"mm\"\n";
  } else {
    h << "spacings: " << g.spacing.x() * 1e3 << " " << g.spacing.y() * 1e3 << " " << g.spacing.z() * 1e3 << "\n";
  }
  h << "encoding: raw\n";
  if (type->bytes > 1) h << "endian: " << (options.big_endian ? "big" : "little") << "\n";
  const fs::path raw_path = fs::path(path).replace_extension(".raw");
  if (options.detached) h << "data file: " << raw_path.filename().string() << "\n";
  h << "\n";

  std::string data;
  data.reserve(volume.labels.size() * static_cast<std::size_t>(type->bytes));
  const bool swap = type->bytes > 1 && options.big_endian != host_is_big_endian();
  for (std::int32_t label : volume.labels) {
    unsigned char b[4] = {0, 0, 0, 0};
    const bool fits = type->is_float || (type->bytes == 1 && label >= 0 && label <= 255) ||
                      (type->bytes == 2 && !type->is_signed && label >= 0 && label <= 65535) ||
                      (type->bytes == 2 && type->is_signed && label >= -32768 && label <= 32767) || type->bytes == 4;
    if (!fits) throw_error(path, ": label ", label, " does not fit type ", type->name);
    if (type->is_float) {
      const float f = static_cast<float>(label);
      std::memcpy(b, &f, 4);
    } else if (type->bytes == 1) {
      b[0] = static_cast<unsigned char>(label);
    } else if (type->bytes == 2) {
      const auto u = static_cast<std::uint16_t>(label);
      std::memcpy(b, &u, 2);
    } else {
      std::memcpy(b, &label, 4);
    }
    if (swap) std::reverse(b, b + type->bytes);
    data.append(reinterpret_cast<const char*>(b), static_cast<std::size_t>(type->bytes));
  }
  auto write_all = [](const std::string& file, const std::string& a, const std::string* b) {
    std::FILE* f = std::fopen(file.c_str(), "wb");
    if (f == nullptr) throw_error(file, ": cannot create: ", std::strerror(errno));
    bool ok = std::fwrite(a.data(), 1, a.size(), f) == a.size();
    if (b != nullptr) ok = ok && std::fwrite(b->data(), 1, b->size(), f) == b->size();
    if (std::fclose(f) != 0 || !ok) throw_error(file, ": write failed");
  };
  if (options.detached) {
    write_all(path, h.str(), nullptr);
    write_all(raw_path.string(), data, nullptr);
  } else {
    write_all(path, h.str(), &data);
  }
}

}  // namespace surgsim::imaging
