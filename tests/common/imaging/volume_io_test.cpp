// Tests for common/imaging/volume_io.cpp: PNG slice folders and NRRD volumes, written and read back, and every bad
// input refused with the file (and header line) named.
#include "imaging/volume_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "support/error_test_util.h"
#include "core/error.h"

using namespace surgsim::core;
using namespace surgsim::imaging;

namespace surgsim {
namespace {

using test::error_of;
using test::contains;

namespace fs = std::filesystem;

// A fresh folder per test, removed afterwards.
class VolumeIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("surgsim_volume_io_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

LabelVolume sample(int nx, int ny, int nz, std::int32_t max_label) {
  LabelVolume v;
  v.grid.size = Eigen::Vector3i(nx, ny, nz);
  v.grid.spacing = Eigen::Vector3d(0.0008, 0.0009, 0.0015);
  v.labels.resize(static_cast<std::size_t>(nx) * ny * nz);
  for (std::size_t i = 0; i < v.labels.size(); ++i) v.labels[i] = static_cast<std::int32_t>((i * 7919) % (max_label + 1));
  v.source = "sample";
  return v;
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
}

TEST_F(VolumeIoTest, PngSlicesRoundTrip8And16Bit) {
  for (std::int32_t max_label : {3, 700}) {
    const LabelVolume v = sample(7, 5, 4, max_label);
    const std::string folder = path("slices" + std::to_string(max_label));
    write_png_slices(v, folder);
    EXPECT_TRUE(fs::exists(fs::path(folder) / "slice_0003.png"));
    const LabelVolume r = read_png_slices(folder, v.grid.spacing);
    EXPECT_EQ(r.grid.size, v.grid.size);
    EXPECT_EQ(r.grid.spacing, v.grid.spacing);
    EXPECT_EQ(r.labels, v.labels) << "max label " << max_label;
    EXPECT_EQ(r.source, folder);
  }
}

TEST_F(VolumeIoTest, PngSlicesAreOrderedByTheNumberInTheirNames) {
  LabelVolume v = sample(3, 3, 3, 9);
  write_png_slices(v, path("a"));
  // Renamed so that alphabetical and numerical order differ: 8, 9, 10.
  const std::string f = path("b");
  fs::create_directories(f);
  fs::copy_file(path("a/slice_0000.png"), f + "/scan8.png");
  fs::copy_file(path("a/slice_0001.png"), f + "/scan9.png");
  fs::copy_file(path("a/slice_0002.png"), f + "/scan10.png");
  EXPECT_EQ(read_png_slices(f, v.grid.spacing).labels, v.labels);
}

TEST_F(VolumeIoTest, BadSliceFoldersAreRefusedNamingTheFile) {
  const LabelVolume v = sample(5, 4, 3, 1);
  const Eigen::Vector3d spacing = v.grid.spacing;
  // Mismatched slice sizes.
  write_png_slices(v, path("sizes"));
  write_png_slices(sample(6, 4, 1, 1), path("other"));
  fs::copy_file(path("other/slice_0000.png"), path("sizes/slice_0001.png"), fs::copy_options::overwrite_existing);
  std::string e = error_of([&] { read_png_slices(path("sizes"), spacing); });
  EXPECT_TRUE(contains(e, "sizes/slice_0001.png") && contains(e, "6 x 4") && contains(e, "5 x 4")) << e;
  // A missing slice (gap in the numbering).
  write_png_slices(v, path("gap"));
  fs::remove(path("gap/slice_0001.png"));
  e = error_of([&] { read_png_slices(path("gap"), spacing); });
  EXPECT_TRUE(contains(e, path("gap")) && contains(e, "missing slice 1") && contains(e, "slice_0000.png") &&
              contains(e, "slice_0002.png"))
      << e;
  // A name without a number.
  write_png_slices(v, path("names"));
  fs::copy_file(path("names/slice_0000.png"), path("names/extra.png"));
  e = error_of([&] { read_png_slices(path("names"), spacing); });
  EXPECT_TRUE(contains(e, "names/extra.png") && contains(e, "no number")) << e;
  // Not a PNG; a truncated PNG.
  write_png_slices(v, path("garbage"));
  write_text(path("garbage/slice_0002.png"), "this is not an image");
  e = error_of([&] { read_png_slices(path("garbage"), spacing); });
  EXPECT_TRUE(contains(e, "garbage/slice_0002.png") && contains(e, "not a PNG")) << e;
  write_png_slices(v, path("cut"));
  fs::resize_file(path("cut/slice_0001.png"), fs::file_size(path("cut/slice_0001.png")) / 2);
  e = error_of([&] { read_png_slices(path("cut"), spacing); });
  EXPECT_TRUE(contains(e, "cut/slice_0001.png") && contains(e, "unreadable")) << e;
  // Empty folder, not a folder, bad spacing.
  fs::create_directories(path("none"));
  e = error_of([&] { read_png_slices(path("none"), spacing); });
  EXPECT_TRUE(contains(e, path("none")) && contains(e, "no .png")) << e;
  e = error_of([&] { read_png_slices(path("missing"), spacing); });
  EXPECT_TRUE(contains(e, path("missing"))) << e;
  e = error_of([&] { read_png_slices(path("gap"), Eigen::Vector3d(1e-3, 0.0, 1e-3)); });
  EXPECT_TRUE(contains(e, "spacing")) << e;
}

// The CRC-32 of PNG chunks (ISO 3309, bit by bit), to patch a header and keep the file well-formed.
std::uint32_t png_crc(const std::string& bytes) {
  std::uint32_t c = 0xffffffffu;
  for (unsigned char b : bytes) {
    c ^= b;
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return c ^ 0xffffffffu;
}

TEST_F(VolumeIoTest, APngHeaderDeclaringMoreThanItsFileCanHoldIsRefusedBeforeAllocating) {
  // A valid 2 x 2 slice whose header then says 1e6 x 1e6 pixels (a terabyte of rows from a file of ~70 bytes):
  // deflate cannot expand that much, so the file is corrupt, and the rows must not be allocated first.
  LabelVolume v;
  v.grid.size = Eigen::Vector3i(2, 2, 1);
  v.labels = {0, 1, 1, 0};
  write_png_slices(v, path("huge"));
  std::string bytes;
  {
    std::ifstream in(path("huge/slice_0000.png"), std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  ASSERT_EQ(bytes.substr(12, 4), "IHDR");
  for (int k = 0; k < 2; ++k) {  // width, then height: 1000000 = 0x000f4240, big-endian
    const char big[4] = {0x00, 0x0f, 0x42, 0x40};
    bytes.replace(16 + 4 * static_cast<std::size_t>(k), 4, big, 4);
  }
  const std::uint32_t crc = png_crc(bytes.substr(12, 4 + 13));
  for (int k = 0; k < 4; ++k) bytes[29 + static_cast<std::size_t>(k)] = static_cast<char>(crc >> (24 - 8 * k));
  {
    std::ofstream out(path("huge/slice_0000.png"), std::ios::binary | std::ios::trunc);
    out << bytes;
  }
  const std::string e = error_of([&] { read_png_slices(path("huge"), Eigen::Vector3d(1e-3, 1e-3, 1e-3)); });
  EXPECT_TRUE(contains(e, "huge/slice_0000.png") && contains(e, "1000000 x 1000000 pixels") &&
              contains(e, "truncated or corrupt"))
      << e;
}

TEST_F(VolumeIoTest, NrrdRoundTripsEveryTypeAttachedAndDetached) {
  LabelVolume v = sample(6, 5, 4, 200);
  v.grid.origin = Eigen::Vector3d(0.01, -0.02, 0.03);
  v.grid.axes << 1, 0, 0, 0, -1, 0, 0, 0, 1;  // j runs along -y: a reflection
  for (const char* type : {"uchar", "ushort", "short", "int", "float"}) {
    for (bool detached : {false, true}) {
      for (bool big : {false, true}) {
        NrrdWriteOptions o;
        o.type = type;
        o.detached = detached;
        o.big_endian = big;
        const std::string file = path(std::string("v_") + type + (detached ? ".nhdr" : ".nrrd"));
        write_nrrd(v, file, o);
        const LabelVolume r = read_nrrd(file);
        EXPECT_EQ(r.labels, v.labels) << type << (detached ? " detached" : " attached") << (big ? " big" : " little");
        EXPECT_EQ(r.grid.size, v.grid.size);
        EXPECT_TRUE(r.grid.spacing.isApprox(v.grid.spacing, 1e-12));
        EXPECT_TRUE(r.grid.origin.isApprox(v.grid.origin, 1e-12));
        EXPECT_TRUE(r.grid.axes.isApprox(v.grid.axes, 1e-12));
      }
    }
  }
  NrrdWriteOptions spacings;
  spacings.space_directions = false;
  write_nrrd(v, path("s.nrrd"), spacings);
  const LabelVolume r = read_nrrd(path("s.nrrd"));
  EXPECT_TRUE(r.grid.spacing.isApprox(v.grid.spacing, 1e-12));
  EXPECT_TRUE(r.grid.axes.isIdentity());
}

TEST_F(VolumeIoTest, NrrdAcceptsInformationalFieldsSkipsAndUnits) {
  // 2 x 2 x 2 uchar, data at the end of a detached file after a line and some bytes to skip.
  const std::string header =
      "NRRD0005\n# a comment\ncontent: test\ntype: unsigned char\ndimension: 3\nspace: left-posterior-superior\n"
      "sizes: 2 2 2\nspace directions: (0.1,0,0) (0,0.1,0) (0,0,0.2)\nspace units: \"cm\" \"cm\" \"cm\"\n"
      "kinds: domain domain domain\nendian: little\nencoding: raw\nspace origin: (1,2,3)\nmy key:=my value\n"
      "data file: d.raw\nbyte skip: -1\n";
  write_text(path("h.nhdr"), header);
  write_text(path("d.raw"), std::string("preamble\n") + std::string("\x00\x01\x00\x01\x02\x02\x00\x01", 8));
  const LabelVolume r = read_nrrd(path("h.nhdr"));
  EXPECT_EQ(r.labels, (std::vector<std::int32_t>{0, 1, 0, 1, 2, 2, 0, 1}));
  EXPECT_TRUE(r.grid.spacing.isApprox(Eigen::Vector3d(0.001, 0.001, 0.002), 1e-12));
  EXPECT_TRUE(r.grid.origin.isApprox(Eigen::Vector3d(0.01, 0.02, 0.03), 1e-12));
  write_text(path("h2.nhdr"), "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 1 1 1\nencoding: raw\n"
                              "data file: d.raw\nline skip: 1\n");
  EXPECT_EQ(read_nrrd(path("h2.nhdr")).labels, r.labels);
}

TEST_F(VolumeIoTest, BadNrrdHeadersAreRefusedNamingFileAndLine) {
  const std::string head = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 1 1 1\n";
  const std::string data(8, '\1');
  struct Case {
    std::string header, expect;
  };
  const std::vector<Case> cases = {
      {"NRRD0004\ntype: complex\n", ":2: unknown type 'complex'"},
      {head + "encoding: gzip\n", ":6: unknown or unsupported encoding 'gzip'"},
      {head + "encoding: raw\nendian: middle\n", ":7: unknown endian 'middle'"},
      {head + "encoding: raw\ncolour: red\n", ":7: unknown field 'colour'"},
      {head + "space units: \"furlong\" \"furlong\" \"furlong\"\nencoding: raw\n", ":6: unknown space units"},
      {head + "space: martian\nencoding: raw\n", ":6: unknown or unsupported space 'martian'"},
      {"NRRD0004\ntype: uchar\ndimension: 4\n", ":3: dimension 4 not supported"},
      {"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 0 2\n", ":4: sizes"},
      {"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 1 -1 1\n", ":5: spacings"},
      {"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspace directions: (1,0,0) (0,1,0) none\n",
       ":5: space directions"},
      {"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspace directions: (1,0,0) (1,1,0) (0,0,1)\n"
       "encoding: raw\n",
       "not orthogonal"},
      {"NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nspacings: 1 1 1\nencoding: raw\n", "no 'endian'"},
      {"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n", "neither 'spacings' nor"},
      {"NRRD0004\ndimension: 3\n", "no 'type'"},
      {"NRRD0004\ntype: uchar\nsizes 2 2 2\n", ":3: expected 'field: value'"},
      {"P5 not nrrd\n", ":1: not an NRRD file"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const std::string file = path("bad" + std::to_string(i) + ".nrrd");
    write_text(file, cases[i].header + "\n" + data);
    const std::string e = error_of([&] { read_nrrd(file); });
    EXPECT_TRUE(contains(e, file) && contains(e, cases[i].expect)) << "case " << i << ": " << e;
  }
}

TEST_F(VolumeIoTest, TruncatedOrMissingNrrdDataIsRefusedNamingTheDataFile) {
  const LabelVolume v = sample(6, 5, 4, 9);
  NrrdWriteOptions o;
  o.type = "ushort";
  write_nrrd(v, path("a.nrrd"), o);
  fs::resize_file(path("a.nrrd"), fs::file_size(path("a.nrrd")) - 3);
  std::string e = error_of([&] { read_nrrd(path("a.nrrd")); });
  EXPECT_TRUE(contains(e, path("a.nrrd")) && contains(e, "truncated") && contains(e, "240 bytes")) << e;

  o.detached = true;
  write_nrrd(v, path("d.nhdr"), o);
  fs::resize_file(path("d.raw"), 100);
  e = error_of([&] { read_nrrd(path("d.nhdr")); });
  EXPECT_TRUE(contains(e, path("d.raw")) && contains(e, "truncated") && contains(e, "100 found")) << e;
  fs::remove(path("d.raw"));
  e = error_of([&] { read_nrrd(path("d.nhdr")); });
  EXPECT_TRUE(contains(e, path("d.raw")) && contains(e, "cannot open")) << e;

  // A float volume must hold labels.
  write_text(path("f.nrrd"), "NRRD0004\ntype: float\ndimension: 3\nsizes: 1 1 2\nspacings: 1 1 1\nencoding: raw\n"
                             "endian: little\n\n");
  {
    std::ofstream f(path("f.nrrd"), std::ios::binary | std::ios::app);
    const float values[2] = {1.0f, 0.5f};
    f.write(reinterpret_cast<const char*>(values), sizeof values);
  }
  e = error_of([&] { read_nrrd(path("f.nrrd")); });
  EXPECT_TRUE(contains(e, path("f.nrrd")) && contains(e, "whole-number labels")) << e;
  e = error_of([&] { read_nrrd(path("absent.nrrd")); });
  EXPECT_TRUE(contains(e, path("absent.nrrd"))) << e;
}

}  // namespace
}  // namespace surgsim
