#include "frame_output.h"

#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.h"
#include "organ_view.h"

using namespace surgsim::core;

namespace surgsim {

namespace {
// Finds a program on PATH.
bool on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (path == nullptr) return false;
  std::stringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (!dir.empty() && ::access((dir + "/" + name).c_str(), X_OK) == 0) return true;
  }
  return false;
}
}  // namespace

FrameOutput::FrameOutput(const FrameOutputOptions& options) : options_(options), png_every_(options.png_every) {
  if (options_.enabled && png_every_ > 0) {
    std::error_code ec;
    std::filesystem::create_directories(options_.out, ec);
    if (ec) throw_error(options_.out, ": cannot create the output folder (", ec.message(), ")");
    // Index of the written frames, so a reader knows what each PNG shows.
    index_ = std::fopen((options_.out + "/frames.csv").c_str(), "w");
    if (index_ == nullptr) throw_error(options_.out, "/frames.csv: cannot create the frame index");
    std::fprintf(index_, "png,seq,sim_time,contacts,max_displacement_m,instruments\n");
  }
}

FrameOutput::~FrameOutput() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;  // the writer empties the queue first
  }
  queued_.notify_all();
  if (writer_.joinable()) writer_.join();
  if (index_ != nullptr) std::fclose(index_);
}

void FrameOutput::flush() {
  std::unique_lock<std::mutex> lock(mutex_);
  freed_.wait(lock, [&] { return tail_ == head_; });
  if (index_ != nullptr) std::fflush(index_);
}

std::uint64_t FrameOutput::pngs_written() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return pngs_written_;
}

std::uint64_t FrameOutput::png_errors() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return png_errors_;
}

std::uint64_t FrameOutput::png_waits() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return png_waits_;
}

void FrameOutput::write(const Image& image, std::uint64_t frame, std::uint64_t seq, double sim_time,
                        const OrganView& organ, int instruments) {
  char name[64];
  std::snprintf(name, sizeof name, "frame_%06llu.png", static_cast<unsigned long long>(frame));
  // The VTK here: it reads the organ, which the render loop changes next frame.
  if (options_.vtk) {
    const std::string path = options_.out + "/" + name;
    try {
      if (organ.write_vtk(path.substr(0, path.size() - 4) + ".vtk")) ++vtk_written_;
    } catch (const Error& e) {
      count_error(e);
    }
  }
  std::unique_lock<std::mutex> lock(mutex_);
  if (head_ - tail_ == kSlots) {
    ++png_waits_;  // the disk is slower than the frames asked of it: wait rather than drop a recorded frame
    freed_.wait(lock, [&] { return head_ - tail_ < kSlots; });
  }
  Slot& slot = slots_[head_ % kSlots];
  lock.unlock();  // the writer never touches slot head_ (not queued yet)
  slot.image.resize(image.width, image.height);
  std::copy(image.rgb.begin(), image.rgb.end(), slot.image.rgb.begin());
  slot.name = name;
  slot.seq = seq;
  slot.sim_time = sim_time;
  slot.contacts = organ.contacts_shown();
  slot.max_displacement = organ.max_displacement();
  slot.instruments = instruments;
  lock.lock();
  ++head_;
  if (!writer_.joinable()) writer_ = std::thread([this] { writer_loop(); });
  lock.unlock();
  queued_.notify_one();
}

void FrameOutput::writer_loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    queued_.wait(lock, [&] { return stop_ || tail_ < head_; });
    if (tail_ == head_) return;  // stopping, nothing left
    const Slot& slot = slots_[tail_ % kSlots];
    lock.unlock();
    write_slot(slot);
    lock.lock();
    ++tail_;
    freed_.notify_all();
  }
}

void FrameOutput::write_slot(const Slot& slot) {
  const std::string path = options_.out + "/" + slot.name;
  // A full disk must not stop the display: count the failure, keep drawing.
  try {
    write_png(path, slot.image);
    std::lock_guard<std::mutex> lock(mutex_);
    if (index_ != nullptr) {
      std::fprintf(index_, "%s,%llu,%.6f,%d,%.9g,%d\n", slot.name.c_str(), static_cast<unsigned long long>(slot.seq),
                   slot.sim_time, slot.contacts, slot.max_displacement, slot.instruments);
    }
    if (first_png_.empty()) first_png_ = path;
    last_png_ = path;
    ++pngs_written_;
  } catch (const Error& e) {
    count_error(e);
  }
}

void FrameOutput::count_error(const Error& e) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (png_errors_++ == 0) std::cerr << "visual_node: " << e.what() << " (further PNG errors counted)\n";
}

void FrameOutput::finish() {
  flush();
  // The PNG frames as an MP4 when asked and Debian's ffmpeg is there (never required).
  if (options_.video && pngs_written_ > 1) {
    if (!on_path("ffmpeg")) {
      video_ = "skipped: ffmpeg not found (apt-get install ffmpeg, or SURGSIM_WITH_VIDEO=1 scripts/setup.sh)";
    } else {
      const double fps = options_.rate_hz / std::max(1, png_every_);
      const std::string out = options_.out + "/video.mp4";
      const std::string cmd = "ffmpeg -y -loglevel error -framerate " + std::to_string(fps) + " -pattern_type glob -i '" +
                              options_.out + "/frame_*.png' -c:v libx264 -pix_fmt yuv420p '" + out + "'";
      video_ = std::system(cmd.c_str()) == 0 ? out : "failed: " + cmd;
    }
    if (!options_.quiet) std::cerr << "visual_node: video " << video_ << "\n";
  }
}

void FrameOutput::add_stats(nlohmann::json& j) const {
  std::lock_guard<std::mutex> lock(mutex_);
  j["pngs_written"] = pngs_written_;
  j["png_errors"] = png_errors_;
  j["png_waits"] = png_waits_;
  j["vtk_written"] = vtk_written_;
  j["video"] = video_;
  j["out"] = options_.out;
  j["first_png"] = first_png_;
  j["last_png"] = last_png_;
}

}  // namespace surgsim
