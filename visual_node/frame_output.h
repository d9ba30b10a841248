// What the visual node writes besides the display: every n-th rendered frame as a PNG (out/frame_NNNNNN.png), the
// index out/frames.csv saying which contact frame each PNG shows and how many instruments it draws, the organ's
// surface as VTK next to each PNG when the scene asks (visual.vtk), and at shutdown the PNGs as out/video.mp4 when
// asked and ffmpeg is installed.
// A failed write (e.g. a full disk) must not stop the display: it is counted, the first one printed on stderr.
// PNGs are compressed and written on a thread of this class (libpng at 640 x 480 costs about a frame period), so a
// PNG frame does not make the display miss its rate: write() copies the picture into one of kSlots preallocated slots
// and returns. When every slot is still waiting for the disk, write() waits for one (counted in png_waits): a recorded
// frame is never dropped. Files appear, and frames.csv gains its rows, in frame order.
#pragma once
#include <array>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <thread>

#include "render/image.h"

namespace surgsim::core {
class Error;
}  // namespace surgsim::core

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
  /// Init: when writing, creates the folder and frames.csv with its header. Throws surgsim::core::Error when it cannot.
  explicit FrameOutput(const FrameOutputOptions& options);
  ~FrameOutput();
  FrameOutput(const FrameOutput&) = delete;
  FrameOutput& operator=(const FrameOutput&) = delete;

  /// Waits until every PNG handed to write() is on disk (or counted as failed), then pushes frames.csv to the file.
  void flush();
  /// Whether rendered frame number `frame` (1-based) is written.
  bool due(std::uint64_t frame) const {
    return png_every_ > 0 && options_.enabled && frame % static_cast<std::uint64_t>(png_every_) == 0;
  }
  /// Writes `image` as frame_NNNNNN.png (NNNNNN = `frame`), the organ's VTK beside it when asked, and the index row
  /// (contact frame `seq`, its `sim_time`, the organ's contacts and largest displacement, the `instruments` drawn).
  /// A surgsim::core::Error on the way is counted (png_errors) and the frame skipped; the first is printed. Returns
  /// once the picture is copied (the PNG, its index row and the counters follow on the writer thread; flush() waits for
  /// them); the VTK is written before it returns.
  void write(const Image& image, std::uint64_t frame, std::uint64_t seq, double sim_time, const OrganView& organ,
             int instruments);
  /// Shutdown: waits for the queued PNGs, then the video, when asked and more than one PNG was written (says where,
  /// unless quiet).
  void finish();

  /// PNGs on disk so far (those still queued are not counted until written: flush() first for a final count).
  std::uint64_t pngs_written() const;
  std::uint64_t png_errors() const;
  /// Times write() found every slot busy and waited for the disk.
  std::uint64_t png_waits() const;
  std::uint64_t vtk_written() const { return vtk_written_; }
  const std::string& video() const { return video_; }
  const std::string& out() const { return options_.out; }
  /// Adds pngs_written, png_errors, png_waits, vtk_written, video, out, first_png, last_png.
  void add_stats(nlohmann::json& stats) const;

  static constexpr int kSlots = 3;

 private:
  // One PNG waiting for the writer thread: the picture and its frames.csv row.
  struct Slot {
    Image image;
    std::string name;  // frame_NNNNNN.png
    std::uint64_t seq = 0;
    double sim_time = 0;
    int contacts = 0;
    double max_displacement = 0;
    int instruments = 0;
  };
  void writer_loop();
  void write_slot(const Slot& slot);  // on the writer thread
  void count_error(const core::Error& e);  // png_errors (PNG or VTK), the first printed on stderr

  FrameOutputOptions options_;
  int png_every_ = 0;
  std::FILE* index_ = nullptr;  // frames.csv: which contact frame each PNG shows
  mutable std::mutex mutex_;    // guards the queue, the counters, first/last_png and index_
  std::condition_variable queued_, freed_;
  std::array<Slot, kSlots> slots_;
  std::uint64_t head_ = 0, tail_ = 0;  // slots [tail_, head_) are queued, in frame order (index modulo kSlots); the
                                       // writer keeps slot tail_ queued while it writes it
  bool stop_ = false;
  std::thread writer_;  // started with the first write()
  std::uint64_t pngs_written_ = 0;
  std::uint64_t png_errors_ = 0;
  std::uint64_t png_waits_ = 0;
  std::uint64_t vtk_written_ = 0;
  std::string video_;  // path of the MP4 written, or why not
  std::string first_png_;
  std::string last_png_;
};

}  // namespace surgsim
