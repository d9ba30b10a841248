// Records every DataWriter::write(void*) the test program makes: which thread, which topic, and for ForceFeedback
// the sample's seq, force and flags; for ContactFrame each entry's organ; BodyState's organ; the whole SceneInfo.
// dds_write_spy.cpp interposes Fast DDS's DataWriter::write (the executable's definition wins over libfastrtps's for
// the calls our code makes) and forwards to the library's.
#pragma once
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

namespace surgsim::test {

/// SceneInfo.organs[k] as written.
struct OrganInfoWrite {
  std::string name, model;
  std::uint64_t mesh_hash = 0, tensor_hash = 0;
  std::uint32_t node_count = 0, surface_node_count = 0;
};

struct DdsWrite {
  std::thread::id thread;
  std::string topic;
  std::uint64_t seq = 0;        // ForceFeedback and ContactFrame
  double force[3] = {0, 0, 0};  // ForceFeedback
  int instrument = 0;            // ForceFeedback's key
  std::uint32_t flags = 0;      // ForceFeedback and ContactFrame
  std::vector<int> contact_organs;  // ContactFrame: each entry's organ, in order
  std::vector<int> contact_nodes;   // ContactFrame: each entry's node, in order
  int organ = -1;                   // BodyState's key
  // SceneInfo: the whole-scene fields and one entry per organ.
  std::string scene_name;
  std::uint64_t mesh_hash = 0, tensor_hash = 0;
  std::uint32_t node_count = 0, surface_node_count = 0;
  std::vector<OrganInfoWrite> organs;
};

/// Starts recording (clears what was recorded). Recording allocates, on the writing thread only.
void dds_spy_start();
/// Stops recording and returns the writes since dds_spy_start(), in the order they were made.
std::vector<DdsWrite> dds_spy_stop();

}  // namespace surgsim::test
