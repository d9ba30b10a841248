// Records every DataWriter::write(void*) the test program makes: which thread, which topic, and for ForceFeedback
// the sample's seq, force and flags. dds_write_spy.cpp interposes Fast DDS's DataWriter::write (the executable's
// definition wins over libfastrtps's for the calls our code makes) and forwards to the library's.
#pragma once
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

namespace surgsim::test {

struct DdsWrite {
  std::thread::id thread;
  std::string topic;
  std::uint64_t seq = 0;        // ForceFeedback and ContactFrame
  double force[3] = {0, 0, 0};  // ForceFeedback
  int instrument = 0;            // ForceFeedback's key
  std::uint32_t flags = 0;      // ForceFeedback and ContactFrame
};

/// Starts recording (clears what was recorded). Recording allocates, on the writing thread only.
void dds_spy_start();
/// Stops recording and returns the writes since dds_spy_start(), in the order they were made.
std::vector<DdsWrite> dds_spy_stop();

}  // namespace surgsim::test
