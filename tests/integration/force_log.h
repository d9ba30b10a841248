// The haptic node's per-tick --log (tick,t,fx,fy,fz,contacts) read around a loss of device input, for the tests
// that stop or kill a device and check that the force goes to exactly zero and stays there.
#pragma once
#include <cmath>
#include <sstream>
#include <string>

#include "process.h"

namespace surgsim::testing {

struct ForceAroundLoss {
  long rows = 0;                 // ticks logged
  bool finite = true;            // every force finite
  double before_max = 0;         // N, largest force in (loss_t - before_s, loss_t)
  double first_zero_after = -1;  // s, first tick at or after loss_t with exactly zero force (-1: none)
  long zero_late = 0;            // ticks after loss_t + late_s with exactly zero force
  long nonzero_late = 0;         // ticks after loss_t + late_s with any other force
};

/// `loss_t`: the loss on the node's simulated time (s); `late_s`: from when on the force must be zero.
inline ForceAroundLoss force_around_loss(const std::string& log_file, double loss_t, double before_s, double late_s) {
  ForceAroundLoss r;
  std::istringstream log(read_file(log_file));
  std::string line;
  std::getline(log, line);  // header
  while (std::getline(log, line)) {
    std::stringstream ss(line);
    std::string f[6];
    for (auto& x : f) std::getline(ss, x, ',');
    const double t = std::stod(f[1]);
    const double force = std::hypot(std::stod(f[2]), std::stod(f[3]), std::stod(f[4]));
    ++r.rows;
    r.finite = r.finite && std::isfinite(force);
    if (t > loss_t - before_s && t < loss_t) r.before_max = std::max(r.before_max, force);
    if (t >= loss_t && force == 0.0 && r.first_zero_after < 0) r.first_zero_after = t;
    if (t > loss_t + late_s) (force == 0.0 ? r.zero_late : r.nonzero_late)++;
  }
  return r;
}

}  // namespace surgsim::testing
