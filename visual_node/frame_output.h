// What the visual node writes besides the display: every n-th rendered frame as a PNG (out/frame_NNNNNN.png), the
// index out/frames.csv saying which contact frame each PNG shows and how many instruments it draws, the organ's
// surface as VTK next to each PNG when the scene asks (visual.vtk), and at shutdown the PNGs as out/video.mp4 when
// asked and ffmpeg is installed.
// A failed write (e.g. a full disk) must not stop the display: it is counted, the first one printed on stderr.
#pragma once
#include <cstdint>
#include <cstdio>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "render/image.h"

namespace surgsim {

class OrganView;

struct FrameOutputOptions {
  std::string out;        // folder of the PNG, VTK, frames.csv and video files
  int png_every = 0;      // write every n-th rendered frame (0: none)
  bool enabled = true;    // false (headless: no image to read): nothing is written and no folder is made
  bool vtk = false;       // the organ's surface as VTK beside each PNG
  bool video = false;     // assemble the PNGs into out/video.mp4 at finish()
  double rate_hz = 50;    // the displayed frame rate (the video's is rate_hz / png_every)
  bool quiet = false;     // no "video" line on stderr
};

class FrameOutput {
 public:
  /// Init: when writing, creates the folder and frames.csv with its header. Throws surgsim::Error when it cannot.
  explicit FrameOutput(const FrameOutputOptions& options);
  ~FrameOutput();
  FrameOutput(const FrameOutput&) = delete;
  FrameOutput& operator=(const FrameOutput&) = delete;

  /// Pushes what frames.csv holds so far to the file.
  void flush();
  /// Whether rendered frame number `frame` (1-based) is written.
  bool due(std::uint64_t frame) const {
    return png_every_ > 0 && options_.enabled && frame % static_cast<std::uint64_t>(png_every_) == 0;
  }
  /// Writes `image` as frame_NNNNNN.png (NNNNNN = `frame`), the organ's VTK beside it when asked, and the index row
  /// (contact frame `seq`, its `sim_time`, the organ's contacts and largest displacement, the `instruments` drawn).
  /// A surgsim::Error on the way is counted (png_errors) and the frame skipped; the first is printed.
  void write(const Image& image, std::uint64_t frame, std::uint64_t seq, double sim_time, const OrganView& organ,
             int instruments);
  /// Shutdown: the video, when asked and more than one PNG was written (says where, unless quiet).
  void finish();

  std::uint64_t pngs_written() const { return pngs_written_; }
  std::uint64_t png_errors() const { return png_errors_; }
  std::uint64_t vtk_written() const { return vtk_written_; }
  const std::string& video() const { return video_; }
  const std::string& out() const { return options_.out; }
  /// Adds pngs_written, png_errors, vtk_written, video, out, first_png, last_png.
  void add_stats(nlohmann::json& stats) const;

 private:
  FrameOutputOptions options_;
  int png_every_ = 0;
  std::FILE* index_ = nullptr;  // frames.csv: which contact frame each PNG shows
  std::uint64_t pngs_written_ = 0;
  std::uint64_t png_errors_ = 0;
  std::uint64_t vtk_written_ = 0;
  std::string video_;  // path of the MP4 written, or why not
  std::string first_png_;
  std::string last_png_;
};

}  // namespace surgsim
