// Fuzz target: tool trajectories, v1 and v2 (common/tool/trajectory.cpp): the same file through Trajectory::load
// (v1 only) and MultiTrajectory::load (v1 or v2), then a few lookups of each pose over the loaded time range.
// Expected: surgsim::core::Error (see fuzz_support.h); anything else escaping is a finding.
#include "core/error.h"
#include "fuzz_support.h"
#include "tool/trajectory.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim;
  const std::string path = fuzz::write_input("trajectory.csv", fuzz::as_text(data, size));
  try {
    const tool::Trajectory t = tool::Trajectory::load(path);
    for (double s : {-1.0, 0.0, 0.5 * t.duration(), t.duration(), t.duration() + 1.0}) (void)t.at(s);
  } catch (const core::Error&) {
  }
  try {
    const tool::MultiTrajectory m = tool::MultiTrajectory::load(path);
    tool::Pose5 pose;
    for (int i = 0; i < m.instruments(); ++i) {
      for (double s : {-1.0, 0.0, 0.5 * m.duration(), m.duration(), m.duration() + 1.0}) (void)m.at(i, s, pose);
    }
  } catch (const core::Error&) {
  }
  return 0;
}
